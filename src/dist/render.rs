//! One distributed render: decompose, exchange, build each brick, then per frame render the
//! brick's samples, composite by direct send and accumulate; the image gathered at rank 0.

use std::sync::Arc;

use super::DistError;
use super::balance::{CostModel, pilot_side};
use super::clock::StageClock;
use super::comm::{Comm, CommExt};
use super::composite::{TileGrid, TileSums, assemble, direct_send, screen_rect};
use super::exchange::{decompose, exchange};
use super::kd::KdTree;
use super::occlusion;
use super::scan::exclusive_scan;
use crate::accel::ClusterSize;
use crate::backend::precision::PositionKind;
use crate::backend::{Backend, BrickShare, DepthRays, LightMap, LightPrefix, Precision, StepInput};
use crate::field::{FieldSettings, PeriodicBox, particle_reaches};
use crate::render::CycleWeights;
use crate::values::{Bounds, FrameParams, HalfOpenBox, Image, Integrator, PixelRect, Step};

/// What every rank renders with: the same on all of them (series-wide values, never one
/// rank's), so that every brick's field is the single-rank field over its leaf.
#[derive(Clone, Copy, Debug)]
pub struct DistScene<'a> {
    /// The field every brick renders: attribute, radius, maps, kernel.
    pub field: &'a FieldSettings,
    /// The cluster size every brick's BVH is built with.
    pub cluster: ClusterSize,
    /// The series' bounds: the Hilbert grid and local origin of every brick (with a periodic
    /// box, the box grown by the largest reach of any rank's particles instead, as a single
    /// rank grows it by its step's).
    pub series_bounds: Bounds,
    /// The attribute's range over the series (never a brick's).
    pub series_range: Option<(f64, f64)>,
    /// Asked of every brick; where bricks would choose differently (`auto`), all take f64.
    pub precision: Precision,
    /// The box whose faces wrap, if any. Each rank wraps its own particles into it and makes
    /// their periodic images ([`PeriodicBox::images`], the single rank's rule, which looks at
    /// one particle at a time); the images then go through the exchange as particles, owned by
    /// the leaf that holds them and ghosts of the leaves they reach, so a brick at a face sums
    /// the particles across it.
    pub periodic: Option<PeriodicBox>,
    /// How single scattering's shadow rays cross bricks.
    pub shadows: DistShadows,
}

impl<'a> DistScene<'a> {
    /// What a backend is given to hold `step` under this scene in `precision`: a rank's
    /// brick, or the whole step on one rank (the single-rank render a distributed one equals).
    pub fn step_input<'s>(&self, step: &'s Arc<Step>, precision: Precision) -> StepInput<'s>
    where
        'a: 's,
    {
        StepInput {
            step,
            field: self.field,
            cluster: self.cluster,
            series_bounds: self.series_bounds,
            series_range: self.series_range,
            precision,
        }
    }
}

/// How a shadow ray that leaves its brick is continued (`--dist-shadows`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DistShadows {
    /// Through the other bricks: each brick marches the rays of an orthographic light map of
    /// this many texels a side through its own box, and an exclusive scan in the order from
    /// the light gives each brick the depth nearer the light, looked up bilinearly at the
    /// brick's exit ([`LightPrefix`]). Exact along the light, interpolated across it.
    PrefixMap(u32),
    /// Only through the ray's own brick (as OSPRay's distributed renderer shadows): light
    /// passes every other brick unattenuated. The baseline the prefix map is measured against.
    Local,
}

impl Default for DistShadows {
    fn default() -> Self {
        DistShadows::PrefixMap(DEFAULT_SHADOW_MAP)
    }
}

/// The light map's texels a side where a benchmark does not say (the 1024).
pub const DEFAULT_SHADOW_MAP: u32 = 1024;

/// The light map's side for an image of `width` x `height` where the user does not say
/// (`--shadow-map`): half the image's longer side, 64 to 512 texels. On the 1M dam break at
/// 1024² the distributed image's FLIP against the single rank's levels off at M = 512
/// (0.0003–0.0009 for 512 … 2048 at P = 2 … 8, docs/distributed.md), while the map's M² rays,
/// marched through the whole volume, cost more than the image's own beyond it.
pub fn shadow_map_for(width: u32, height: u32) -> u32 {
    (width.max(height) / 2).clamp(64, 512)
}

