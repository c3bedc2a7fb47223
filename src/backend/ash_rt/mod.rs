//! The native backend: the paper's method on a Vulkan ray-tracing pipeline (ash).
//!
//! - Range queries run on the RT pipeline (hardware on NVIDIA / AMD / Intel GPUs, software in
//!   Mesa lavapipe): a field query at x is a ray from x along (1, 1, 1) with
//!   tmin = tmax = 0 (see `shaders_glsl/vulkan/field_query.glsl`), an intersection shader that
//!   tests each particle of the hit box and an any-hit shader that sums the RBF terms.
//! - A step is prepared on the device ([`prepare`]): the CPU converts it once into staging
//!   memory, compute passes sort it along the Hilbert curve and gather it.
//! - The structure is an AABB BLAS with one box per cluster of K Hilbert-sorted particles,
//!   written by a compute shader (`blas_boxes.comp`) from positions, radius map and global radius;
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
//!   on the CPU ([`crate::accel::lbvh`], the build the wgpu backend runs on the device).
//!
//! One Vulkan device serves the whole process ([`context::shared`]).
//!
//! Files: `context` (instance, device, its limits and the validation messenger), `resources`
//! (buffers, command submission, timestamps), `pipelines` (descriptor layout, RT and compute
//! pipelines, binding table), `buffers` (the backend's buffers, descriptors and parameter
//! block), `prepare` (the step's preparation on the device), `structure` (BLAS and TLAS), `build` (box kernel, build and refit, the LBVH for the
//! software traversal), `launch` (specialisation, push constants, one timed launch), and here
//! the backend itself.

mod buffers;
mod build;
pub mod context;
mod inspect;
mod launch;
#[cfg(test)]
mod naga_spirv;
mod owned;
pub mod pipelines;
mod prepare;
pub mod resources;
pub mod structure;
mod voxel;

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ash::vk;
use glam::DVec3;
use gpu_allocator::MemoryLocation;

use self::buffers::{Buffers, addressed, boxes_buffer, ensure_points_lo, storage};
use self::context::{Context, NAME, device_error};
use self::launch::Launch;
use self::pipelines::{BindingTable, Push};
use self::prepare::{Prepare, Targets};
use self::resources::{Buffer, Commands};
use self::structure::{BOX_BYTES, Structure};
use super::gpu_data::{GpuStepData, SortedParticles};
use super::{Backend, BackendError, Capabilities, MemoryReport, StepInput, Timings};
use crate::accel::lbvh::Lbvh;
use crate::backend::shaders::brick::BrickLaunch;
use crate::backend::shaders::{GpuFrame, GpuVoxels, SpecConstants};
use crate::field::FieldSettings;
use crate::noise::BlueNoiseMask;
use crate::values::FrameParams;
use crate::values::Image;
use crate::values::shader_constants::{STBN_DEPTH, STBN_HEIGHT, STBN_WIDTH, TABLE_FLOATS};
use crate::values::{Bounds, Step};

pub use self::context::{REQUIRED_EXTENSIONS, validation_messages};

/// Queries per launch (the query buffers hold this many points).
const QUERY_BATCH: usize = 1 << 18;
/// Row width of query launches.
pub(super) const QUERY_WIDTH: u32 = 1024;
/// Workgroups per row of the box kernel's 2D dispatch.
pub(super) const BOX_ROW_GROUPS: u32 = 1024;

/// Timestamp slots: a build or refit uses all four, a query or render launch the first two.
pub(super) const TS_START: u32 = 0;
pub(super) const TS_BOXES: u32 = 1;
pub(super) const TS_END: u32 = 1;
pub(super) const TS_BLAS: u32 = 2;
pub(super) const TS_TLAS: u32 = 3;
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

/// Whether this machine has a Vulkan device with ray-tracing pipelines (probes once).
pub fn available() -> Result<String, BackendError> {
    context::shared().map(|c| c.describe())
}

/// The uploaded step, kept to refit and to re-read a radius attribute.
struct Uploaded {
    step: std::sync::Arc<Step>,
    field: FieldSettings,
    series_bounds: Bounds,
    series_range: Option<(f64, f64)>,
    data: GpuStepData,
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
    /// The step's preparation on the device (made at the first upload).
    prepare: Option<Prepare>,
    /// Whether the preparation may read the step where the CPU wrote it (see
    /// [`prepare::Staging`]); tests turn it off to run a discrete GPU's copies.
    staging: prepare::Staging,
    /// Particles the buffers hold.
    capacity: usize,
    reserved: usize,
    /// The map-table buffer's contents.
    tables: Vec<f32>,
    accum_size: Option<(u32, u32)>,
    frames: u32,
    binding_tables: HashMap<(SpecConstants, context::RtProgram), BindingTable>,
    timings: Timings,
    structure_timings: StructureTimings,
    traversal: Traversal,
    hit_reports: HitReports,
    /// The LBVH over the current particles and radii, when built (`Traversal::Lbvh`).
    lbvh: Option<Lbvh>,
    /// The voxel baseline's grid of the last [`Backend::voxelize`].
    voxels: Option<voxel::Voxels>,
}

