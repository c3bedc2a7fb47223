//! The ash backend's buffers and descriptors: the arrays a step and a frame need, grown to
//! the largest step (or the reserved count) so a series reuses them, and the parameter block.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::AshBackend;
use super::context::{Context, NAME, device_error};
use super::pipelines::binding;
use super::resources::Buffer;
use super::structure::{BOX_BYTES, Structure};
use crate::accel::ClusterSize;
use crate::backend::BackendError;
use crate::backend::shaders::{GpuFrame, pack_map_tables};
use crate::values::FrameParams;
use crate::values::shader_constants::TABLE_SIZE;

pub(super) struct Buffers {
    pub(super) params: Buffer,
    pub(super) points: Buffer,
    /// The lo parts of double-single positions (a placeholder when the step has none).
    pub(super) points_lo: Buffer,
    pub(super) radius: Buffer,
    pub(super) tables: Buffer,
    pub(super) stbn: Buffer,
    pub(super) accum: Buffer,
    pub(super) query_points: Buffer,
    pub(super) query_results: Buffer,
    pub(super) boxes: Buffer,
    pub(super) lbvh_nodes: Buffer,
    pub(super) lbvh_boxes: Buffer,
}

impl Buffers {
    /// Grows the radius-attribute buffer to `words` floats: the radius attribute and an SPH
    /// kernel's volumes after it (`gpu_data::factor_layout`). The shaders reach it by address,
    /// read at each launch, so no descriptor changes.
    pub(super) fn ensure_factors(
        &mut self,
        ctx: &Arc<Context>,
        words: usize,
    ) -> Result<(), BackendError> {
        let need = words as u64 * 4;
        if self.radius.size < need {
            self.radius = addressed(ctx, "radius attribute", need)?;
        }
        Ok(())
    }
}

/// A buffer the shaders reach by device address (so its size is bound by the allocation
/// limit, not by maxStorageBufferRange).
pub(super) fn addressed(ctx: &Arc<Context>, name: &str, size: u64) -> Result<Buffer, BackendError> {
    Buffer::new(
        ctx,
        name,
        size,
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        MemoryLocation::GpuOnly,
    )
}

pub(super) fn storage(ctx: &Arc<Context>, name: &str, size: u64) -> Result<Buffer, BackendError> {
    Buffer::new(
        ctx,
        name,
        size,
        vk::BufferUsageFlags::STORAGE_BUFFER,
        MemoryLocation::GpuOnly,
    )
}

pub(super) fn boxes_buffer(ctx: &Arc<Context>, boxes: u64) -> Result<Buffer, BackendError> {
    Buffer::new(
        ctx,
        "cluster boxes",
        boxes * BOX_BYTES,
        vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        MemoryLocation::GpuOnly,
    )
}

/// Grows `buffer`, the lo parts of double-single positions, to `capacity` particles (the
/// first time a step needs them; the preparation gathers into it).
pub(super) fn ensure_points_lo(
    ctx: &Arc<Context>,
    buffer: &mut Buffer,
    capacity: usize,
) -> Result<(), BackendError> {
    let need = capacity as u64 * 16;
    if buffer.size < need {
        *buffer = addressed(ctx, "particle lo parts", need)?;
    }
    Ok(())
}