/// What one rank did, for the log and the benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct RankReport {
    /// Particles this rank read (its share of the step).
    pub read: u64,
    /// Particles its leaf owns, and ghosts it received.
    pub owned: u64,
    /// Ghost particles it received from the leaves around its own.
    pub ghosts: u64,
    /// Bytes sent to other ranks: particles, then tiles (over all frames).
    pub particle_bytes: u64,
    /// Bytes of tiles sent to other ranks in compositing, and of the depth in front of each
    /// brick (stochastic marching), all frames.
    pub tile_bytes: u64,
    /// Bytes of light map depths sent to other ranks (shadows across bricks).
    pub shadow_map_bytes: u64,
    /// Whether its brick was built in f64 (1) or f32 (0).
    pub f64_positions: u64,
    /// Seconds: sampling, decomposition and exchange; upload and build; rendering its brick
    /// (all frames); compositing (all frames). A collective's time includes waiting in it
    /// for the slowest rank.
    pub exchange_seconds: f64,
    /// Seconds uploading the brick and building its acceleration structure.
    pub build_seconds: f64,
    /// Seconds rendering its brick's samples (all frames).
    pub render_seconds: f64,
    /// Seconds compositing (all frames), with the scan of the depth in front of each brick.
    pub composite_seconds: f64,
    /// Seconds marching the light map through the brick and scanning it (shadows across
    /// bricks; once per light).
    pub shadow_map_seconds: f64,
    /// CPU seconds of the rank's own thread in the same four stages: its work alone where it
    /// runs on one thread (waiting in a collective is not charged), as `aarbf bench
    /// distributed` runs each rank; with more threads, only the calling thread's share.
    pub exchange_cpu_seconds: f64,
    /// CPU seconds building (see [`RankReport::exchange_cpu_seconds`]).
    pub build_cpu_seconds: f64,
    /// CPU seconds rendering (see [`RankReport::exchange_cpu_seconds`]).
    pub render_cpu_seconds: f64,
    /// CPU seconds compositing (see [`RankReport::exchange_cpu_seconds`]).
    pub composite_cpu_seconds: f64,
    /// CPU seconds of the light map (see [`RankReport::exchange_cpu_seconds`]).
    pub shadow_map_cpu_seconds: f64,
    /// Bytes the rank holds for its brick: the brick's particles (position and attributes in
    /// f64), the backend's arrays and structures, and its largest layer.
    pub memory_bytes: u64,
}

/// The image at the root: the mean of the frames per pixel, in f64.
#[derive(Clone, Debug)]
pub struct DistImage {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Frames accumulated into `mean`.
    pub frames: u32,
    /// Row-major linear RGBA (the background composited), as a single-rank backend's mean.
    pub mean: Vec<[f64; 4]>,
    /// Past a blue-noise mask cycle, the image with the cycles weighted by their measured
    /// noise, as a single rank's session makes it (`None` where the mean is the image).
    pub weighted: Option<Image>,
    /// Every rank's report, rank order.
    pub reports: Vec<RankReport>,
}

impl DistImage {
    /// The image as a single rank's session returns it: the f64 mean rounded to f32, or past
    /// a blue-noise mask cycle the cycles weighted by their noise.
    pub fn image(&self) -> Image {
        self.weighted
            .clone()
            .unwrap_or_else(|| f32_image(self.width, self.height, &self.mean))
    }
}

/// Records `[r N / P, (r + 1) N / P)` of `step`: the part rank r of P reads
/// ([`crate::io::Part`]).
pub fn slice_of(step: &Step, rank: usize, ranks: usize) -> Step {
    crate::io::slice_step(step, crate::io::Part::new(rank, ranks))
}

fn check_frames(frames: &[FrameParams]) -> Result<(), DistError> {
    let Some(first) = frames.first() else {
        return Err(DistError::NotDistributed(
            "a distributed render of no frames".into(),
        ));
    };
    for f in frames {
        if (f.width, f.height) != (first.width, first.height) {
            return Err(DistError::NotDistributed(
                "frames of different sizes in one accumulation".into(),
            ));
        }
    }
    Ok(())
}

/// Whether a frame's image depends on light that crosses bricks: a scattering integrator with
/// a light to shadow (else no light map is made).
fn shadows_cross_bricks(frame: &FrameParams) -> bool {
    frame.integrator != Integrator::Ea && frame.light_intensity != 0.0
}

