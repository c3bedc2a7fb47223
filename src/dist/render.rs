//! One distributed render: decompose, exchange, build each brick, then per frame render the
//! brick's samples, composite by direct send and accumulate; the image gathered at rank 0.

use std::sync::Arc;

use super::DistError;
use super::balance::CostModel;
use super::clock::StageClock;
use super::comm::{Comm, CommExt};
use super::composite::{TileGrid, TileSums, assemble, direct_send, screen_rect};
use super::exchange::{decompose, exchange};
use crate::accel::ClusterSize;
use crate::backend::precision::PositionKind;
use crate::backend::{Backend, Precision, StepInput};
use crate::field::{FieldSettings, PeriodicBox, particle_reaches};
use crate::render::CycleWeights;
use crate::values::{Bounds, FrameParams, Image, Integrator, Step};

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
    /// Bytes of tiles sent to other ranks in compositing (all frames).
    pub tile_bytes: u64,
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
    /// Seconds compositing (all frames).
    pub composite_seconds: f64,
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
        if f.integrator != Integrator::Ea {
            return Err(DistError::NotDistributed(format!(
                "--integrator {}: single scattering across bricks (a free flight or a shadow ray \
                 that crosses ranks) is not distributed yet; distributed renders are \
                 emission-absorption (--integrator ea)",
                match f.integrator {
                    Integrator::Delta => "delta",
                    Integrator::Marching => "marching",
                    Integrator::SsReference => "ss-reference",
                    Integrator::Ea => "ea",
                }
            )));
        }
        if (f.width, f.height) != (first.width, first.height) {
            return Err(DistError::NotDistributed(
                "frames of different sizes in one accumulation".into(),
            ));
        }
    }
    Ok(())
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
    backend.upload(&StepInput {
        step,
        field: scene.field,
        cluster: scene.cluster,
        series_bounds: scene.series_bounds,
        series_range: scene.series_range,
        precision,
    })?;
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

/// [`render_distributed`] with the leaves balanced by `cost` (equal particles where `None`),
/// returning, on every rank, what this render measured: each leaf's render seconds per
/// particle it owned, for the next decomposition. A rank's render time is its thread's CPU
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
    let tree = decompose(comm, &local.positions, cost)?;
    let (brick, counts) = exchange(comm, &tree, local, &reaches)?;
    drop(reaches);
    drop(with_images);
    report.owned = brick.owned as u64;
    report.ghosts = brick.ghosts() as u64;
    report.particle_bytes = counts.bytes_sent as u64;
    (report.exchange_seconds, report.exchange_cpu_seconds) = clock.stop();

    let clock = StageClock::start();
    let leaf = brick.leaf;
    let step = Arc::new(brick.step);
    upload(backend, &step, scene, scene.precision)?;
    // The precision a brick chooses follows its own particles; the image must not depend on
    // the decomposition, so where any brick needs f64 every brick takes it.
    let f64_here = backend
        .representation()
        .is_some_and(|r| r.positions == PositionKind::F64);
    let any_f64 = comm
        .all_gather_of(&[u8::from(f64_here)])?
        .iter()
        .any(|v| v.first() == Some(&1));
    if any_f64 && !f64_here {
        upload(backend, &step, scene, Precision::F64)?;
    }
    report.f64_positions = u64::from(any_f64);
    (report.build_seconds, report.build_cpu_seconds) = clock.stop();

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
    for frame in frames {
        if cycles
            .as_ref()
            .is_some_and(|c| c.may_want_mean_at(sums.frames))
        {
            kept.push((sums.frames, sums.flat()));
        }
        let clock = StageClock::start();
        let march_box = Bounds {
            min: frame.box_min,
            max: frame.box_max,
        };
        let rect = screen_rect(frame, leaf.clipped_to(march_box));
        let layer = backend.render_owned(frame, &leaf, rect)?;
        largest_layer = largest_layer.max(std::mem::size_of_val(layer.as_slice()));
        let (wall, cpu) = clock.stop();
        report.render_seconds += wall;
        report.render_cpu_seconds += cpu;

        let clock = StageClock::start();
        let order = tree.front_to_back(frame.camera.eye);
        let blended = direct_send(comm, &grid, rect, &layer, &order)?;
        sums.add(&blended.tiles, frame.background);
        report.tile_bytes += blended.bytes_sent as u64;
        let (wall, cpu) = clock.stop();
        report.composite_seconds += wall;
        report.composite_cpu_seconds += cpu;
    }
    let memory = backend.memory();
    report.memory_bytes = (step_bytes(&step)
        + memory.particle_bytes
        + memory.structure_bytes
        + memory.image_bytes
        + largest_layer) as u64;

    let seconds = if rayon::current_num_threads() == 1 {
        report.render_cpu_seconds
    } else {
        report.render_seconds
    };
    let measured = comm.all_gather_of(&[[report.owned as f64, seconds]])?;
    let measured = CostModel::new(tree, &measured.concat());

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
