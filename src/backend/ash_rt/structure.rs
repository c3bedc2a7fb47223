//! The acceleration structures: one AABB BLAS over the cluster boxes (one geometry, one box per
//! cluster of K Hilbert-sorted particles, sized for the series' maximum count) and a TLAS with
//! one instance of it.
//!
//! - The BLAS is built with `ALLOW_UPDATE | PREFER_FAST_TRACE`: a new step is a full build
//!   (mode `BUILD`), a radius change a refit (mode `UPDATE`, in place).
//! - Its geometry carries `NO_DUPLICATE_ANY_HIT_INVOCATION` (otherwise the any-hit sum may
//!   count a box twice) and is not opaque (otherwise any-hit is skipped).
//! - Storage and scratch are sized for the series' maximum box count, but a build covers only
//!   the uploaded step's clusters (`primitiveCount` below the size-query maximum, which Vulkan
//!   allows). The box kernel still writes NaN (inactive) boxes into the unused tail of the box
//!   buffer, but they are not handed to the build: Mesa lavapipe 25.0 does not treat NaN AABBs
//!   as inactive (its CPU builder takes `MIN2`/`MAX2` of child bounds, so one NaN box makes the
//!   root's bounds NaN and every ray misses; checked: 50 NaN boxes after 1500 real ones turned
//!   every query to 0), and leaving them out is what inactive primitives amount to on any
//!   driver, at a lower build cost. A refit uses the count of the build it updates, as the
//!   specification requires.
//! - Scratch memory is allocated once for the larger of the build and update needs, and reused
//!   by every build, refit and the TLAS build (with a barrier in between).
//! - The TLAS is rebuilt after every BLAS build or refit (one instance: microseconds).

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::context::{Context, device_error, vk_error};
use super::resources::{Buffer, barrier};
use crate::backend::BackendError;

/// Bytes per box in the AABB buffer (`VkAabbPositionsKHR`).
pub const BOX_BYTES: u64 = 24;

/// An acceleration structure and its storage.
struct Accel {
    ctx: Arc<Context>,
    raw: vk::AccelerationStructureKHR,
    _buffer: Buffer,
    address: u64,
    size: u64,
}

impl Accel {
    fn new(
        ctx: &Arc<Context>,
        ty: vk::AccelerationStructureTypeKHR,
        size: u64,
        name: &str,
    ) -> Result<Accel, BackendError> {
        let buffer = Buffer::new(
            ctx,
            name,
            size,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
        )?;
        let info = vk::AccelerationStructureCreateInfoKHR::default()
            .buffer(buffer.raw)
            .size(size)
            .ty(ty);
        // SAFETY: the buffer has the storage usage and at least `size` bytes.
        let raw = unsafe { ctx.accel.create_acceleration_structure(&info, None) }
            .map_err(|e| vk_error(&format!("creating the {name}"), e))?;
        // SAFETY: raw was just created.
        let address = unsafe {
            ctx.accel.get_acceleration_structure_device_address(
                &vk::AccelerationStructureDeviceAddressInfoKHR::default()
                    .acceleration_structure(raw),
            )
        };
        Ok(Accel {
            ctx: ctx.clone(),
            raw,
            _buffer: buffer,
            address,
            size,
        })
    }
}

impl Drop for Accel {
    fn drop(&mut self) {
        // SAFETY: nothing in flight uses it (every submission is waited for).
        unsafe {
            self.ctx
                .accel
                .destroy_acceleration_structure(self.raw, None)
        };
    }
}

fn aabb_geometry(boxes_address: u64) -> vk::AccelerationStructureGeometryKHR<'static> {
    vk::AccelerationStructureGeometryKHR::default()
        .geometry_type(vk::GeometryTypeKHR::AABBS)
        .geometry(vk::AccelerationStructureGeometryDataKHR {
            aabbs: vk::AccelerationStructureGeometryAabbsDataKHR::default()
                .data(vk::DeviceOrHostAddressConstKHR {
                    device_address: boxes_address,
                })
                .stride(BOX_BYTES),
        })
        .flags(vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION)
}