/// Whether two frames have the same light map: the same light through the same field.
fn same_light(a: &FrameParams, b: &FrameParams) -> bool {
    a.light_dir == b.light_dir
        && a.box_min == b.box_min
        && a.box_max == b.box_max
        && a.dt == b.dt
        && a.phi_ref == b.phi_ref
        && a.density_scale == b.density_scale
        && a.optical_table == b.optical_table
}

/// The brick's [`LightPrefix`] for `frame`'s light: every brick marches through its own
/// samples the map's texels near its box that a brick farther from the light needs (those
/// near both boxes; none for the brick farthest along every texel), and an exclusive scan in
/// the order from the light sums, per texel, the bricks nearer the light. Returns the bytes
/// sent.
fn light_prefix(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    tree: &KdTree,
    frame: &FrameParams,
    size: u32,
) -> Result<(LightPrefix, usize), DistError> {
    let map = LightMap::new(frame.light_dir, frame.march_box(), size);
    let near: Vec<PixelRect> = tree
        .leaves()
        .iter()
        .map(|l| map.texels_near(l.clipped_to(frame.march_box())))
        .collect();
    let order = tree.nearest_first_along(frame.light_dir);
    // Per brick, the texels a brick after it in that order needs: the rectangle around their
    // overlaps (every rank computes every brick's, so the scan knows what each one holds).
    let marched: Vec<PixelRect> = order.iter().enumerate().fold(
        vec![PixelRect::default(); near.len()],
        |mut marched, (k, &b)| {
            marched[b] = order[k + 1..]
                .iter()
                .map(|&later| near[b].intersection(&near[later]))
                .fold(PixelRect::default(), |around, o| around.around(&o));
            marched
        },
    );
    let me = comm.rank();
    let mine = if marched[me].is_empty() {
        Vec::new()
    } else {
        backend.owned_depth(
            frame,
            &tree.leaves()[me],
            DepthRays::Light(&map, marched[me]),
        )?
    };
    let scanned = exclusive_scan(comm, &order, &marched, &near, &mine)?;
    let prefix = LightPrefix {
        map,
        rect: near[me],
        depth: scanned.sums,
    };
    Ok((prefix, scanned.bytes_sent))
}

/// With a periodic box, `local` wrapped into it with its periodic images, and the bounds every
/// brick is prepared with: the box grown by the largest reach over all ranks (one all-gather),
/// as the single rank grows it by its step's. Without one, nothing and the series' bounds.
fn periodic_images(
    comm: &dyn Comm,
    local: &Step,
    scene: &DistScene<'_>,
) -> Result<(Option<Step>, Bounds), DistError> {
    let Some(periodic) = &scene.periodic else {
        return Ok((None, scene.series_bounds));
    };
    let images = periodic.images(local, scene.field, scene.series_range)?;
    if images.wrapped > 0 {
        tracing::info!(
            "step '{}': {} particles outside the periodic box wrapped into it (rank {})",
            local.name,
            images.wrapped,
            comm.rank()
        );
    }
    let largest = comm
        .all_gather_of(&[images.largest_reach])?
        .iter()
        .flatten()
        .fold(0.0, |a: f64, &b| a.max(b));
    let step = Arc::try_unwrap(images.step).unwrap_or_else(|shared| (*shared).clone());
    Ok((Some(step), periodic.bounds().grown(largest)))
}

/// Pilot renders before the first image balanced by cost: the first by count, each later one
/// balanced by what those before it measured, which it corrects leaf by leaf
/// ([`CostModel::refined`]). `aarbf bench distributed --ranks 1,4 --weak-count 0 --balance
/// cost` on the 1M dam break at 1024² (emission–absorption, bricks behind opaque ones ending
/// their rays), six runs each: the slowest rank rendered 1.25–1.50 times the mean (median
/// 1.43) after one pilot, 1.17–1.23 (median 1.22) after two.
const PILOT_ROUNDS: usize = 2;

