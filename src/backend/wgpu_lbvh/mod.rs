//! The portable GPU backend: wgpu compute over a GPU-built LBVH (Karras 2012). The paper's
//! software baseline, and the fallback on every GPU without ray-tracing hardware.
//!
//! - **Upload**: the CPU converts the step in one pass, in its own order, straight into mapped
//!   staging memory ([`GpuStepData`]: local coordinates, t, the radius attribute); the device
//!   copies it, computes Hilbert keys, sorts and gathers into Hilbert order (`prepare`), into
//!   buffers kept for the largest step seen (or [`Backend::reserve`]d for the series' maximum
//!   count), staging included, so stepping makes no buffer (`buffers_made`, tested); the
//!   radius-attribute buffer exists only when the scene has one. The arrays of 16-byte elements that outgrow one storage
//!   binding first (particles, LBVH nodes, cluster boxes, the accumulation) live in up to
//!   `util::PARTS` = 4 buffers each (`util::SplitBuffer`, `shaders_glsl/wgpu/split.glsl`);
//!   a step beyond that, or one whose 4-byte arrays (sort keys, parents, radius attribute)
//!   outgrow one binding, is refused with an error naming the step, the need and the limit.
//!   Every kernel exists in two layouts (`context::Layout`): the one-part layout, which a step
//!   that fits runs, binds at most 8 storage buffers per stage (WebGPU's default, checked in
//!   `build.rs`), so the backend runs on small GPUs; only a split step needs more.
//! - **Build**, every stage a compute pass: cluster boxes (`shaders_glsl/wgpu/lbvh_boxes.comp`),
//!   Morton keys (`shaders_wgsl/lbvh_keys.wgsl`), a portable LSD radix sort
//!   (`radix_sort.wgsl`), Karras' hierarchy (`lbvh_hierarchy.wgsl`) and bottom-up bounds
//!   (`lbvh_fit.wgsl`). The build reads back the leaf count and the tree's depth.
//! - **Refit** (radius changes): boxes and bottom-up bounds again over the same topology. A
//!   cluster that was empty at the build and is not any more forces a rebuild (it has no leaf).
//! - **Query and render**: `shaders_glsl/wgpu/lbvh_query.comp` and `lbvh_render.comp` (and
//!   `lbvh_splat.comp`, Knoll et al.'s splatter, for [`Backend::render_splat`]), the
//!   shared GLSL (`shaders_glsl/shared/`: RBF, maps, noise, integrators and the LBVH traversal
//!   `lbvh.glsl`) through naga's GLSL front end; one pipeline per specialisation-constant
//!   variant, cached for the process. Frames accumulate as f32 sums in a storage buffer.
//!
//! Files: `context` (device, limits, shader modules and pipelines), `util` (buffers, split
//! arrays, staging, passes), `scene` (the uploaded step's buffers and bindings), `prepare`
//! (the step's preparation on the device), `tree` (the LBVH
//! build and refit passes), `sort` (the radix sort), `query` and `render` (the two traversal
//! kernels), and here the backend itself.
//!
//! The CPU twin of every build stage is in [`crate::backend::shaders::cpu`], a file per shader
//! (the LBVH's are the library's build, [`crate::accel::lbvh`]); `tests/wgpu_lbvh.rs` compares
//! them, and the backend with the CPU reference.

mod context;
mod owned;
pub mod prepare;
mod query;
mod render;
mod scene;
pub mod sort;
pub mod tree;
mod util;
mod voxel;

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;

pub use context::{
    AdapterSummary, GpuContext, adapters, adapters_to_choose_from, buffers_made, instance_flags,
};
pub use tree::{BuildStage, TreeReport, TreeSnapshot};

use super::gpu_data::{GpuStepData, SortedParticles};
use super::{Backend, BackendError, Capabilities, MemoryReport, StepInput, Timings};
use crate::accel::lbvh::{KeyGrid, LBVH_STACK_SIZE, structure_bytes};
use crate::backend::shaders::GpuFrame;
use crate::backend::shaders::brick::BrickLaunch;
use crate::field::FieldSettings;
use crate::values::FrameParams;
use crate::values::Image;
use crate::values::shader_constants::{TABLE_SIZE, spec};
use crate::values::{ColourMode, Integrator, NoiseKind};
use context::device_error;
use prepare::Prepare;
use scene::{Scene, SceneBuffers, capacity_for_step};
use tree::{GpuTree, SceneBindings};
use util::{PARTS, SplitBuffer, storage, uniform};