impl AshBackend {
    pub(super) fn write_descriptors(&mut self) {
        let b = &self.buffers;
        let infos: Vec<(u32, vk::DescriptorType, [vk::DescriptorBufferInfo; 1])> = [
            (binding::PARAMS, &b.params),
            (binding::TABLES, &b.tables),
            (binding::STBN, &b.stbn),
            (binding::QUERY_POINTS, &b.query_points),
            (binding::QUERY_RESULTS, &b.query_results),
            (binding::LBVH_NODES, &b.lbvh_nodes),
            (binding::LBVH_BOXES, &b.lbvh_boxes),
        ]
        .into_iter()
        .map(|(i, buf)| {
            let ty = if i == binding::PARAMS {
                vk::DescriptorType::UNIFORM_BUFFER
            } else {
                vk::DescriptorType::STORAGE_BUFFER
            };
            (i, ty, [buf.descriptor()])
        })
        .collect();
        let writes: Vec<vk::WriteDescriptorSet> = infos
            .iter()
            .map(|(i, ty, info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(self.set)
                    .dst_binding(*i)
                    .descriptor_type(*ty)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: the set is not in use by a pending submission (all are waited for).
        unsafe { self.ctx.device.update_descriptor_sets(&writes, &[]) };
    }

    pub(super) fn write_tlas_descriptor(&self) {
        let Some(s) = &self.structure else { return };
        let tlas = [s.tlas()];
        let mut accel = vk::WriteDescriptorSetAccelerationStructureKHR::default()
            .acceleration_structures(&tlas);
        // ash leaves descriptor_count at 0 when the buffer info is chained: set it.
        let mut write = vk::WriteDescriptorSet::default()
            .dst_set(self.set)
            .dst_binding(binding::TLAS)
            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
            .push_next(&mut accel);
        write.descriptor_count = 1;
        // SAFETY: as in write_descriptors.
        unsafe { self.ctx.device.update_descriptor_sets(&[write], &[]) };
    }

    /// Grows the particle buffers to hold `n` particles (and what was reserved), and makes the
    /// structure match the box count for cluster size `k`.
    pub(super) fn ensure_capacity(&mut self, n: usize, k: ClusterSize) -> Result<(), BackendError> {
        let limit = self.ctx.info.max_allocation;
        let want = n.max(self.reserved).max(1);
        let boxes = k.clusters_for(want) as u64;
        let blas_limit = self.ctx.info.max_primitive_count;
        if (want as u64).saturating_mul(16) > limit
            || boxes.saturating_mul(BOX_BYTES) > limit
            || boxes > blas_limit
        {
            return Err(device_error(
                "uploading the step",
                format!(
                    "{want} particles (K = {k}: {boxes} boxes) need a {} MiB particle buffer and \
                     a {} MiB box buffer; this device allocates at most {} MiB at once and \
                     builds BLASes of at most {blas_limit} boxes (a larger cluster size needs \
                     fewer boxes)",
                    (want as u64 * 16) >> 20,
                    (boxes * BOX_BYTES) >> 20,
                    limit >> 20,
                ),
            ));
        }
        if want > self.capacity {
            // Grow by at least a quarter, so a series whose counts creep up reallocates rarely.
            let grown = if self.capacity == 0 {
                want
            } else {
                want.max(self.capacity + self.capacity / 4)
                    .min((limit / BOX_BYTES) as usize)
                    .max(want)
            };
            self.structure = None;
            self.buffers.points = addressed(&self.ctx, "particles", grown as u64 * 16)?;
            self.buffers.radius = addressed(&self.ctx, "radius attribute", grown as u64 * 4)?;
            self.buffers.boxes = boxes_buffer(&self.ctx, grown as u64)?;
            self.capacity = grown;
            self.write_descriptors();
        }
        let boxes = k.clusters_for(self.capacity) as u32;
        if self.structure.as_ref().is_none_or(|s| s.boxes != boxes) {
            self.structure = None;
            self.structure = Some(Structure::new(&self.ctx, boxes)?);
            self.write_tlas_descriptor();
        }
        Ok(())
    }

    /// Writes the map tables (density, radius and colour from the step, optical density and
    /// colour from `frame` when given) and the parameter block.
    pub(super) fn write_params(&mut self, frame: Option<&FrameParams>) -> Result<(), BackendError> {
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let d = &up.data;
        let zeros = vec![0.0f32; TABLE_SIZE];
        let optical = frame.map_or(&zeros[..], |f| &f.optical_table[..]);
        let colour = frame.map_or(&d.tables.colour[..], |f| &f.colour_table[..]);
        if optical.len() != TABLE_SIZE || colour.len() != TABLE_SIZE {
            return Err(device_error(
                "map tables",
                format!("expected {TABLE_SIZE} samples per table"),
            ));
        }
        let tables = pack_map_tables(&d.tables.density, &d.tables.radius, optical, colour);
        if tables != self.tables {
            self.buffers
                .tables
                .write(0, bytemuck::cast_slice(&tables))?;
            self.tables = tables;
        }
        let gpu_frame = frame.map_or(GpuFrame::default(), |f| GpuFrame::new(f, d.origin));
        let mut bytes = bytemuck::bytes_of(&gpu_frame).to_vec();
        bytes.extend_from_slice(bytemuck::bytes_of(&d.field));
        self.buffers.params.write(0, &bytes)
    }
}