/// [`render_balanced`] balanced by what a `pilot` frame measures where one is given (rendered
/// first, [`PILOT_ROUNDS`] times, on the same bricks' rules and not kept: how `--balance cost`
/// starts), else by `cost`.
/// It takes this rank's part: once the exchange has put what the rank renders into its brick,
/// the part is dropped, so that a rank does not hold its read share through the render.
pub fn render_piloted(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    local: Step,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
    pilot: Option<&FrameParams>,
    cost: Option<&CostModel>,
) -> Result<(Option<DistImage>, CostModel), DistError> {
    check_frames(frames)?;
    let mut piloted: Option<CostModel> = None;
    if let Some(p) = pilot {
        // The pilot's light map is to its render what the image's is to the image's.
        let pilot_scene = DistScene {
            shadows: match scene.shadows {
                DistShadows::PrefixMap(side) => DistShadows::PrefixMap(pilot_side(side)),
                local => local,
            },
            ..*scene
        };
        for _ in 0..PILOT_ROUNDS {
            let frames = std::slice::from_ref(p);
            let (_, measured) = render_balanced(
                comm,
                backend,
                &local,
                &pilot_scene,
                frames,
                piloted.as_ref(),
            )?;
            piloted = Some(measured);
        }
    }
    let brick = prepare_brick(comm, backend, &local, scene, piloted.as_ref().or(cost))?;
    drop(local);
    render_frames_on(comm, backend, &brick, scene, frames)
}

/// A pass before a frame's render: this brick's optical depth along `rays` (the pixels of
/// `rects[rank]`), and the exclusive scan of the bricks' depths in view order `order`: per
/// pixel of that rectangle, the depth of the bricks in front. A brick that no brick behind it
/// needs (no later rectangle meets its own) marches nothing. The march is timed as rendering,
/// the scan as compositing.
#[allow(clippy::too_many_arguments)]
fn scanned_depth(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    frame: &FrameParams,
    leaf: &HalfOpenBox,
    rays: DepthRays<'_>,
    order: &[usize],
    rects: &[PixelRect],
    report: &mut RankReport,
) -> Result<Vec<f64>, DistError> {
    let me = comm.rank();
    let clock = StageClock::start();
    let needed_behind = order
        .iter()
        .skip_while(|&&r| r != me)
        .skip(1)
        .any(|&r| !rects[r].intersection(&rects[me]).is_empty());
    let mine = if needed_behind {
        backend.owned_depth(frame, leaf, rays)?
    } else {
        vec![0.0; rects[me].len()]
    };
    let (wall, cpu) = clock.stop();
    report.render_seconds += wall;
    report.render_cpu_seconds += cpu;
    let clock = StageClock::start();
    let scanned = exclusive_scan(comm, order, rects, rects, &mine)?;
    report.tile_bytes += scanned.bytes_sent as u64;
    let (wall, cpu) = clock.stop();
    report.composite_seconds += wall;
    report.composite_cpu_seconds += cpu;
    Ok(scanned.sums)
}

/// The depth in front of this brick per pixel of `rects[rank]`, where the frame's bricks need
/// it: stochastic marching's pass 1 (each primary ray's depth, stopped past its free-flight
/// depth); emission–absorption's occluding pass, a bound from below of it from a coarse frame
/// ([`occlusion`]; the bound's making is timed as compositing). `None` where no brick needs it.
#[allow(clippy::too_many_arguments)]
fn depth_in_front(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    frame: &FrameParams,
    tree: &KdTree,
    leaf: &HalfOpenBox,
    order: &[usize],
    rects: &[PixelRect],
    report: &mut RankReport,
) -> Result<Option<Vec<f64>>, DistError> {
    let me = comm.rank();
    if frame.integrator == Integrator::Marching {
        let rays = DepthRays::Primary(rects[me]);
        return scanned_depth(comm, backend, frame, leaf, rays, order, rects, report).map(Some);
    }
    if !occlusion::needed(frame, comm.size()) {
        return Ok(None);
    }
    let coarse = occlusion::coarse_frame(frame);
    let coarse_rects = brick_rects(&coarse, tree);
    let rays = DepthRays::Occluding {
        rect: coarse_rects[me],
        stop_past: occlusion::stop_depth(frame),
    };
    let scanned = scanned_depth(
        comm,
        backend,
        &coarse,
        leaf,
        rays,
        order,
        &coarse_rects,
        report,
    )?;
    let clock = StageClock::start();
    let bound = occlusion::depth_bound(frame, rects[me], &coarse, coarse_rects[me], &scanned);
    let (wall, cpu) = clock.stop();
    report.composite_seconds += wall;
    report.composite_cpu_seconds += cpu;
    Ok(Some(bound))
}