/// Bytes per particle the buffers bind (vec4 position + attribute); split over up to
/// [`PARTS`] bindings.
const PARTICLE_BYTES: u64 = 16;
/// Bytes per cluster of the largest per-cluster buffers (nodes, boxes); split over up to
/// [`PARTS`] bindings.
const CLUSTER_BYTES: u64 = 32;
/// Bytes per element of the arrays kept in one binding: per cluster the sort keys and values
/// (and their scratch), parents and heights; per particle the radius attribute. They reach the
/// limit only at 4x the count of the split arrays (at K = 1: twice that of the nodes' split).
const WORD_BYTES: u64 = 4;
/// Queries per dispatch (the points and results buffers are 16 MiB each).
const QUERY_CHUNK: usize = 1 << 20;

struct Accumulation {
    width: u32,
    height: u32,
    frames: u32,
    /// f32 RGBA sums per pixel, split like the particles (16 bytes per pixel).
    sums: SplitBuffer,
    clear: bool,
}

/// The wgpu LBVH backend.
pub struct WgpuBackend {
    ctx: Arc<GpuContext>,
    capabilities: Capabilities,
    reserved: usize,
    scene: Option<Scene>,
    prepare: Option<Prepare>,
    tree: Option<GpuTree>,
    built: Option<TreeReport>,
    accumulation: Option<Accumulation>,
    stbn: Option<wgpu::Buffer>,
    query_buffers: Option<(usize, wgpu::Buffer, wgpu::Buffer, wgpu::Buffer)>,
    dummy: wgpu::Buffer,
    optical: Vec<f32>,
    frame_uniform: wgpu::Buffer,
    tiling_uniform: wgpu::Buffer,
    /// The voxel baseline's grid of the last [`Backend::voxelize`], and the splat's buffers.
    voxels: Option<voxel::Voxels>,
    splat_buffers: voxel::SplatBuffers,
    /// The largest storage binding this backend uses: the device's, or lower (tests).
    max_binding: u64,
    timings: Timings,
}

impl WgpuBackend {
    /// A backend on the process-wide device; an error when wgpu finds no adapter.
    pub fn new() -> Result<WgpuBackend, BackendError> {
        Ok(WgpuBackend::with_context(GpuContext::shared()?))
    }

    /// A backend on the device of `ctx`, nothing uploaded.
    pub fn with_context(ctx: Arc<GpuContext>) -> WgpuBackend {
        let max_binding = ctx.max_binding();
        WgpuBackend::with_max_binding(ctx, max_binding)
    }

    /// A backend that binds at most `max_binding` bytes per storage buffer (at most the
    /// device's limit; at least 32): with a low limit, small steps exercise the split of
    /// particles, nodes and boxes over several bindings (tests).
    pub fn with_max_binding(ctx: Arc<GpuContext>, max_binding: u64) -> WgpuBackend {
        let max_binding = max_binding.min(ctx.max_binding()).max(CLUSTER_BYTES);
        WgpuBackend {
            capabilities: Capabilities {
                name: "wgpu",
                device: ctx.describe(),
                hardware_rt: false,
                software: ctx.info.device_type == wgpu::DeviceType::Cpu,
                // At K = 1 the nodes and boxes (32 B per cluster, split over PARTS bindings)
                // hold the fewest particles; a larger K holds more (see `check_fits`).
                max_particles: Some(
                    (util::part_limit(max_binding) / CLUSTER_BYTES * PARTS) as usize,
                ),
                scatters_grids: false,
                frame_timer: if ctx.timestamps.is_some() {
                    super::FrameTimer::DeviceTimestamps
                } else {
                    super::FrameTimer::SubmitToCompletion
                },
            },
            reserved: 0,
            scene: None,
            prepare: None,
            tree: None,
            built: None,
            accumulation: None,
            stbn: None,
            query_buffers: None,
            dummy: storage(&ctx, "unused radius attribute", 16),
            optical: vec![0.0; TABLE_SIZE],
            frame_uniform: uniform(&ctx, "frame", std::mem::size_of::<GpuFrame>() as u64),
            tiling_uniform: uniform(&ctx, "tiling", 32),
            voxels: None,
            splat_buffers: voxel::SplatBuffers::default(),
            max_binding,
            ctx,
            timings: Timings::default(),
        }
    }