fn instance_geometry(instances_address: u64) -> vk::AccelerationStructureGeometryKHR<'static> {
    vk::AccelerationStructureGeometryKHR::default()
        .geometry_type(vk::GeometryTypeKHR::INSTANCES)
        .geometry(vk::AccelerationStructureGeometryDataKHR {
            instances: vk::AccelerationStructureGeometryInstancesDataKHR::default()
                .array_of_pointers(false)
                .data(vk::DeviceOrHostAddressConstKHR {
                    device_address: instances_address,
                }),
        })
}

const BLAS_FLAGS: vk::BuildAccelerationStructureFlagsKHR =
    vk::BuildAccelerationStructureFlagsKHR::from_raw(
        vk::BuildAccelerationStructureFlagsKHR::ALLOW_UPDATE.as_raw()
            | vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE.as_raw(),
    );

/// Sizes of the BLAS over `boxes` boxes: (structure, build scratch, update scratch).
pub fn blas_sizes(ctx: &Context, boxes: u32) -> (u64, u64, u64) {
    let geometry = [aabb_geometry(0)];
    let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
        .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
        .flags(BLAS_FLAGS)
        .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
        .geometries(&geometry);
    let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
    // SAFETY: a valid build info (addresses are ignored by the size query).
    unsafe {
        ctx.accel.get_acceleration_structure_build_sizes(
            vk::AccelerationStructureBuildTypeKHR::DEVICE,
            &info,
            &[boxes],
            &mut sizes,
        )
    };
    (
        sizes.acceleration_structure_size,
        sizes.build_scratch_size,
        sizes.update_scratch_size,
    )
}

/// The BLAS, TLAS, instance buffer and scratch for a fixed number of boxes.
pub struct Structure {
    ctx: Arc<Context>,
    blas: Accel,
    tlas: Accel,
    instances: Buffer,
    scratch: Buffer,
    scratch_address: u64,
    /// Boxes the storage is sized for (the capacity's clusters).
    pub boxes: u32,
    /// Boxes (primitives) in the last build.
    pub active: u32,
    /// Whether the BLAS holds a built structure (an update needs one).
    pub built: bool,
}