/// Each leaf's pixels of `frame`: those whose rays can meet its part of the march box.
fn brick_rects(frame: &FrameParams, tree: &KdTree) -> Vec<PixelRect> {
    let march_box = frame.march_box();
    tree.leaves()
        .iter()
        .map(|l| screen_rect(frame, l.clipped_to(march_box)))
        .collect()
}

/// A mean image, rounded to f32 as a backend returns it.
fn f32_image(width: u32, height: u32, mean: &[[f64; 4]]) -> Image {
    Image {
        width,
        height,
        pixels: mean.iter().map(|p| p.map(|v| v as f32)).collect(),
    }
}

/// The bytes of a step's positions and attributes.
fn step_bytes(step: &Step) -> usize {
    std::mem::size_of_val(step.positions.as_slice())
        + step
            .attributes
            .iter()
            .map(|a| std::mem::size_of_val(a.values.as_slice()))
            .sum::<usize>()
}

fn upload(
    backend: &mut dyn Backend,
    step: &Arc<Step>,
    scene: &DistScene<'_>,
    precision: Precision,
) -> Result<(), DistError> {
    backend.upload(&scene.step_input(step, precision))?;
    backend.build()?;
    Ok(())
}

/// Renders `frames` (one accumulation: the same size, any camera) of the step whose part this
/// rank read is `local`, on `backend`, and returns the image at rank 0 (`None` elsewhere).
/// Every rank calls it with its own `local` and the same `scene` and `frames`. The leaves
/// hold equal particles; [`render_balanced`] balances them by a measured cost.
pub fn render_distributed(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    local: &Step,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
) -> Result<Option<DistImage>, DistError> {
    render_balanced(comm, backend, local, scene, frames, None).map(|(image, _)| image)
}

/// [`representation_code`] of the most precise representations: f64 on the CPU, double-single
/// positions with compensated sums on a GPU (what each makes of [`Precision::F64`]).
const MOST_PRECISE: u8 = 0;

/// [`representation_code`] of a backend that holds no representation (a brick without
/// particles): it asks nothing of the others.
const NO_REPRESENTATION: u8 = u8::MAX;

/// A brick's representation as one byte for the ranks to compare: [`MOST_PRECISE`], which
/// less precise one it is, or [`NO_REPRESENTATION`].
fn representation_code(r: Option<crate::backend::Representation>) -> u8 {
    use crate::backend::precision::Summation;
    match r.map(|r| (r.positions, r.summation)) {
        None => NO_REPRESENTATION,
        Some((PositionKind::F64, _)) => MOST_PRECISE,
        Some((PositionKind::DoubleSingle, Summation::Compensated { .. })) => MOST_PRECISE,
        Some((PositionKind::DoubleSingle, _)) => 1,
        Some((PositionKind::F32, Summation::Compensated { .. })) => 2,
        Some((PositionKind::F32, _)) => 3,
    }
}

/// [`render_distributed`] with the leaves balanced by `cost` (equal particles where `None`),
/// returning, on every rank, what this render measured: each leaf's seconds of render and
/// light map per particle it owned, for the next decomposition. A rank's render time is its thread's CPU
/// time where it runs on one thread (its own work, whatever else shares the core), and the
/// wall time otherwise (its threads are its own cores under MPI).
pub fn render_balanced(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    local: &Step,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
    cost: Option<&CostModel>,
) -> Result<(Option<DistImage>, CostModel), DistError> {
    check_frames(frames)?;
    let brick = prepare_brick(comm, backend, local, scene, cost)?;
    render_frames_on(comm, backend, &brick, scene, frames)
}

/// A rank's brick, exchanged and uploaded to its backend: what any number of frames render
/// from ([`render_frames_on`]).
pub struct PreparedBrick {
    tree: KdTree,
    leaf: HalfOpenBox,
    step: Arc<Step>,
    /// The model the decomposition was balanced by, and the cost it predicted for the
    /// particles this brick owns (their count where there is none): what a render's
    /// measurement corrects ([`CostModel::refined`]).
    balanced_by: Option<CostModel>,
    predicted_cost: f64,
    /// The report of the exchange and build; each render adds its frames' stages to a copy.
    report: RankReport,
}