    /// The device context it runs on.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The uploaded step as the GPU holds it.
    pub fn step_data(&self) -> Option<&GpuStepData> {
        self.scene.as_ref().map(|s| &s.data)
    }

    /// The Morton grid of the uploaded step.
    pub fn key_grid(&self) -> Option<KeyGrid> {
        self.scene.as_ref().map(|s| s.grid)
    }

    /// What the last build or refit reported (None before a build).
    pub fn tree_report(&self) -> Option<TreeReport> {
        self.built
    }

    /// Parts the uploaded step's particles and its nodes (and boxes) are split over (tests).
    pub fn split_parts(&self) -> Option<(usize, usize)> {
        let scene = self.scene.as_ref()?;
        let tree = self.tree.as_ref()?;
        Some((scene.particles.parts_used(), tree.nodes.parts_used()))
    }

    /// Frames accumulated since the last reset.
    pub fn frames(&self) -> u32 {
        self.accumulation.as_ref().map_or(0, |a| a.frames)
    }

    /// Bytes of build scratch (sort keys, values, histogram) beside the structure.
    pub fn scratch_bytes(&self) -> usize {
        self.tree.as_ref().map_or(0, GpuTree::scratch_bytes)
    }

    /// The uploaded step's particles as the device prepared them, in Hilbert order, with the
    /// order (tests).
    pub fn sorted_particles(&self) -> Result<SortedParticles, BackendError> {
        let (Some(scene), Some(prepare)) = (&self.scene, &self.prepare) else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let n = scene.data.count;
        let vec4s = |b: &SplitBuffer| -> Result<Vec<[f32; 4]>, BackendError> {
            Ok(bytemuck::pod_collect_to_vec(
                &b.read(&self.ctx, n as u64 * 16)?,
            ))
        };
        let targets = scene.targets();
        Ok(SortedParticles {
            points: vecs_or_empty(n, || vec4s(targets.particles))?,
            points_lo: targets
                .particles_lo
                .map(|b| vecs_or_empty(n, || vec4s(b)))
                .transpose()?,
            radius_attribute: targets
                .radius_attribute
                .filter(|_| scene.data.has_radius_attribute)
                .map(|b| util::read_f32s(&self.ctx, b, 0, n))
                .transpose()?,
            volume: targets
                .radius_attribute
                .filter(|_| scene.data.kernel.is_sph())
                .map(|b| util::read_f32s(&self.ctx, b, scene.data.volume_offset(), n))
                .transpose()?,
            order: prepare.order(&self.ctx, n)?,
        })
    }

    /// Fills the prepared particles (and their lo parts and radius attribute) and the
    /// preparation's buffers with 0xFF (tests: poison before an upload).
    pub fn poison_prepared(&self) -> Result<(), BackendError> {
        let (Some(scene), Some(prepare)) = (&self.scene, &self.prepare) else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        scene.particles.poison(&self.ctx);
        if let Some(b) = &scene.particles_lo {
            b.poison(&self.ctx);
        }
        if let Some(b) = &scene.radius_attribute {
            util::poison(&self.ctx, b);
        }
        prepare.poison(&self.ctx);
        Ok(())
    }

    /// Fills the accumulation with 0xFF (NaN) and restarts it (tests: the next splatter frame
    /// stores every pixel into the sums uncleared, so a pixel it misses shows as NaN).
    pub fn poison_accumulation(&mut self) -> Result<(), BackendError> {
        let acc = self
            .accumulation
            .as_mut()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        acc.sums.poison(&self.ctx);
        acc.frames = 0;
        acc.clear = true;
        Ok(())
    }

    /// Fills the tree's buffers with 0xFF (tests: poison before a build).
    pub fn poison_tree(&mut self) -> Result<(), BackendError> {
        let tree = self
            .tree
            .as_ref()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        tree.poison(&self.ctx);
        Ok(())
    }

    /// Reads the tree back (tests).
    pub fn snapshot(&self) -> Result<TreeSnapshot, BackendError> {
        let (Some(scene), Some(tree)) = (&self.scene, &self.tree) else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        tree.snapshot(&self.ctx, scene.clusters() as usize)
    }

