//! The portable GPU backend: wgpu compute over a GPU-built LBVH (Karras 2012). The paper's
//! software baseline, and the fallback on every GPU without ray-tracing hardware.
//!
//! - **Upload**: a step prepared by [`GpuStepData`] (Hilbert-sorted particles in local
//!   coordinates, maps baked to tables) goes into buffers kept for the largest step seen (or
//!   [`Backend::reserve`]d for the series' maximum count); the radius-attribute buffer exists
//!   only when the scene has one. The arrays of 16-byte elements that outgrow one storage
//!   binding first (particles, LBVH nodes, cluster boxes, the accumulation) live in up to
//!   `util::PARTS` = 4 buffers each (`util::SplitBuffer`, `shaders_glsl/wgpu/split.glsl`);
//!   a step beyond that, or one whose 4-byte arrays (sort keys, parents, radius attribute)
//!   outgrow one binding, is refused with an error naming the step, the need and the limit.
//!   Every kernel exists in two layouts (`context::Layout`): the one-part layout, which a step
//!   that fits runs, binds at most 8 storage buffers per stage (WebGPU's default, checked in
//!   `build.rs`), so the backend runs on small GPUs; only a split step needs more.
//! - **Build**, every stage a compute pass: cluster boxes (`shaders_glsl/wgpu/lbvh_bounds.comp`),
//!   Morton keys (`shaders_wgsl/lbvh_keys.wgsl`), a portable LSD radix sort
//!   (`radix_sort.wgsl`), Karras' hierarchy (`lbvh_hierarchy.wgsl`) and bottom-up bounds
//!   (`lbvh_fit.wgsl`). The build reads back the leaf count and the tree's depth.
//! - **Refit** (radius changes): boxes and bottom-up bounds again over the same topology. A
//!   cluster that was empty at the build and is not any more forces a rebuild (it has no leaf).
//! - **Query and render**: `shaders_glsl/wgpu/lbvh_query.comp` and `lbvh_render.comp`, the
//!   shared GLSL (`shaders_glsl/shared/`: RBF, maps, noise, integrators and the LBVH traversal
//!   `lbvh.glsl`) through naga's GLSL front end; one pipeline per specialisation-constant
//!   variant, cached for the process. Frames accumulate as f32 sums in a storage buffer.
//!
//! The CPU twin of every build stage is in [`crate::backend::shaders::cpu`], a file per shader; `tests/wgpu_lbvh.rs` compares
//! them, and the backend with the CPU reference.

mod context;
pub mod sort;
pub mod tree;
mod util;

use std::sync::Arc;
use std::time::Instant;

use glam::DVec3;

pub use context::{AdapterSummary, GpuContext, Kernel, adapters};
pub use tree::{BuildStage, TreeReport, TreeSnapshot};

use super::gpu_data::GpuStepData;
use super::{Backend, BackendError, Capabilities, MemoryReport, StepInput, Timings};
use crate::accel::ClusterSize;
use crate::backend::shaders::cpu::{
    lbvh::{LBVH_STACK_SIZE, structure_bytes},
    lbvh_keys::KeyGrid,
};
use crate::backend::shaders::{GpuFrame, SpecConstants, pack_map_tables};
use crate::field::{Classification, FieldSettings};
use crate::noise::BlueNoiseMask;
use crate::values::FrameParams;
use crate::values::Image;
use crate::values::Step;
use crate::values::shader_constants::{
    SPEC_CONSTANTS, STBN_DEPTH, STBN_HEIGHT, STBN_WIDTH, TABLE_FLOATS, TABLE_SIZE, spec,
};
use crate::values::{ColourMode, Integrator, NoiseKind};
use context::{Layout, device_error};
use tree::{GpuTree, SceneBindings};
use util::{PARTS, SplitBuffer, bind, dispatch, grid, parts_needed, storage, uniform, write};

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