impl AshBackend {
    /// A backend on the process's shared Vulkan device; `Unavailable` when this machine has no
    /// device with ray-tracing pipelines (the message says what each device lacks).
    pub fn new() -> Result<AshBackend, BackendError> {
        Self::on(context::shared()?)
    }

    /// A backend on the device `ctx` opened ([`context::on_every_device`]).
    pub fn on(ctx: Arc<context::Context>) -> Result<AshBackend, BackendError> {
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
                voxel::VOXELS_OFFSET + std::mem::size_of::<GpuVoxels>() as u64,
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

        // One descriptor of each binding of the set.
        let mut sizes: Vec<vk::DescriptorPoolSize> = Vec::new();
        for (_, ty, _) in pipelines::set_bindings() {
            match sizes.iter_mut().find(|s| s.ty == ty) {
                Some(s) => s.descriptor_count += 1,
                None => sizes.push(vk::DescriptorPoolSize::default().ty(ty).descriptor_count(1)),
            }
        }
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
            scatters_grids: false,
            frame_timer: if ctx.info.timestamp_period.is_some() {
                super::FrameTimer::DeviceTimestamps
            } else {
                super::FrameTimer::SubmitToCompletion
            },
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
            prepare: None,
            staging: prepare::Staging::InPlaceWherePossible,
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
            voxels: None,
        };
        backend.write_descriptors();
        Ok(backend)
    }

    /// The uploaded step's local origin (the shaders' positions are relative to it).
    fn local_origin(&self) -> Result<DVec3, BackendError> {
        self.uploaded
            .as_ref()
            .map(|u| u.data.origin)
            .ok_or(BackendError::NothingUploaded(NAME))
    }

    fn built(&self) -> Result<(), BackendError> {
        match &self.structure {
            Some(s) if s.built && self.uploaded.is_some() => Ok(()),
            _ => Err(BackendError::NothingUploaded(NAME)),
        }
    }

    /// Makes the preparation's buffers hold at least `n` particles and the buffers' capacity.
    fn ensure_prepare(&mut self, n: usize) -> Result<(), BackendError> {
        let capacity = n.max(self.capacity);
        if self
            .prepare
            .as_ref()
            .is_none_or(|p| p.capacity() < capacity)
        {
            self.prepare = None;
            self.prepare = Some(Prepare::new(&self.ctx, capacity, self.staging)?);
        }
        Ok(())
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
        let radius = changed.factors && up.data.has_factors();
        if radius {
            self.buffers
                .ensure_factors(&self.ctx, up.data.factor_words())?;
        }
        if changed.positions_lo {
            ensure_points_lo(&self.ctx, &mut self.buffers.points_lo, self.capacity)?;
        }
        if radius || changed.positions_lo {
            let prepare = self
                .prepare
                .as_mut()
                .ok_or(BackendError::NothingUploaded(NAME))?;
            prepare.restage(&up.data, &up.step, field, radius, changed.positions_lo)?;
            let cb = self.commands.begin()?;
            prepare.record_gathers(
                cb,
                &up.data,
                radius.then_some(&self.buffers.radius),
                changed.positions_lo.then_some(&self.buffers.points_lo),
            )?;
            self.commands.submit_and_wait()?;
        }
        up.field = field.clone();
        self.write_params(None)
    }
}