    fn bindings<'a>(scene: &'a Scene, dummy: &'a wgpu::Buffer) -> SceneBindings<'a> {
        let variant = scene.variant(Integrator::Ea, ColourMode::Post, NoiseKind::Stbn);
        // Only what the bounds kernel reads varies its pipeline (boxes come from the hi parts
        // of positions, which their padding allows).
        let mut v = variant;
        for unread in [
            spec::INTEGRATOR,
            spec::COLOUR_MODE,
            spec::NOISE_KIND,
            spec::DENSITY_MAP_VARIES,
            spec::POSITION_DS,
            spec::RT_HIT_PER_PARTICLE,
            spec::COMPENSATED_SUM,
        ] {
            v[unread] = 0;
        }
        SceneBindings {
            field: &scene.field_uniform,
            particles: &scene.particles,
            maps: &scene.maps,
            radius_attribute: scene.radius_attribute.as_ref().unwrap_or(dummy),
            variant: Some(v),
        }
    }

    /// Builds up to `until` (tests compare each stage with its CPU twin); `Fit` is a full build.
    pub fn build_until(&mut self, until: BuildStage) -> Result<TreeReport, BackendError> {
        let (Some(scene), Some(tree)) = (&self.scene, &self.tree) else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let started = Instant::now();
        let report = tree.build(
            &self.ctx,
            &Self::bindings(scene, &self.dummy),
            &scene.grid,
            scene.clusters(),
            until,
        )?;
        self.built = None;
        if until == BuildStage::Fit {
            if report.leaves > scene.clusters() {
                return Err(device_error(format!(
                    "the build counted {} leaves for {} clusters",
                    report.leaves,
                    scene.clusters()
                )));
            }
            if report.depth > LBVH_STACK_SIZE {
                return Err(device_error(format!(
                    "the tree is {} deep, more than the traversal stack's {LBVH_STACK_SIZE} entries",
                    report.depth
                )));
            }
            self.built = Some(report);
            self.timings.build = report.device_time.unwrap_or_else(|| started.elapsed());
            tracing::debug!(
                "wgpu: built an LBVH over {} clusters ({} leaves, depth {}) in {:.1} ms",
                scene.clusters(),
                report.leaves,
                report.depth,
                self.timings.build.as_secs_f64() * 1e3
            );
        }
        Ok(report)
    }

    /// Applies field settings that keep the particles (`GpuStepData::apply_field`, the one
    /// check every backend makes) and uploads what they change.
    fn apply_field(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let Some(scene) = self.scene.as_mut() else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let changed =
            scene
                .data
                .apply_field(&scene.step, &scene.field, field, scene.series_range)?;
        scene.ensure_radius_attribute(&self.ctx)?;
        scene.ensure_points_lo(&self.ctx, self.max_binding)?;
        let targets = scene.targets();
        let radius = targets.radius_attribute.filter(|_| changed.factors);
        let lo = targets.particles_lo.filter(|_| changed.positions_lo);
        if radius.is_some() || lo.is_some() {
            let prepare = self
                .prepare
                .as_mut()
                .ok_or(BackendError::NothingUploaded("wgpu"))?;
            prepare.regather(&self.ctx, &scene.data, &scene.step, field, radius, lo)?;
        }
        scene.field = field.clone();
        let colour = scene.data.tables.colour.clone();
        scene.write_maps(&self.ctx, self.tree.as_ref(), &self.optical, &colour);
        Ok(())
    }

    fn built_scene(&self) -> Result<&Scene, BackendError> {
        match (&self.scene, self.built) {
            (Some(s), Some(_)) => Ok(s),
            _ => Err(BackendError::NothingUploaded("wgpu")),
        }
    }
}

impl Backend for WgpuBackend {
    fn capabilities(&self) -> &Capabilities {
        &self.capabilities
    }

    fn reserve(&mut self, max_particles: usize) {
        self.reserved = self.reserved.max(max_particles);
    }