/// The uploaded step and its buffers.
struct Scene {
    step: Step,
    field: FieldSettings,
    cluster: ClusterSize,
    series_range: Option<(f64, f64)>,
    data: GpuStepData,
    grid: KeyGrid,
    particles: SplitBuffer,
    /// The lo parts of double-single positions, split like the particles (when the step has
    /// them; kernels without them bind `particles` in their place, unread).
    particles_lo: Option<SplitBuffer>,
    particle_capacity: usize,
    radius_attribute: Option<wgpu::Buffer>,
    maps: wgpu::Buffer,
    field_uniform: wgpu::Buffer,
}

impl Scene {
    fn clusters(&self) -> u32 {
        self.data.field.counts[1]
    }

    fn colour_mode(&self) -> ColourMode {
        match (&self.field.attribute, self.field.classification) {
            (None, _) => ColourMode::Density,
            (Some(_), Classification::Post) => ColourMode::Post,
            (Some(_), Classification::Pre) => ColourMode::Pre,
        }
    }

    /// The GLSL kernels' specialisation constants.
    fn variant(
        &self,
        integrator: Integrator,
        colour: ColourMode,
        noise: NoiseKind,
    ) -> [u32; SPEC_CONSTANTS.len()] {
        SpecConstants {
            integrator: SpecConstants::integrator_id(integrator),
            colour_mode: SpecConstants::colour_id(colour),
            noise_kind: SpecConstants::noise_id(noise),
            cluster_size: self.cluster.get() as u32,
            radius_map_varies: u32::from(self.data.radius_map_varies),
            density_map_varies: u32::from(self.data.density_map_varies),
            has_radius_attribute: u32::from(self.data.radius_attribute.is_some()),
            position_ds: u32::from(self.data.double_single()),
            rt_hit_per_particle: 0,
        }
        .values()
    }

    /// The bind-group entries every kernel that traverses the tree shares: the field uniform
    /// (1), the maps (3), the radius attribute (4, `dummy` without one), the particles (10..),
    /// the tree's nodes (14..) and boxes (18..), and the particles' lo parts (26..: the
    /// particles themselves in their place, unread, without double-single positions).
    fn traversal_entries<'a>(
        &'a self,
        tree: &'a GpuTree,
        dummy: &'a wgpu::Buffer,
        layout: Layout,
    ) -> Vec<(u32, wgpu::BindingResource<'a>)> {
        let mut entries = vec![
            (1, self.field_uniform.as_entire_binding()),
            (3, self.maps.as_entire_binding()),
            (
                4,
                self.radius_attribute
                    .as_ref()
                    .unwrap_or(dummy)
                    .as_entire_binding(),
            ),
        ];
        entries.extend(self.particles.entries(10, layout));
        entries.extend(tree.nodes.entries(14, layout));
        entries.extend(tree.boxes.entries(18, layout));
        entries.extend(
            self.particles_lo
                .as_ref()
                .unwrap_or(&self.particles)
                .entries(26, layout),
        );
        entries
    }

    /// Uploads the lo parts of double-single positions, making their buffer (split like the
    /// particles) the first time a step needs them.
    fn write_points_lo(&mut self, ctx: &GpuContext, max_binding: u64) -> Result<(), BackendError> {
        let Some(lo) = &self.data.points_lo else {
            return Ok(());
        };
        if self
            .particles_lo
            .as_ref()
            .is_none_or(|b| b.size() < self.particles.size())
        {
            let capacity = self.particle_capacity as u64;
            self.particles_lo = Some(
                ctx.scoped("particle lo parts", || {
                    SplitBuffer::new(
                        ctx,
                        "particle lo parts",
                        capacity,
                        PARTICLE_BYTES,
                        max_binding,
                    )
                })?
                .ok_or_else(|| device_error("the particles' lo parts do not fit their parts"))?,
            );
        }
        if let Some(b) = &self.particles_lo {
            b.write(ctx, bytemuck::cast_slice(lo));
        }
        Ok(())
    }
}

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
    tree: Option<GpuTree>,
    built: Option<TreeReport>,
    accumulation: Option<Accumulation>,
    stbn: Option<wgpu::Buffer>,
    query_buffers: Option<(usize, wgpu::Buffer, wgpu::Buffer, wgpu::Buffer)>,
    dummy: wgpu::Buffer,
    optical: Vec<f32>,
    frame_uniform: wgpu::Buffer,
    tiling_uniform: wgpu::Buffer,
    /// The largest storage binding this backend uses: the device's, or lower (tests).
    max_binding: u64,
    timings: Timings,
}