/// The decomposition, exchange and upload of [`render_balanced`]: this rank's brick of the
/// ranks' `local` parts, balanced by `cost` (equal particles where `None`). Collective.
pub fn prepare_brick(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    local: &Step,
    scene: &DistScene<'_>,
    cost: Option<&CostModel>,
) -> Result<PreparedBrick, DistError> {
    let mut report = RankReport {
        read: local.len() as u64,
        ..RankReport::default()
    };

    let clock = StageClock::start();
    let (with_images, bounds) = periodic_images(comm, local, scene)?;
    let local = with_images.as_ref().unwrap_or(local);
    let scene = &DistScene {
        series_bounds: bounds,
        ..*scene
    };
    let reaches = particle_reaches(local, scene.field, scene.series_range)?;
    let tree = decompose(comm, &local.positions, Some(&reaches), cost)?;
    let (brick, counts) = exchange(comm, &tree, local, &reaches)?;
    drop(reaches);
    drop(with_images);
    let predicted_cost = cost.map_or(brick.owned as f64, |c| {
        brick.step.positions[..brick.owned]
            .iter()
            .map(|&x| c.at(x))
            .sum()
    });
    report.owned = brick.owned as u64;
    report.ghosts = brick.ghosts() as u64;
    report.particle_bytes = counts.bytes_sent as u64;
    (report.exchange_seconds, report.exchange_cpu_seconds) = clock.stop();

    let clock = StageClock::start();
    let leaf = brick.leaf;
    let step = Arc::new(brick.step);
    upload(backend, &step, scene, scene.precision)?;
    // The precision a brick chooses follows its own particles; the image must not depend on
    // the decomposition, so where bricks chose differently every brick takes the most precise
    // (f64 on the CPU; on a GPU backend double-single positions with compensated sums, what
    // it makes of f64).
    let chosen = representation_code(backend.representation());
    let codes = comm.all_gather_of(&[chosen])?;
    let differ = codes
        .iter()
        .filter_map(|v| v.first())
        .any(|&c| c != NO_REPRESENTATION && c != chosen);
    if differ && chosen != MOST_PRECISE && chosen != NO_REPRESENTATION {
        upload(backend, &step, scene, Precision::F64)?;
    }
    report.f64_positions = u64::from(
        backend
            .representation()
            .is_some_and(|r| r.positions == PositionKind::F64),
    );
    (report.build_seconds, report.build_cpu_seconds) = clock.stop();
    Ok(PreparedBrick {
        tree,
        leaf,
        step,
        balanced_by: cost.cloned(),
        predicted_cost,
        report,
    })
}