    fn upload(&mut self, input: &StepInput<'_>) -> Result<(), BackendError> {
        let started = Instant::now();
        let staging = GpuStepData::check(input)?;
        let checked = started.elapsed();
        let n = staging.len();
        let clusters = input.cluster.clusters_for(n);
        let max_binding = self.max_binding;
        let capacity = capacity_for_step(
            input,
            &staging,
            self.reserved,
            max_binding,
            &self.ctx.info.name,
        )?;
        let ctx = self.ctx.clone();
        let mut old = self.scene.take();
        let SceneBuffers {
            particles,
            particles_lo,
            particle_capacity,
            maps,
            field_uniform,
            maps_written,
            radius_attribute,
        } = SceneBuffers::reuse_or_make(
            &ctx,
            &mut old,
            &input.step.name,
            n,
            capacity,
            max_binding,
        )?;
        if self
            .prepare
            .as_ref()
            .is_none_or(|p| p.capacity() < particle_capacity)
        {
            self.prepare = None;
            self.prepare = Some(
                Prepare::new(&ctx, particle_capacity, max_binding)
                    .map_err(|e| device_error(format!("step '{}': {e}", input.step.name)))?,
            );
        }
        let Some(prepare) = self.prepare.as_mut() else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let views = prepare.map(&ctx, n, staging.factor_words())?;
        let allocated = started.elapsed();
        let data = prepare.stage(&ctx, staging, views, input.step)?;
        let staged = started.elapsed();
        self.timings.prepare = checked + (staged - allocated);
        let mut scene = Scene {
            step: input.step.clone(),
            field: input.field.clone(),
            cluster: input.cluster,
            series_range: input.series_range,
            grid: KeyGrid::new(input.series_bounds, data.origin),
            data,
            particles,
            particles_lo,
            particle_capacity,
            radius_attribute,
            maps,
            field_uniform,
            maps_written,
        };
        scene.ensure_points_lo(&ctx, max_binding)?;
        scene.ensure_radius_attribute(&ctx)?;
        prepare.copy(&ctx, &scene.data)?;
        let copied = started.elapsed();
        prepare.run(&ctx, &scene.data, &scene.targets())?;
        let prepared = started.elapsed();
        self.timings.device_prepare = prepared - copied;
        tracing::debug!(
            "wgpu: step '{}' ({n} particles): CPU {:.1} ms (check {:.1}), staging mapped after {:.1} ms, copy {:.1} ms, device preparation {:.1} ms",
            input.step.name,
            self.timings.prepare.as_secs_f64() * 1e3,
            checked.as_secs_f64() * 1e3,
            (allocated - checked).as_secs_f64() * 1e3,
            (copied - staged).as_secs_f64() * 1e3,
            self.timings.device_prepare.as_secs_f64() * 1e3
        );
        let cluster_capacity = input.cluster.clusters_for(scene.particle_capacity);
        if self.tree.as_ref().is_none_or(|t| t.capacity < clusters) {
            self.tree = None;
            self.tree = Some(
                GpuTree::new(&ctx, cluster_capacity.max(clusters), max_binding)
                    .map_err(|e| device_error(format!("step '{}': {e}", input.step.name)))?,
            );
        }
        scene.write_maps(
            &ctx,
            self.tree.as_ref(),
            &self.optical,
            &scene.data.tables.colour,
        );
        self.scene = Some(scene);
        self.built = None;
        self.timings.upload =
            started.elapsed() - self.timings.prepare - self.timings.device_prepare;
        Ok(())
    }

    fn build(&mut self) -> Result<(), BackendError> {
        self.build_until(BuildStage::Fit).map(|_| ())
    }

