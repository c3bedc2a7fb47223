//! The native backend: the paper's method on a Vulkan ray-tracing pipeline (ash).
//!
//! - Range queries run on the RT pipeline (hardware on NVIDIA / AMD / Intel GPUs, software in
//!   Mesa lavapipe): a field query at x is a ray from x along (1, 1, 1) with
//!   tmin = tmax = 0 (see `shaders_glsl/vulkan/field_query.glsl`), an intersection shader that
//!   tests each particle of the hit box and an any-hit shader that sums the RBF terms.
//! - The structure is an AABB BLAS with one box per cluster of K Hilbert-sorted particles,
//!   written by a compute shader (`boxes.comp`) from positions, radius map and global radius;
//!   a new step is a full build, a radius change a refit ([`structure`]).
//! - Rendering runs the shared integrators (`shaders_glsl/shared/integrators.glsl`) in the
//!   ray-generation shader and sums frames into an f32 buffer.
//! - Buffers, BLAS storage and scratch are sized for the largest step seen (or the
//!   [`Backend::reserve`]d maximum), so a series' steps reuse them; the box buffer's tail past
//!   a step's clusters holds NaN boxes, and a build covers the step's clusters only (see
//!   [`structure`] for why).
//! - [`Traversal::Lbvh`] swaps the RT pipeline for the shared LBVH stack traversal
//!   (`shared/lbvh.glsl`, the wgpu backend's) in a compute pipeline on the same device, with the
//!   same particles, maps, RBF code and integrators: the paper's Fig. 10a comparison of
//!   hardware and software traversal on one device, one API, one integrator. Its tree is built
//!   on the CPU ([`crate::backend::shaders::cpu`], the twin of the wgpu backend's GPU build).
//!
//! One Vulkan device serves the whole process ([`context::shared`]).

pub mod context;
pub mod pipelines;
pub mod resources;
pub mod structure;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;
use glam::DVec3;
use gpu_allocator::MemoryLocation;

use self::context::{Context, NAME, device_error};
use self::pipelines::{BindingTable, ComputeKind, Push, binding};
use self::resources::{Buffer, Commands, barrier};
use self::structure::{BOX_BYTES, Structure};
use super::gpu_data::GpuStepData;
use super::{Backend, BackendError, Capabilities, MemoryReport, StepInput, Timings};
use crate::accel::ClusterSize;
use crate::backend::shaders::cpu::{
    Lbvh, cluster_box::lbvh_bounds, lbvh_keys::KeyGrid, rbf::RadiusRule,
};
use crate::backend::shaders::{GpuField, GpuFrame, SpecConstants, pack_map_tables};
use crate::field::{Classification, FieldSettings};
use crate::noise::BlueNoiseMask;
use crate::values::ColourMode;
use crate::values::FrameParams;
use crate::values::Image;
use crate::values::shader_constants::{
    STBN_DEPTH, STBN_HEIGHT, STBN_WIDTH, TABLE_FLOATS, TABLE_SIZE,
};
use crate::values::{Bounds, Step};

pub use self::context::{REQUIRED_EXTENSIONS, validation_messages};

/// Queries per launch (the query buffers hold this many points).
const QUERY_BATCH: usize = 1 << 18;
/// Row width of query launches and of the box kernel's 2D dispatch.
const QUERY_WIDTH: u32 = 1024;
const BOX_GROUP: u32 = 64;
const BOX_ROW: u32 = BOX_GROUP * 1024;

/// Timestamp slots: a build or refit uses all four, a query or render launch the first two.
const TS_START: u32 = 0;
const TS_BOXES: u32 = 1;
const TS_END: u32 = 1;
const TS_BLAS: u32 = 2;
const TS_TLAS: u32 = 3;
const TS_COUNT: u32 = 4;

/// GPU time of the last structure build or refit, by stage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StructureTimings {
    /// The box kernel.
    pub boxes: Duration,
    /// The BLAS build or refit.
    pub blas: Duration,
    /// The TLAS build.
    pub tlas: Duration,
    /// Whether the last one was a refit.
    pub refit: bool,
}

/// How the RT pipeline reports what a box's particles add (`shaders_glsl/vulkan/particle.rint`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum HitReports {
    /// One report per box with its particles' sum: counted exactly once on any driver (the
    /// geometry's NO_DUPLICATE_ANY_HIT_INVOCATION promises one any-hit call per primitive).
    #[default]
    PerCluster,
    /// One report per particle, as the paper does (for the traversal study). For clusters of
    /// more than one particle a driver may call any-hit once for several reports of a box and
    /// undercount; lavapipe does not.
    PerParticle,
}