impl WgpuBackend {
    /// A backend on the process-wide device; an error when wgpu finds no adapter.
    pub fn new() -> Result<WgpuBackend, BackendError> {
        Ok(WgpuBackend::with_context(GpuContext::shared()?))
    }

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
            },
            reserved: 0,
            scene: None,
            tree: None,
            built: None,
            accumulation: None,
            stbn: None,
            query_buffers: None,
            dummy: storage(&ctx, "unused radius attribute", 16),
            optical: vec![0.0; TABLE_SIZE],
            frame_uniform: uniform(&ctx, "frame", std::mem::size_of::<GpuFrame>() as u64),
            tiling_uniform: uniform(&ctx, "tiling", 32),
            max_binding,
            ctx,
            timings: Timings::default(),
        }
    }

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
            self.timings.build = started.elapsed();
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

    /// Writes the map tables (with the last frame's optical-density table) and field constants
    /// (with the part lengths of the split arrays, `shaders_glsl/wgpu/split.glsl`).
    fn write_maps(
        ctx: &GpuContext,
        scene: &Scene,
        tree: Option<&GpuTree>,
        optical: &[f32],
        colour: &[[f32; 3]],
    ) {
        let tables = pack_map_tables(
            &scene.data.tables.density,
            &scene.data.tables.radius,
            optical,
            colour,
        );
        write(ctx, &scene.maps, bytemuck::cast_slice(&tables));
        let mut field = scene.data.field;
        field.counts[2] = scene.particles.part_len(PARTICLE_BYTES);
        field.counts[3] = tree.map_or(u32::MAX, |t| t.boxes.part_len(16));
        write(ctx, &scene.field_uniform, bytemuck::bytes_of(&field));
    }

    fn write_radius_attribute(ctx: &GpuContext, scene: &mut Scene) -> Result<(), BackendError> {
        match &scene.data.radius_attribute {
            Some(h) => {
                let needed = (scene.particle_capacity.max(h.len()) * 4) as u64;
                if scene
                    .radius_attribute
                    .as_ref()
                    .is_none_or(|b| b.size() < needed)
                {
                    scene.radius_attribute = Some(ctx.scoped("radius attribute buffer", || {
                        storage(ctx, "radius attribute", needed)
                    })?);
                }
                if let Some(b) = &scene.radius_attribute {
                    write(ctx, b, bytemuck::cast_slice(h));
                }
            }
            None => scene.radius_attribute = None,
        }
        Ok(())
    }

    fn built_scene(&self) -> Result<&Scene, BackendError> {
        match (&self.scene, self.built) {
            (Some(s), Some(_)) => Ok(s),
            _ => Err(BackendError::NothingUploaded("wgpu")),
        }
    }
}