    fn refit(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let started = Instant::now();
        if self.built.is_none() {
            return Err(BackendError::NothingUploaded("wgpu"));
        }
        let ctx = self.ctx.clone();
        self.apply_field(field)?;
        let (Some(scene), Some(tree)) = (&self.scene, &self.tree) else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let report = tree.refit(
            &ctx,
            &Self::bindings(scene, &self.dummy),
            &scene.grid,
            scene.clusters(),
        )?;
        if report.needs_rebuild {
            tracing::debug!("wgpu: a refit left a non-empty cluster outside the tree; rebuilding");
            self.build_until(BuildStage::Fit)?;
        } else if let Some(b) = &mut self.built {
            b.needs_rebuild = false;
        }
        // On the device's clock where it has one: the refit, and the rebuild it led to.
        self.timings.refit = match report.device_time {
            Some(t) if report.needs_rebuild => t + self.timings.build,
            Some(t) => t,
            None => started.elapsed(),
        };
        Ok(())
    }

    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        self.apply_field(field)
    }

    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        self.run_query(points)
    }

    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        self.run_render(frame)
    }

    /// `lbvh_owned.comp` over the share's rectangle (the shared integrators' brick variant).
    fn render_owned(
        &mut self,
        frame: &FrameParams,
        share: &crate::backend::BrickShare<'_>,
    ) -> Result<Vec<[f64; 4]>, BackendError> {
        let origin = self.built_scene()?.data.origin;
        let launch = BrickLaunch::render("wgpu", frame, share, origin)?;
        let own_frame = share.own_frame(frame);
        let bytes = self.run_owned(own_frame.as_ref().unwrap_or(frame), &launch)?;
        Ok(BrickLaunch::pixels(&bytes))
    }

    /// `lbvh_owned.comp` along the rays' rectangle.
    fn owned_depth(
        &mut self,
        frame: &FrameParams,
        owned: &crate::values::HalfOpenBox,
        rays: crate::backend::DepthRays<'_>,
    ) -> Result<Vec<f64>, BackendError> {
        let origin = self.built_scene()?.data.origin;
        let launch = BrickLaunch::depth(frame, owned, rays, origin);
        let bytes = self.run_owned(frame, &launch)?;
        Ok(BrickLaunch::depths(&bytes))
    }

    /// The splatter's slabs collect their hits by a software traversal of the LBVH
    /// (`lbvh_splat.comp`); the kernel does not count lost hits.
    fn render_splat(
        &mut self,
        frame: &FrameParams,
        k: usize,
    ) -> Result<Option<crate::field::splat::SplatCounts>, BackendError> {
        self.run_splat(frame, k)?;
        Ok(None)
    }

    /// Splats with atomics into a 3D texture, slab by slab (`voxel_particles.comp`,
    /// `voxel_splat.wgsl`); needs no build.
    fn voxelize(&mut self, frame: &FrameParams, n: usize) -> Result<(), BackendError> {
        self.run_voxelize(frame, n)
    }

    /// `voxel_render.comp`: the shared integrators over the grid's texture.
    fn render_voxels(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        self.run_voxel_frame(frame)
    }

    fn voxel_grid(&mut self) -> Result<crate::backend::voxel::VoxelGrid, BackendError> {
        self.read_voxels()
    }

    fn reset(&mut self) {
        if let Some(a) = &mut self.accumulation {
            a.frames = 0;
            a.clear = true;
        }
    }

    fn image(&mut self) -> Result<Image, BackendError> {
        let acc = self
            .accumulation
            .as_ref()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        let pixels = acc.width as usize * acc.height as usize;
        let bytes = if acc.clear || acc.frames == 0 {
            vec![0u8; pixels * 16]
        } else {
            acc.sums.read(&self.ctx, pixels as u64 * 16)?
        };
        let sums: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
        let n = acc.frames.max(1) as f32;
        Ok(Image {
            width: acc.width,
            height: acc.height,
            pixels: sums.iter().map(|s| s.map(|v| v / n)).collect(),
        })
    }

    fn timings(&self) -> Timings {
        self.timings
    }

    fn representation(&self) -> Option<super::Representation> {
        self.scene.as_ref().map(|s| s.data.representation())
    }

    fn memory(&self) -> MemoryReport {
        MemoryReport {
            particle_bytes: self.scene.as_ref().map_or(0, |s| s.data.particle_bytes()),
            structure_bytes: self
                .scene
                .as_ref()
                .filter(|_| self.built.is_some())
                .map_or(0, |s| structure_bytes(s.clusters() as usize)),
            image_bytes: self
                .accumulation
                .as_ref()
                .map_or(0, |a| a.sums.size() as usize),
            preparation_bytes: self.prepare.as_ref().map_or(0, Prepare::bytes),
            voxel_bytes: self.voxel_bytes(),
        }
    }
}

/// `read()` of `n` elements, or nothing without elements (a zero-length read is no read).
fn vecs_or_empty<T>(
    n: usize,
    read: impl FnOnce() -> Result<Vec<T>, BackendError>,
) -> Result<Vec<T>, BackendError> {
    if n == 0 { Ok(Vec::new()) } else { read() }
}