/// How field queries find the particles around a point.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Traversal {
    /// The ray-tracing pipeline over the AABB BLAS (hardware where the GPU has RT cores).
    #[default]
    RtPipeline,
    /// A compute pipeline walking an LBVH with a per-thread stack (`shared/lbvh.glsl`).
    Lbvh,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Launch {
    Query,
    Render,
}

/// Whether this machine has a Vulkan device with ray-tracing pipelines (probes once).
pub fn available() -> Result<String, BackendError> {
    context::shared().map(|c| c.describe())
}

/// The uploaded step, kept to refit and to re-read a radius attribute.
struct Uploaded {
    step: Step,
    field: FieldSettings,
    series_bounds: Bounds,
    series_range: Option<(f64, f64)>,
    data: GpuStepData,
}

struct Buffers {
    params: Buffer,
    points: Buffer,
    /// The lo parts of double-single positions (a placeholder when the step has none).
    points_lo: Buffer,
    radius: Buffer,
    tables: Buffer,
    stbn: Buffer,
    accum: Buffer,
    query_points: Buffer,
    query_results: Buffer,
    boxes: Buffer,
    lbvh_nodes: Buffer,
    lbvh_boxes: Buffer,
}

/// A buffer the shaders reach by device address (so its size is bound by the allocation
/// limit, not by maxStorageBufferRange).
fn addressed(ctx: &Arc<Context>, name: &str, size: u64) -> Result<Buffer, BackendError> {
    Buffer::new(
        ctx,
        name,
        size,
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        MemoryLocation::GpuOnly,
    )
}

fn storage(ctx: &Arc<Context>, name: &str, size: u64) -> Result<Buffer, BackendError> {
    Buffer::new(
        ctx,
        name,
        size,
        vk::BufferUsageFlags::STORAGE_BUFFER,
        MemoryLocation::GpuOnly,
    )
}