/// Whether a step of `n` particles in `clusters` clusters fits bindings of `max_binding`
/// bytes: the particles, nodes and boxes in at most [`PARTS`] parts each, the 4-byte arrays in
/// one. Err names what does not fit and what it needs.
fn check_fits(
    n: usize,
    clusters: usize,
    has_radius_attribute: bool,
    max_binding: u64,
) -> Result<(), String> {
    let (n, c) = (n as u64, clusters as u64);
    let split = [
        ("the particles", n, PARTICLE_BYTES),
        ("the LBVH nodes", c, CLUSTER_BYTES),
        ("the cluster boxes", c, CLUSTER_BYTES),
    ];
    for (what, count, bytes) in split {
        if parts_needed(count, bytes, max_binding) > PARTS {
            return Err(format!(
                "{what} need {} bytes, more than {PARTS} x {max_binding}",
                count * bytes
            ));
        }
    }
    let mut single = vec![("the per-cluster sort keys", c)];
    if has_radius_attribute {
        single.push(("the radius attribute", n));
    }
    for (what, count) in single {
        if count * WORD_BYTES > max_binding {
            return Err(format!(
                "{what} need {} bytes in one binding, more than {max_binding}",
                count * WORD_BYTES
            ));
        }
    }
    Ok(())
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
        let data = GpuStepData::prepare(input)?;
        let n = data.points.len();
        let clusters = data.field.counts[1] as usize;
        let has_radius = data.radius_attribute.is_some();
        let max_binding = self.max_binding;
        if let Err(what) = check_fits(n, clusters, has_radius, max_binding) {
            return Err(device_error(format!(
                "step '{}' ({n} particles in {clusters} clusters of {}): {what}; {} binds at \
                 most {max_binding} bytes per storage buffer, and this backend splits the \
                 particles, nodes and boxes over at most {PARTS} (a larger cluster size needs \
                 fewer clusters)",
                input.step.name, input.cluster, self.ctx.info.name,
            )));
        }
        let ctx = self.ctx.clone();
        // Keep buffers for the largest step seen (or reserved, when that fits): a series
        // allocates once.
        let reserved = self.reserved.max(n);
        let capacity = if check_fits(
            reserved,
            input.cluster.clusters_for(reserved),
            has_radius,
            max_binding,
        )
        .is_ok()
        {
            reserved
        } else {
            n
        };
        let old = self.scene.take();
        let (particles, particles_lo, particle_capacity, maps, field_uniform, radius_attribute) =
            match old {
                Some(s) if s.particle_capacity >= n => (
                    s.particles,
                    s.particles_lo,
                    s.particle_capacity,
                    s.maps,
                    s.field_uniform,
                    s.radius_attribute,
                ),
                _ => {
                    let need = capacity as u64 * PARTICLE_BYTES;
                    ctx.scoped(
                        &format!(
                            "step '{}': particle buffers ({need} bytes for {capacity} particles)",
                            input.step.name
                        ),
                        || {
                            (
                                SplitBuffer::new(
                                    &ctx,
                                    "particles",
                                    capacity as u64,
                                    PARTICLE_BYTES,
                                    max_binding,
                                ),
                                capacity,
                                storage(&ctx, "map tables", TABLE_FLOATS as u64 * 4),
                                uniform(&ctx, "field", 32),
                                None,
                            )
                        },
                    )
                    .and_then(|(p, c, m, f, r)| {
                        let p = p.ok_or_else(|| {
                            device_error(format!("{capacity} particles do not fit {PARTS} parts"))
                        })?;
                        Ok((p, None, c, m, f, r))
                    })?
                }
            };
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
        };
        scene
            .particles
            .write(&ctx, bytemuck::cast_slice(&scene.data.points));
        scene.write_points_lo(&ctx, max_binding)?;
        Self::write_radius_attribute(&ctx, &mut scene)?;
        let cluster_capacity = input.cluster.clusters_for(scene.particle_capacity);
        if self.tree.as_ref().is_none_or(|t| t.capacity < clusters) {
            self.tree = None;
            self.tree = Some(
                GpuTree::new(&ctx, cluster_capacity.max(clusters), max_binding)
                    .map_err(|e| device_error(format!("step '{}': {e}", input.step.name)))?,
            );
        }
        Self::write_maps(
            &ctx,
            &scene,
            self.tree.as_ref(),
            &self.optical,
            &scene.data.tables.colour,
        );
        self.scene = Some(scene);
        self.built = None;
        self.timings.upload = started.elapsed();
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
        let Some(scene) = self.scene.as_mut() else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let changed =
            scene
                .data
                .apply_field(&scene.step, &scene.field, field, scene.series_range)?;
        if changed.radius_attribute {
            Self::write_radius_attribute(&ctx, scene)?;
        }
        if changed.positions_lo {
            scene.write_points_lo(&ctx, self.max_binding)?;
        }
        scene.field = field.clone();
        let colour = scene.data.tables.colour.clone();
        Self::write_maps(&ctx, scene, self.tree.as_ref(), &self.optical, &colour);
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
        self.timings.refit = started.elapsed();
        Ok(())
    }

    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let Some(scene) = self.scene.as_mut() else {
            return Err(BackendError::NothingUploaded("wgpu"));
        };
        let changed =
            scene
                .data
                .apply_field(&scene.step, &scene.field, field, scene.series_range)?;
        if changed.radius_attribute {
            Self::write_radius_attribute(&self.ctx, scene)?;
        }
        if changed.positions_lo {
            scene.write_points_lo(&self.ctx, self.max_binding)?;
        }
        scene.field = field.clone();
        let colour = scene.data.tables.colour.clone();
        Self::write_maps(&self.ctx, scene, self.tree.as_ref(), &self.optical, &colour);
        Ok(())
    }

    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        if points.is_empty() {
            return Ok(Vec::new());
        }
        // A query point is one vec4, or with double-single positions two (hi, lo).
        let per_point = if self
            .scene
            .as_ref()
            .expect("checked above")
            .data
            .double_single()
        {
            2
        } else {
            1
        };
        let chunk = QUERY_CHUNK
            .min((self.max_binding / (16 * per_point as u64)) as usize)
            .min(points.len());
        if self
            .query_buffers
            .as_ref()
            .is_none_or(|q| q.0 < chunk || q.2.size() < (chunk * per_point) as u64 * 16)
        {
            self.query_buffers = Some(ctx.scoped("query buffers", || {
                (
                    chunk,
                    uniform(&ctx, "query count", 16),
                    storage(&ctx, "query points", (chunk * per_point) as u64 * 16),
                    storage(&ctx, "query results", chunk as u64 * 16),
                )
            })?);
        }
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self
            .tree
            .as_ref()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        let (_, count_buffer, points_buffer, results_buffer) =
            self.query_buffers.as_ref().expect("made above");
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes]);
        let pipeline = ctx.pipeline(
            Kernel::Query,
            Some(scene.variant(Integrator::Ea, scene.colour_mode(), NoiseKind::Stbn)),
            layout,
        )?;
        let bg = ctx.scoped("query bind group", || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, count_buffer.as_entire_binding()),
                (7, points_buffer.as_entire_binding()),
                (8, results_buffer.as_entire_binding()),
            ]);
            bind(&ctx, &pipeline, &entries)
        })?;
        let mut out = Vec::with_capacity(points.len());
        let mut bytes = Vec::new();
        let mut local: Vec<[f32; 4]> = Vec::with_capacity(chunk * per_point);
        for part in points.chunks(chunk) {
            local.clear();
            for &x in part {
                scene.data.push_query(x, &mut local);
            }
            write(&ctx, points_buffer, bytemuck::cast_slice(&local));
            let groups = (part.len() as u32).div_ceil(64);
            let (blocks, per_block, dispatched) = util::interleave(groups);
            write(
                &ctx,
                count_buffer,
                bytemuck::cast_slice(&[part.len() as u32, groups, blocks, per_block]),
            );
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            ctx.scoped("query", || {
                dispatch(
                    &mut encoder,
                    "lbvh query",
                    &pipeline,
                    &bg,
                    grid(u64::from(dispatched), 1),
                );
            })?;
            bytes.clear();
            util::read_into(
                &ctx,
                Some(encoder),
                results_buffer,
                0,
                part.len() as u64 * 16,
                &mut bytes,
            )?;
            let values: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
            out.extend(values.iter().map(|v| {
                (
                    f64::from(v[0]),
                    [f64::from(v[1]), f64::from(v[2]), f64::from(v[3])],
                )
            }));
        }
        self.timings.query = started.elapsed();
        Ok(out)
    }

    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        let (w, h) = (frame.width, frame.height);
        let bytes = u64::from(w) * u64::from(h) * 16;
        let pixels = u64::from(w) * u64::from(h);
        if parts_needed(pixels, 16, self.max_binding) > PARTS {
            return Err(device_error(format!(
                "a {w}x{h} image needs {bytes} bytes of accumulation, more than {PARTS} x {}; \
                 {} binds at most {} bytes per storage buffer",
                self.max_binding, ctx.info.name, self.max_binding
            )));
        }
        if self
            .accumulation
            .as_ref()
            .is_none_or(|a| a.width != w || a.height != h)
        {
            self.accumulation = None;
            let max_binding = self.max_binding;
            let sums = ctx
                .scoped(&format!("accumulation buffer ({bytes} bytes)"), || {
                    SplitBuffer::new(&ctx, "accumulation", pixels, 16, max_binding)
                })?
                .ok_or_else(|| device_error("the accumulation does not fit its parts"))?;
            self.accumulation = Some(Accumulation {
                width: w,
                height: h,
                frames: 0,
                sums,
                clear: true,
            });
        }
        if self.stbn.is_none() {
            let mask = BlueNoiseMask::builtin();
            if (mask.width, mask.height, mask.depth) != (STBN_WIDTH, STBN_HEIGHT, STBN_DEPTH) {
                return Err(device_error(format!(
                    "the shaders expect a 128x128x64 blue-noise mask, not {}x{}x{}",
                    mask.width, mask.height, mask.depth
                )));
            }
            let words = mask.packed_words();
            let buffer = ctx.scoped("blue-noise mask", || {
                storage(&ctx, "stbn mask", words.len() as u64 * 4)
            })?;
            write(&ctx, &buffer, bytemuck::cast_slice(&words));
            self.stbn = Some(buffer);
        }
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self.tree.as_ref().expect("built");
        self.optical = frame.optical_table.to_vec();
        Self::write_maps(&ctx, scene, Some(tree), &self.optical, &frame.colour_table);
        write(
            &ctx,
            &self.frame_uniform,
            bytemuck::bytes_of(&GpuFrame::new(frame, scene.data.origin)),
        );
        let sums = &self.accumulation.as_ref().expect("made above").sums;
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes, sums]);
        let pipeline = ctx.pipeline(
            Kernel::Render,
            Some(scene.variant(frame.integrator, frame.colour, frame.noise)),
            layout,
        )?;
        let tiles_x = w.div_ceil(8);
        let tiles = tiles_x * h.div_ceil(8);
        let (blocks, per_block, dispatched) = util::interleave(tiles);
        let acc_part = self
            .accumulation
            .as_ref()
            .map_or(u32::MAX, |a| a.sums.part_len(16));
        write(
            &ctx,
            &self.tiling_uniform,
            bytemuck::cast_slice(&[tiles_x, tiles, blocks, per_block, acc_part, 0, 0, 0]),
        );
        let acc = self.accumulation.as_mut().expect("made above");
        let stbn = self.stbn.as_ref().expect("made above");
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("render", || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, self.frame_uniform.as_entire_binding()),
                (7, stbn.as_entire_binding()),
                (9, self.tiling_uniform.as_entire_binding()),
            ]);
            entries.extend(acc.sums.entries(22, layout));
            let bg = bind(&ctx, &pipeline, &entries);
            if acc.clear {
                acc.sums.clear(&mut encoder);
                acc.frames = 0;
                acc.clear = false;
            }
            dispatch(
                &mut encoder,
                "lbvh render",
                &pipeline,
                &bg,
                grid(u64::from(dispatched), 1),
            );
        })?;
        util::submit_and_wait(&ctx, "render", encoder)?;
        acc.frames += 1;
        self.timings.frame = started.elapsed();
        Ok(())
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

    fn positions(&self) -> Option<super::Positions> {
        self.scene.as_ref().map(|s| s.data.positions())
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
        }
    }
}