/// Renders `frames` (one image's, [`check_frames`]) from a brick [`prepare_brick`] made,
/// composites them and gathers the image at rank 0, as [`render_balanced`] does; returns what
/// the render measured for the next decomposition. Collective.
pub fn render_frames_on(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    brick: &PreparedBrick,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
) -> Result<(Option<DistImage>, CostModel), DistError> {
    check_frames(frames)?;
    let PreparedBrick {
        tree,
        leaf,
        step,
        balanced_by,
        predicted_cost,
        report,
    } = brick;
    let leaf = *leaf;
    let mut report = *report;
    let grid = TileGrid {
        width: frames[0].width,
        height: frames[0].height,
        ranks: comm.size(),
    };
    let mut sums = TileSums::new(grid, comm.rank());
    // Past a blue-noise mask cycle the image weights the cycles by their measured noise
    // (`render::cycles`), from the means at a few frame counts: each tile's owner keeps its
    // sums at every count that can be asked for, and rank 0 replays the single rank's choice.
    let cycles = CycleWeights::of_frames(frames[0].noise, frames[0].integrator);
    let mut kept: Vec<(u32, Vec<[f64; 4]>)> = Vec::new();
    let mut largest_layer = 0;
    let mut light: Option<(FrameParams, LightPrefix)> = None;
    for frame in frames {
        if cycles
            .as_ref()
            .is_some_and(|c| c.may_want_mean_at(sums.frames))
        {
            kept.push((sums.frames, sums.flat()));
        }
        let light_here = match scene.shadows {
            // One brick has no brick nearer the light.
            DistShadows::PrefixMap(size) if comm.size() > 1 && shadows_cross_bricks(frame) => {
                if light.as_ref().is_none_or(|(f, _)| !same_light(f, frame)) {
                    let clock = StageClock::start();
                    let (prefix, bytes) = light_prefix(comm, backend, tree, frame, size)?;
                    light = Some((frame.clone(), prefix));
                    let (wall, cpu) = clock.stop();
                    report.shadow_map_seconds += wall;
                    report.shadow_map_cpu_seconds += cpu;
                    report.shadow_map_bytes += bytes as u64;
                }
                light.as_ref().map(|(_, l)| l)
            }
            _ => None,
        };
        let rects = brick_rects(frame, tree);
        let rect = rects[comm.rank()];
        let order = tree.front_to_back(frame.camera.eye);
        let depth_in_front = depth_in_front(
            comm,
            backend,
            frame,
            tree,
            &leaf,
            &order,
            &rects,
            &mut report,
        )?;

        let clock = StageClock::start();
        let share = BrickShare {
            owned: &leaf,
            rect,
            index: comm.rank() as u32,
            depth_in_front: depth_in_front.as_deref(),
            light: light_here,
        };
        let layer = backend.render_owned(frame, &share)?;
        largest_layer = largest_layer.max(std::mem::size_of_val(layer.as_slice()));
        let (wall, cpu) = clock.stop();
        report.render_seconds += wall;
        report.render_cpu_seconds += cpu;

        let clock = StageClock::start();
        let blended = direct_send(comm, &grid, rect, &layer, &order)?;
        sums.add(&blended.tiles, frame.background);
        report.tile_bytes += blended.bytes_sent as u64;
        let (wall, cpu) = clock.stop();
        report.composite_seconds += wall;
        report.composite_cpu_seconds += cpu;
    }
    let memory = backend.memory();
    report.memory_bytes = (step_bytes(step)
        + memory.particle_bytes
        + memory.structure_bytes
        + memory.image_bytes
        + largest_layer) as u64;

    // The work that follows the brick: its render and its light map (single scattering's
    // shadows across bricks), which balancing by render alone would pile on the bricks it
    // gives more particles.
    let seconds = if rayon::current_num_threads() == 1 {
        report.render_cpu_seconds + report.shadow_map_cpu_seconds
    } else {
        report.render_seconds + report.shadow_map_seconds
    };
    let measured = comm.all_gather_of(&[[report.owned as f64, seconds, *predicted_cost]])?;
    let measured = CostModel::refined(balanced_by.as_ref(), tree.clone(), &measured.concat());

    // The kept sums, then the final ones, end to end: one gather.
    let mut flat: Vec<[f64; 4]> = kept.iter().flat_map(|(_, k)| k.iter().copied()).collect();
    flat.extend(sums.flat());
    let tiles = comm.gather_of(0, &flat)?;
    let reports = comm.gather_of(0, &[report])?;
    let (Some(tiles), Some(reports)) = (tiles, reports) else {
        return Ok((None, measured));
    };
    let sums_at = |j: usize| -> Result<Vec<[f64; 4]>, DistError> {
        let parts: Vec<Vec<[f64; 4]>> = tiles
            .iter()
            .map(|t| {
                let len = t.len() / (kept.len() + 1);
                t[j * len..(j + 1) * len].to_vec()
            })
            .collect();
        assemble(&grid, &parts)
    };
    let mean_of = |sums: Vec<[f64; 4]>, frames: u32| -> Vec<[f64; 4]> {
        let n = f64::from(frames.max(1));
        sums.into_iter().map(|s| s.map(|v| v / n)).collect()
    };
    let mean = mean_of(sums_at(kept.len())?, sums.frames);
    let weighted = match cycles {
        Some(mut cycles) if !kept.is_empty() => {
            for (j, (at, _)) in kept.iter().enumerate() {
                if cycles.wants_mean_at(*at) {
                    let image = f32_image(grid.width, grid.height, &mean_of(sums_at(j)?, *at));
                    cycles.took_mean(*at, image);
                }
            }
            Some(cycles.image(sums.frames, f32_image(grid.width, grid.height, &mean)))
        }
        _ => None,
    };
    let image = DistImage {
        width: grid.width,
        height: grid.height,
        frames: sums.frames,
        mean,
        weighted,
        reports: reports.concat(),
    };
    Ok((Some(image), measured))
}