fn boxes_buffer(ctx: &Arc<Context>, boxes: u64) -> Result<Buffer, BackendError> {
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

/// Uploads the lo parts of double-single positions, if the step has them, into `buffer`
/// (grown to `capacity` particles the first time a step needs them).
fn write_points_lo(
    ctx: &Arc<Context>,
    buffer: &mut Buffer,
    capacity: usize,
    data: &GpuStepData,
) -> Result<(), BackendError> {
    let Some(lo) = &data.points_lo else {
        return Ok(());
    };
    let need = capacity as u64 * 16;
    if buffer.size < need {
        *buffer = addressed(ctx, "particle lo parts", need)?;
    }
    buffer.write(0, bytemuck::cast_slice(lo))
}

/// The ash ray-tracing backend.
pub struct AshBackend {
    ctx: Arc<Context>,
    capabilities: Capabilities,
    commands: Commands,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    buffers: Buffers,
    structure: Option<Structure>,
    uploaded: Option<Uploaded>,
    /// Particles the buffers hold.
    capacity: usize,
    reserved: usize,
    /// The map-table buffer's contents.
    tables: Vec<f32>,
    accum_size: Option<(u32, u32)>,
    frames: u32,
    binding_tables: HashMap<SpecConstants, BindingTable>,
    timings: Timings,
    structure_timings: StructureTimings,
    traversal: Traversal,
    hit_reports: HitReports,
    /// The LBVH over the current particles and radii, when built (`Traversal::Lbvh`).
    lbvh: Option<Lbvh>,
}

impl AshBackend {
    /// A backend on the process's shared Vulkan device; `Unavailable` when this machine has no
    /// device with ray-tracing pipelines (the message says what each device lacks).
    pub fn new() -> Result<AshBackend, BackendError> {
        let ctx = context::shared()?;
        let commands = Commands::new(&ctx, TS_COUNT)?;
        let mask = BlueNoiseMask::builtin();
        if (mask.width, mask.height, mask.depth) != (STBN_WIDTH, STBN_HEIGHT, STBN_DEPTH) {
            return Err(device_error(
                "blue-noise mask",
                "the shaders expect the built-in 128 x 128 x 64 mask",
            ));
        }
        let words = mask.packed_words();
        let mut buffers = Buffers {
            params: Buffer::new(
                &ctx,
                "parameters",
                (std::mem::size_of::<GpuFrame>() + std::mem::size_of::<GpuField>()) as u64,
                vk::BufferUsageFlags::UNIFORM_BUFFER,
                MemoryLocation::GpuOnly,
            )?,
            points: addressed(&ctx, "particles", 16)?,
            points_lo: addressed(&ctx, "particle lo parts", 16)?,
            radius: addressed(&ctx, "radius attribute", 16)?,
            tables: storage(&ctx, "map tables", (TABLE_FLOATS * 4) as u64)?,
            stbn: storage(&ctx, "blue-noise mask", (words.len() * 4) as u64)?,
            accum: addressed(&ctx, "accumulation", 16)?,
            query_points: storage(&ctx, "query points", (QUERY_BATCH * 16) as u64)?,
            query_results: storage(&ctx, "query results", (QUERY_BATCH * 16) as u64)?,
            boxes: boxes_buffer(&ctx, 1)?,
            lbvh_nodes: storage(&ctx, "LBVH nodes", 32)?,
            lbvh_boxes: storage(&ctx, "LBVH boxes", 32)?,
        };
        buffers.stbn.write(0, bytemuck::cast_slice(&words))?;

        let sizes = [
            vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                .descriptor_count(1),
            vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::UNIFORM_BUFFER)
                .descriptor_count(1),
            vk::DescriptorPoolSize::default()
                .ty(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(binding::STORAGE.len() as u32),
        ];
        // SAFETY: valid create infos; the pool is destroyed in Drop.
        let pool = unsafe {
            ctx.device.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default()
                    .max_sets(1)
                    .pool_sizes(&sizes),
                None,
            )
        }
        .map_err(|e| context::vk_error("creating a descriptor pool", e))?;
        let layouts = [ctx.layouts.set];
        // SAFETY: as above.
        let set = match unsafe {
            ctx.device.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default()
                    .descriptor_pool(pool)
                    .set_layouts(&layouts),
            )
        } {
            Ok(s) => s[0],
            Err(e) => {
                // SAFETY: nothing allocated from the pool.
                unsafe { ctx.device.destroy_descriptor_pool(pool, None) };
                return Err(context::vk_error("allocating a descriptor set", e));
            }
        };
        let capabilities = Capabilities {
            name: NAME,
            device: ctx.describe(),
            hardware_rt: true,
            software: ctx.info.software,
            // At K = 1 the box buffer (24 bytes per box) is the largest addressed buffer, and
            // one BLAS holds at most max_primitive_count boxes (the BLAS itself may run out of
            // memory first; that is reported when it is allocated).
            max_particles: Some(
                (ctx.info.max_allocation / BOX_BYTES).min(ctx.info.max_primitive_count) as usize,
            ),
        };
        let mut backend = AshBackend {
            ctx,
            capabilities,
            commands,
            pool,
            set,
            buffers,
            structure: None,
            uploaded: None,
            capacity: 0,
            reserved: 0,
            tables: vec![0.0; TABLE_FLOATS],
            accum_size: None,
            frames: 0,
            binding_tables: HashMap::new(),
            timings: Timings::default(),
            structure_timings: StructureTimings::default(),
            traversal: Traversal::default(),
            hit_reports: HitReports::default(),
            lbvh: None,
        };
        backend.write_descriptors();
        Ok(backend)
    }

    /// Chooses how queries and frames traverse the particles. The RT structure is built in
    /// either case; the LBVH is built (on the CPU) when first needed.
    pub fn set_traversal(&mut self, traversal: Traversal) {
        self.traversal = traversal;
    }

    pub fn traversal(&self) -> Traversal {
        self.traversal
    }

    /// Chooses how the RT pipeline reports hits ([`HitReports`]).
    pub fn set_hit_reports(&mut self, reports: HitReports) {
        self.hit_reports = reports;
    }

    /// The LBVH's depth (internal nodes on its longest path), once built.
    pub fn lbvh_depth(&self) -> Option<u32> {
        self.lbvh.as_ref().map(|t| t.depth)
    }

    /// GPU time of the last build or refit, by stage.
    pub fn structure_timings(&self) -> StructureTimings {
        self.structure_timings
    }

    /// Bytes of the BLAS (0 before the first build).
    pub fn blas_bytes(&self) -> u64 {
        self.structure.as_ref().map_or(0, Structure::blas_bytes)
    }

    /// Boxes the BLAS storage and the box buffer are sized for (clusters of the capacity).
    pub fn blas_boxes(&self) -> u32 {
        self.structure.as_ref().map_or(0, |s| s.boxes)
    }

    /// Boxes (primitives) the last build covered: the uploaded step's clusters.
    pub fn blas_active_boxes(&self) -> u32 {
        self.structure.as_ref().map_or(0, |s| s.active)
    }

    /// The local-coordinate origin of the uploaded step (data = local + origin).
    pub fn origin(&self) -> Option<DVec3> {
        self.uploaded.as_ref().map(|u| u.data.origin)
    }

    /// The cluster boxes the box kernel wrote (local coordinates, `[min, max]`), one per slot
    /// of the box buffer (NaN past the step's clusters): for tests against
    /// `accel::ClusterBoxes`.
    pub fn read_boxes(&mut self) -> Result<Vec<[f32; 6]>, BackendError> {
        let n = self.blas_boxes() as u64;
        let bytes = self.buffers.boxes.read(n * BOX_BYTES)?;
        Ok(bytemuck::pod_collect_to_vec::<u8, f32>(&bytes)
            .chunks_exact(6)
            .map(|c| [c[0], c[1], c[2], c[3], c[4], c[5]])
            .collect())
    }

    fn write_descriptors(&mut self) {
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

    fn write_tlas_descriptor(&self) {
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
    fn ensure_capacity(&mut self, n: usize, k: ClusterSize) -> Result<(), BackendError> {
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
    fn write_params(&mut self, frame: Option<&FrameParams>) -> Result<(), BackendError> {
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

    /// The specialisation constants for the uploaded step and the given frame settings.
    fn spec(
        &self,
        integrator: u32,
        colour: u32,
        noise: u32,
    ) -> Result<SpecConstants, BackendError> {
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let d = &up.data;
        Ok(SpecConstants {
            integrator,
            colour_mode: colour,
            noise_kind: noise,
            cluster_size: d.cluster.get() as u32,
            radius_map_varies: u32::from(d.radius_map_varies),
            density_map_varies: u32::from(d.density_map_varies),
            has_radius_attribute: u32::from(d.radius_attribute.is_some()),
            position_ds: u32::from(d.double_single()),
            rt_hit_per_particle: u32::from(self.hit_reports == HitReports::PerParticle),
        })
    }

    /// The colour mode a query uses: what Theta's numerator sums for this field.
    fn query_colour(&self) -> u32 {
        let field = self.uploaded.as_ref().map(|u| &u.field);
        SpecConstants::colour_id(match field {
            Some(f) if f.attribute.is_none() => ColourMode::Density,
            Some(f) if f.classification == Classification::Pre => ColourMode::Pre,
            _ => ColourMode::Post,
        })
    }

    /// The RT pipeline and binding table for `spec`.
    fn rt(&mut self, spec: SpecConstants) -> Result<(vk::Pipeline, &BindingTable), BackendError> {
        let pipeline = pipelines::rt_pipeline(&self.ctx, spec)?;
        if !self.binding_tables.contains_key(&spec) {
            let table = BindingTable::new(&self.ctx, pipeline)?;
            self.binding_tables.insert(spec, table);
        }
        Ok((pipeline, &self.binding_tables[&spec]))
    }

    fn bind(
        &self,
        cb: vk::CommandBuffer,
        point: vk::PipelineBindPoint,
        pipeline: vk::Pipeline,
        push: Push,
    ) {
        let push = Push {
            particle_address: self.buffers.points.address,
            radius_address: self.buffers.radius.address,
            boxes_address: self.buffers.boxes.address,
            accum_address: self.buffers.accum.address,
            particle_lo_address: self.buffers.points_lo.address,
            ..push
        };
        let device = &self.ctx.device;
        // SAFETY: recording; the set matches the pipeline layout.
        unsafe {
            device.cmd_bind_pipeline(cb, point, pipeline);
            device.cmd_bind_descriptor_sets(
                cb,
                point,
                self.ctx.layouts.pipeline,
                0,
                &[self.set],
                &[],
            );
            device.cmd_push_constants(
                cb,
                self.ctx.layouts.pipeline,
                vk::ShaderStageFlags::ALL,
                0,
                bytemuck::bytes_of(&push),
            );
        }
    }

    /// Writes the boxes, then builds (or refits) the BLAS and builds the TLAS, timed.
    fn build_structure(&mut self, update: bool) -> Result<(), BackendError> {
        let spec = self.spec(0, 0, 0)?;
        let boxes_pipeline = pipelines::compute_pipeline(&self.ctx, ComputeKind::Boxes, spec)?;
        let boxes_address = self.buffers.boxes.address;
        let structure = self
            .structure
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        // The kernel writes every box of the buffer (NaN past the step); the build takes the
        // step's clusters only (see `structure`).
        let count = structure.boxes;
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let active = up.data.cluster.clusters_for(up.data.points.len()) as u32;
        let started = Instant::now();
        let cb = self.commands.begin()?;
        self.commands.timestamp(TS_START);
        self.bind(
            cb,
            vk::PipelineBindPoint::COMPUTE,
            boxes_pipeline,
            Push {
                count,
                width: BOX_ROW,
                ..Push::default()
            },
        );
        let groups = count.div_ceil(BOX_GROUP);
        // SAFETY: recording with the pipeline and set bound.
        unsafe {
            self.ctx.device.cmd_dispatch(
                cb,
                groups.min(BOX_ROW / BOX_GROUP),
                count.div_ceil(BOX_ROW).max(1),
                1,
            )
        };
        barrier(
            &self.ctx,
            cb,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_WRITE,
            ),
            (
                vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR,
            ),
        );
        self.commands.timestamp(TS_BOXES);
        let commands = &self.commands;
        let structure = self.structure.as_mut().expect("checked above");
        if !update {
            structure.built = false;
        }
        structure.record(cb, boxes_address, active, update, || {
            commands.timestamp(TS_BLAS)
        })?;
        self.commands.timestamp(TS_TLAS);
        self.commands.submit_and_wait()?;
        let structure = self.structure.as_mut().expect("checked above");
        structure.built = true;
        let wall = started.elapsed();
        let c = &self.commands;
        self.structure_timings = StructureTimings {
            boxes: c.elapsed(TS_START, TS_BOXES).unwrap_or_default(),
            blas: c.elapsed(TS_BOXES, TS_BLAS).unwrap_or_default(),
            tlas: c.elapsed(TS_BLAS, TS_TLAS).unwrap_or_default(),
            refit: update,
        };
        let total = c.elapsed(TS_START, TS_TLAS).unwrap_or(wall);
        if update {
            self.timings.refit = total;
        } else {
            self.timings.build = total;
        }
        Ok(())
    }

    /// Records and runs one query or render launch over `size` (queries: a count laid out in
    /// rows of `QUERY_WIDTH`; frames: pixels) with the current traversal, after filling
    /// `poison` (buffer, bytes; 0 for none) with NaN. Returns the launch's GPU time.
    fn launch(
        &mut self,
        launch: Launch,
        spec: SpecConstants,
        push: Push,
        poison: (vk::Buffer, u64),
        size: (u32, u32),
    ) -> Result<Duration, BackendError> {
        let (w, h) = match launch {
            Launch::Query => (size.0.min(QUERY_WIDTH), size.0.div_ceil(QUERY_WIDTH)),
            Launch::Render => size,
        };
        enum Work {
            Rays(vk::Pipeline, [vk::StridedDeviceAddressRegionKHR; 3]),
            Compute(vk::Pipeline, [u32; 2]),
        }
        let work = match self.traversal {
            Traversal::RtPipeline => {
                let (pipeline, table) = self.rt(spec)?;
                let raygen = match launch {
                    Launch::Query => table.query,
                    Launch::Render => table.render,
                };
                Work::Rays(pipeline, [raygen, table.miss, table.hit])
            }
            Traversal::Lbvh => {
                self.ensure_lbvh()?;
                let (kind, group) = match launch {
                    Launch::Query => (ComputeKind::LbvhQuery, [64, 1]),
                    Launch::Render => (ComputeKind::LbvhRender, [8, 8]),
                };
                let pipeline = pipelines::compute_pipeline(&self.ctx, kind, spec)?;
                Work::Compute(pipeline, [w.div_ceil(group[0]), h.div_ceil(group[1])])
            }
        };
        let (stage, point) = match work {
            Work::Rays(..) => (
                vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR,
                vk::PipelineBindPoint::RAY_TRACING_KHR,
            ),
            Work::Compute(..) => (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineBindPoint::COMPUTE,
            ),
        };
        let cb = self.commands.begin()?;
        if poison.1 > 0 {
            // SAFETY: recording; the buffer is alive and at least that large.
            unsafe {
                self.ctx
                    .device
                    .cmd_fill_buffer(cb, poison.0, 0, poison.1, f32::NAN.to_bits())
            };
            barrier(
                &self.ctx,
                cb,
                (
                    vk::PipelineStageFlags::TRANSFER,
                    vk::AccessFlags::TRANSFER_WRITE,
                ),
                (
                    stage,
                    vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                ),
            );
        }
        self.commands.timestamp(TS_START);
        match work {
            Work::Rays(pipeline, [raygen, miss, hit]) => {
                self.bind(cb, point, pipeline, push);
                // SAFETY: recording with the pipeline, set and push constants bound.
                unsafe {
                    self.ctx.rt.cmd_trace_rays(
                        cb,
                        &raygen,
                        &miss,
                        &hit,
                        &vk::StridedDeviceAddressRegionKHR::default(),
                        w,
                        h,
                        1,
                    )
                };
            }
            Work::Compute(pipeline, groups) => {
                self.bind(cb, point, pipeline, push);
                // SAFETY: as above.
                unsafe { self.ctx.device.cmd_dispatch(cb, groups[0], groups[1], 1) };
            }
        }
        self.commands.timestamp(TS_END);
        barrier(
            &self.ctx,
            cb,
            (stage, vk::AccessFlags::SHADER_WRITE),
            (
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::HOST,
                vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::HOST_READ,
            ),
        );
        self.commands.submit_and_wait()?;
        Ok(self.commands.elapsed(TS_START, TS_END).unwrap_or_default())
    }

    /// Builds the LBVH over the uploaded particles and current radii (on the CPU, with the
    /// wgpu backend's twin build) and uploads it, unless it is current.
    fn ensure_lbvh(&mut self) -> Result<(), BackendError> {
        if self.lbvh.is_some() {
            return Ok(());
        }
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let d = &up.data;
        let rule = RadiusRule {
            field: d.field,
            radius_table: d.radius_map_varies.then_some(&d.tables.radius[..]),
            radius_attribute: d.radius_attribute.as_deref(),
        };
        let boxes = lbvh_bounds(&d.points, d.cluster.get(), &rule);
        let tree = Lbvh::build(&boxes, &KeyGrid::new(up.series_bounds, d.origin));
        if tree.depth > crate::backend::shaders::cpu::lbvh::LBVH_STACK_SIZE {
            return Err(device_error(
                "building the LBVH",
                format!("depth {} exceeds the traversal stack", tree.depth),
            ));
        }
        let nodes: &[u8] = bytemuck::cast_slice(&tree.nodes);
        let box_bytes: &[u8] = bytemuck::cast_slice(&boxes);
        let range = self.ctx.info.max_storage_buffer_range;
        if nodes.len().max(box_bytes.len()) as u64 > range {
            return Err(device_error(
                "building the LBVH",
                format!(
                    "{} clusters exceed this device's storage-buffer limit \
                     (maxStorageBufferRange = {} MiB); use a larger cluster size",
                    boxes.len(),
                    range >> 20
                ),
            ));
        }
        let mut rebind = false;
        if nodes.len() as u64 > self.buffers.lbvh_nodes.size {
            self.buffers.lbvh_nodes = storage(&self.ctx, "LBVH nodes", nodes.len() as u64)?;
            rebind = true;
        }
        if box_bytes.len() as u64 > self.buffers.lbvh_boxes.size {
            self.buffers.lbvh_boxes = storage(&self.ctx, "LBVH boxes", box_bytes.len() as u64)?;
            rebind = true;
        }
        self.buffers.lbvh_nodes.write(0, nodes)?;
        self.buffers.lbvh_boxes.write(0, box_bytes)?;
        if rebind {
            self.write_descriptors();
        }
        self.lbvh = Some(tree);
        Ok(())
    }

    fn built(&self) -> Result<(), BackendError> {
        match &self.structure {
            Some(s) if s.built && self.uploaded.is_some() => Ok(()),
            _ => Err(BackendError::NothingUploaded(NAME)),
        }
    }

    /// Applies new maps (and radii) to the uploaded step's GPU data.
    fn apply_field(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let up = self
            .uploaded
            .as_mut()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let changed = up
            .data
            .apply_field(&up.step, &up.field, field, up.series_range)?;
        if changed.radius_attribute
            && let Some(h) = &up.data.radius_attribute
        {
            self.buffers.radius.write(0, bytemuck::cast_slice(h))?;
        }
        if changed.positions_lo {
            write_points_lo(
                &self.ctx,
                &mut self.buffers.points_lo,
                self.capacity,
                &up.data,
            )?;
        }
        up.field = field.clone();
        self.write_params(None)
    }
}

impl Backend for AshBackend {
    fn capabilities(&self) -> &Capabilities {
        &self.capabilities
    }

    /// Sizes the buffers, BLAS and scratch for steps of up to `max_particles` particles (a
    /// series' maximum), so every step of the series reuses them (the box buffer's tail past a
    /// step's clusters holds NaN boxes). Without it, buffers grow to the largest step seen.
    fn reserve(&mut self, max_particles: usize) {
        self.reserved = self.reserved.max(max_particles);
    }

    fn upload(&mut self, input: &StepInput<'_>) -> Result<(), BackendError> {
        let started = Instant::now();
        let data = GpuStepData::prepare(input)?;
        self.uploaded = None;
        self.ensure_capacity(data.points.len(), data.cluster)?;
        if let Some(s) = &mut self.structure {
            s.built = false;
        }
        self.buffers
            .points
            .write(0, bytemuck::cast_slice(&data.points))?;
        write_points_lo(&self.ctx, &mut self.buffers.points_lo, self.capacity, &data)?;
        if let Some(h) = &data.radius_attribute {
            self.buffers.radius.write(0, bytemuck::cast_slice(h))?;
        }
        self.uploaded = Some(Uploaded {
            step: input.step.clone(),
            field: input.field.clone(),
            series_bounds: input.series_bounds,
            series_range: input.series_range,
            data,
        });
        self.lbvh = None;
        self.write_params(None)?;
        self.timings.upload = started.elapsed();
        Ok(())
    }

    fn build(&mut self) -> Result<(), BackendError> {
        if self.uploaded.is_none() {
            return Err(BackendError::NothingUploaded(NAME));
        }
        self.write_params(None)?;
        self.build_structure(false)
    }

    fn refit(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        self.apply_field(field)?;
        self.lbvh = None;
        if self.structure.as_ref().is_some_and(|s| s.built) {
            self.build_structure(true)
        } else {
            // Nothing built yet: the next build uses the new radii.
            Ok(())
        }
    }

    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        self.apply_field(field)
    }

    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        self.built()?;
        self.write_params(None)?;
        let spec = self.spec(0, self.query_colour(), 0)?;
        let double_single = self.uploaded.as_ref().expect("built").data.double_single();
        // The query buffer holds QUERY_BATCH vec4s: as many points, or half as many hi/lo pairs.
        let batch = if double_single {
            QUERY_BATCH / 2
        } else {
            QUERY_BATCH
        };
        let mut out = Vec::with_capacity(points.len());
        let mut gpu_time = Duration::ZERO;
        let started = Instant::now();
        let mut local: Vec<[f32; 4]> = Vec::with_capacity(QUERY_BATCH);
        for chunk in points.chunks(batch) {
            local.clear();
            let data = &self.uploaded.as_ref().expect("built").data;
            for &x in chunk {
                data.push_query(x, &mut local);
            }
            self.buffers
                .query_points
                .write(0, bytemuck::cast_slice(&local))?;
            let n = chunk.len() as u32;
            let push = Push {
                count: n,
                width: QUERY_WIDTH,
                query_lo: u32::from(double_single),
                ..Push::default()
            };
            // Poison the results, so an unwritten one shows as NaN.
            let poison = (self.buffers.query_results.raw, u64::from(n) * 16);
            gpu_time += self.launch(Launch::Query, spec, push, poison, (n, 1))?;
            let bytes = self.buffers.query_results.read(u64::from(n) * 16)?;
            let values = bytemuck::pod_collect_to_vec::<u8, f32>(&bytes);
            out.extend(values.chunks_exact(4).map(|v| {
                (
                    f64::from(v[0]),
                    [f64::from(v[1]), f64::from(v[2]), f64::from(v[3])],
                )
            }));
        }
        self.timings.query = if self.ctx.info.timestamp_period.is_some() {
            gpu_time
        } else {
            started.elapsed()
        };
        Ok(out)
    }

    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        self.built()?;
        let (w, h) = (frame.width, frame.height);
        let invocations = u64::from(w) * u64::from(h);
        if w == 0 || h == 0 || invocations > u64::from(self.ctx.info.max_dispatch_invocations) {
            return Err(device_error(
                "rendering",
                format!(
                    "a {w} x {h} image exceeds the device's ray-dispatch limit of {} rays",
                    self.ctx.info.max_dispatch_invocations
                ),
            ));
        }
        // The kernels reach the accumulation by device address, so only the allocation limit
        // applies (not maxStorageBufferRange, which a 4K image outgrows on lavapipe).
        let limit = self.ctx.info.max_allocation;
        if invocations * 16 > limit {
            return Err(device_error(
                "rendering",
                format!(
                    "a {w} x {h} accumulation buffer ({} MiB) exceeds this device's largest \
                     allocation (maxMemoryAllocationSize = {} MiB)",
                    (invocations * 16) >> 20,
                    limit >> 20
                ),
            ));
        }
        if self.accum_size != Some((w, h)) {
            self.accum_size = None;
            // Reached through the push constants, not a descriptor: nothing to rewrite.
            self.buffers.accum = addressed(&self.ctx, "accumulation", invocations * 16)?;
            self.accum_size = Some((w, h));
            self.frames = 0;
        }
        self.write_params(Some(frame))?;
        let spec = self.spec(
            SpecConstants::integrator_id(frame.integrator),
            SpecConstants::colour_id(frame.colour),
            SpecConstants::noise_id(frame.noise),
        )?;
        let first = self.frames == 0;
        let push = Push {
            first_frame: u32::from(first),
            ..Push::default()
        };
        // On a first frame, poison the accumulation: a pixel the frame misses shows as NaN.
        let poison = (
            self.buffers.accum.raw,
            if first { vk::WHOLE_SIZE } else { 0 },
        );
        let started = Instant::now();
        let gpu = self.launch(Launch::Render, spec, push, poison, (w, h))?;
        self.frames += 1;
        self.timings.frame = if self.ctx.info.timestamp_period.is_some() {
            gpu
        } else {
            started.elapsed()
        };
        Ok(())
    }

    fn reset(&mut self) {
        self.frames = 0;
    }

    fn image(&mut self) -> Result<Image, BackendError> {
        let (w, h) = self.accum_size.ok_or(BackendError::NothingUploaded(NAME))?;
        let n = f64::from(self.frames.max(1));
        let pixels = if self.frames == 0 {
            vec![[0.0; 4]; (w as usize) * (h as usize)]
        } else {
            let bytes = self.buffers.accum.read(u64::from(w) * u64::from(h) * 16)?;
            bytemuck::pod_collect_to_vec::<u8, f32>(&bytes)
                .chunks_exact(4)
                .map(|s| std::array::from_fn(|c| (f64::from(s[c]) / n) as f32))
                .collect()
        };
        Ok(Image {
            width: w,
            height: h,
            pixels,
        })
    }

    fn timings(&self) -> Timings {
        self.timings
    }

    fn positions(&self) -> Option<super::Positions> {
        self.uploaded.as_ref().map(|u| u.data.positions())
    }

    fn memory(&self) -> MemoryReport {
        MemoryReport {
            particle_bytes: self
                .uploaded
                .as_ref()
                .map_or(0, |u| u.data.particle_bytes()),
            structure_bytes: self.structure.as_ref().map_or(0, |s| {
                (s.total_bytes() + u64::from(s.boxes) * BOX_BYTES) as usize
            }) + self.lbvh.as_ref().map_or(0, |t| {
                t.nodes.len() * crate::backend::shaders::cpu::lbvh::NODE_BYTES
                    + t.leaf_parents.len() * crate::backend::shaders::cpu::lbvh::BOX_BYTES
            }),
            image_bytes: self
                .accum_size
                .map_or(0, |(w, h)| (w as usize) * (h as usize) * 16),
        }
    }
}

impl Drop for AshBackend {
    fn drop(&mut self) {
        // SAFETY: every submission was waited for; the set goes with its pool.
        unsafe { self.ctx.device.destroy_descriptor_pool(self.pool, None) };
    }
}