impl Structure {
    /// The structures and their buffers for up to `boxes` boxes, nothing built yet.
    pub fn new(ctx: &Arc<Context>, boxes: u32) -> Result<Structure, BackendError> {
        if u64::from(boxes) > ctx.info.max_primitive_count {
            return Err(device_error(
                "building the BLAS",
                format!(
                    "{boxes} boxes exceed the device's maxPrimitiveCount {}",
                    ctx.info.max_primitive_count
                ),
            ));
        }
        let (blas_size, build_scratch, update_scratch) = blas_sizes(ctx, boxes);
        let blas = Accel::new(
            ctx,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            blas_size,
            "bottom-level acceleration structure",
        )?;

        let instances = [vk::AccelerationStructureInstanceKHR {
            transform: vk::TransformMatrixKHR {
                matrix: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            },
            instance_custom_index_and_mask: vk::Packed24_8::new(0, 0xff),
            instance_shader_binding_table_record_offset_and_flags: vk::Packed24_8::new(0, 0),
            acceleration_structure_reference: vk::AccelerationStructureReferenceKHR {
                device_handle: blas.address,
            },
        }];
        // SAFETY: AccelerationStructureInstanceKHR is a plain repr(C) struct of 64 bytes.
        let bytes = unsafe {
            std::slice::from_raw_parts(
                instances.as_ptr().cast::<u8>(),
                std::mem::size_of_val(&instances),
            )
        };
        let mut instance_buffer = Buffer::new(
            ctx,
            "TLAS instances",
            bytes.len() as u64,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
                | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
        )?;
        instance_buffer.write(0, bytes)?;

        let geometry = [instance_geometry(0)];
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geometry);
        let mut tlas_sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
        // SAFETY: as in blas_sizes.
        unsafe {
            ctx.accel.get_acceleration_structure_build_sizes(
                vk::AccelerationStructureBuildTypeKHR::DEVICE,
                &info,
                &[1],
                &mut tlas_sizes,
            )
        };
        let tlas = Accel::new(
            ctx,
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            tlas_sizes.acceleration_structure_size,
            "top-level acceleration structure",
        )?;
        let alignment = ctx.info.scratch_alignment.max(1);
        let scratch_size = build_scratch
            .max(update_scratch)
            .max(tlas_sizes.build_scratch_size);
        let scratch = Buffer::new(
            ctx,
            "acceleration-structure scratch",
            scratch_size + alignment,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
        )?;
        let scratch_address = scratch.address.div_ceil(alignment) * alignment;
        Ok(Structure {
            ctx: ctx.clone(),
            blas,
            tlas,
            instances: instance_buffer,
            scratch,
            scratch_address,
            boxes,
            active: 0,
            built: false,
        })
    }

    /// The TLAS, which the frames and queries trace.
    pub fn tlas(&self) -> vk::AccelerationStructureKHR {
        self.tlas.raw
    }

    /// Bytes of the BLAS (the paper's Table 2 measure).
    pub fn blas_bytes(&self) -> u64 {
        self.blas.size
    }

    /// Bytes of everything held: BLAS, TLAS, scratch and instances.
    pub fn total_bytes(&self) -> u64 {
        self.blas.size + self.tlas.size + self.scratch.size + self.instances.size
    }

    /// Records the BLAS build over the first `active` boxes at `boxes_address` (or, when
    /// `update`, the refit of the last build, whose box count it keeps), with `between` called
    /// after it (for a timestamp), then the TLAS build. The caller has made the boxes visible to
    /// the build.
    pub fn record(
        &mut self,
        cb: vk::CommandBuffer,
        boxes_address: u64,
        active: u32,
        update: bool,
        between: impl FnOnce(),
    ) -> Result<(), BackendError> {
        if update && !self.built {
            return Err(device_error("refitting the BLAS", "it was never built"));
        }
        if active > self.boxes {
            return Err(device_error(
                "building the BLAS",
                format!("{active} boxes exceed the {} it was sized for", self.boxes),
            ));
        }
        if update && active != self.active {
            return Err(device_error(
                "refitting the BLAS",
                "a refit must keep the box count of its build",
            ));
        }
        self.active = active;
        let ctx = &self.ctx;
        let geometry = [aabb_geometry(boxes_address)];
        let mut info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
            .flags(BLAS_FLAGS)
            .dst_acceleration_structure(self.blas.raw)
            .geometries(&geometry)
            .scratch_data(vk::DeviceOrHostAddressKHR {
                device_address: self.scratch_address,
            });
        info = if update {
            info.mode(vk::BuildAccelerationStructureModeKHR::UPDATE)
                .src_acceleration_structure(self.blas.raw)
        } else {
            info.mode(vk::BuildAccelerationStructureModeKHR::BUILD)
        };
        let ranges =
            [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(active)];
        // SAFETY: recording; every address points into live buffers of the right size.
        unsafe {
            ctx.accel
                .cmd_build_acceleration_structures(cb, &[info], &[&ranges[..]])
        };
        // The TLAS reads the BLAS and reuses the scratch memory.
        let as_stage = vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR;
        barrier(
            ctx,
            cb,
            (as_stage, vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR),
            (
                as_stage,
                vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR
                    | vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR,
            ),
        );
        between();
        let geometry = [instance_geometry(self.instances.address)];
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .dst_acceleration_structure(self.tlas.raw)
            .geometries(&geometry)
            .scratch_data(vk::DeviceOrHostAddressKHR {
                device_address: self.scratch_address,
            });
        let ranges = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(1)];
        // SAFETY: as above.
        unsafe {
            ctx.accel
                .cmd_build_acceleration_structures(cb, &[info], &[&ranges[..]])
        };
        barrier(
            ctx,
            cb,
            (as_stage, vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR),
            (
                vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR
                    | vk::PipelineStageFlags::COMPUTE_SHADER
                    | as_stage,
                vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR
                    | vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR,
            ),
        );
        Ok(())
    }
}