impl AshBackend {
    /// One frame of `launch` (a render or a splat) added to the accumulation; `splat_k` goes
    /// into the frame's shading.w (the splatter's hits per slab).
    fn render_launch(
        &mut self,
        frame: &FrameParams,
        launch: Launch,
        splat_k: usize,
    ) -> Result<(), BackendError> {
        // The voxel march reads the grid, not the structure.
        if launch != Launch::Voxels {
            self.built()?;
        }
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
        if launch == Launch::Splat {
            let at = std::mem::offset_of!(GpuFrame, shading) + 3 * 4;
            self.buffers
                .params
                .write(at as u64, bytemuck::bytes_of(&(splat_k as f32)))?;
        }
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
        let gpu = self.launch(launch, spec, push, poison, (w, h))?;
        self.frames += 1;
        self.timings.frame = if self.ctx.info.timestamp_period.is_some() {
            gpu
        } else {
            started.elapsed()
        };
        Ok(())
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
        let staging = GpuStepData::check(input)?;
        let checked = started.elapsed();
        self.uploaded = None;
        self.ensure_capacity(staging.len(), input.cluster)?;
        self.ensure_prepare(self.capacity)?;
        let Some(prepare) = self.prepare.as_mut() else {
            return Err(BackendError::NothingUploaded(NAME));
        };
        let allocated = started.elapsed();
        let data = prepare.stage(staging, input.step)?;
        let staged = started.elapsed();
        self.timings.prepare = checked + (staged - allocated);
        if data.double_single {
            ensure_points_lo(&self.ctx, &mut self.buffers.points_lo, self.capacity)?;
        }
        self.buffers
            .ensure_factors(&self.ctx, data.factor_words())?;
        if let Some(s) = &mut self.structure {
            s.built = false;
        }
        let mut cb = self.commands.begin()?;
        if prepare.record_copy(cb, &data) {
            self.commands.submit_and_wait()?;
            cb = self.commands.begin()?;
        }
        let copied = started.elapsed();
        prepare.record(
            cb,
            &data,
            &Targets {
                points: &self.buffers.points,
                points_lo: data.double_single.then_some(&self.buffers.points_lo),
                radius: data.has_factors().then_some(&self.buffers.radius),
            },
        )?;
        self.commands.submit_and_wait()?;
        self.timings.device_prepare = started.elapsed() - copied;
        tracing::debug!(
            "ash: step '{}' ({} particles): CPU {:.1} ms, copy {:.1} ms, device preparation {:.1} ms",
            input.step.name,
            data.count,
            self.timings.prepare.as_secs_f64() * 1e3,
            (copied - staged).as_secs_f64() * 1e3,
            self.timings.device_prepare.as_secs_f64() * 1e3
        );
        self.uploaded = Some(Uploaded {
            step: input.step.clone(),
            field: input.field.clone(),
            series_bounds: input.series_bounds,
            series_range: input.series_range,
            data,
        });
        self.lbvh = None;
        self.write_params(None)?;
        self.timings.upload =
            started.elapsed() - self.timings.prepare - self.timings.device_prepare;
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
        self.render_launch(frame, Launch::Render, 0)
    }

    /// `owned.rgen` over the share's rectangle (the shared integrators' brick variant), or
    /// `lbvh_owned.comp` with [`Traversal::Lbvh`].
    fn render_owned(
        &mut self,
        frame: &FrameParams,
        share: &super::BrickShare<'_>,
    ) -> Result<Vec<[f64; 4]>, BackendError> {
        let origin = self.local_origin()?;
        let launch = BrickLaunch::render(NAME, frame, share, origin)?;
        let own_frame = share.own_frame(frame);
        let bytes = self.run_owned(own_frame.as_ref().unwrap_or(frame), &launch)?;
        Ok(BrickLaunch::pixels(&bytes))
    }

    /// `owned.rgen` (or `lbvh_owned.comp`) along the rays' rectangle.
    fn owned_depth(
        &mut self,
        frame: &FrameParams,
        owned: &crate::values::HalfOpenBox,
        rays: super::DepthRays<'_>,
    ) -> Result<Vec<f64>, BackendError> {
        let origin = self.local_origin()?;
        let launch = BrickLaunch::depth(frame, owned, rays, origin);
        let bytes = self.run_owned(frame, &launch)?;
        Ok(BrickLaunch::depths(&bytes))
    }

    /// Knoll et al.'s splatter through the RT pipeline (`splat.rgen`; the LBVH kernel
    /// `lbvh_splat.comp` with the LBVH traversal), into the same accumulation as `render`.
    fn render_splat(
        &mut self,
        frame: &FrameParams,
        k: usize,
    ) -> Result<Option<crate::field::splat::SplatCounts>, BackendError> {
        super::check_gpu_splat_k(NAME, k)?;
        self.render_launch(frame, Launch::Splat, k)?;
        Ok(None)
    }

    /// `voxel_splat.comp`: one dispatch into a grid buffer reached by device address; needs
    /// no build.
    fn voxelize(&mut self, frame: &FrameParams, n: usize) -> Result<(), BackendError> {
        self.run_voxelize(frame, n)
    }

    /// `voxel_render.comp`: the shared integrators over the grid.
    fn render_voxels(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        if self.voxels.is_none() {
            return Err(BackendError::NoVoxelGrid(NAME));
        }
        self.render_launch(frame, Launch::Voxels, 0)
    }

    fn voxel_grid(&mut self) -> Result<super::voxel::VoxelGrid, BackendError> {
        self.read_voxels()
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

    fn representation(&self) -> Option<super::Representation> {
        self.uploaded.as_ref().map(|u| u.data.representation())
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
                t.nodes.len() * crate::accel::lbvh::NODE_BYTES
                    + t.leaf_parents.len() * crate::accel::lbvh::BOX_BYTES
            }),
            image_bytes: self
                .accum_size
                .map_or(0, |(w, h)| (w as usize) * (h as usize) * 16),
            preparation_bytes: self.prepare.as_ref().map_or(0, Prepare::bytes),
            voxel_bytes: self.voxels.as_ref().map_or(0, voxel::Voxels::bytes),
        }
    }
}

impl Drop for AshBackend {
    fn drop(&mut self) {
        // SAFETY: every submission was waited for; the set goes with its pool.
        unsafe { self.ctx.device.destroy_descriptor_pool(self.pool, None) };
    }
}
