//! One distributed render: decompose, exchange, build each brick, then per frame render the
//! brick's samples, composite by direct send and accumulate; the image gathered at rank 0.

use std::sync::Arc;
use std::time::Instant;

use super::DistError;
use super::comm::{Comm, CommExt};
use super::composite::{TileGrid, TileSums, assemble, direct_send, screen_rect};
use super::exchange::{decompose, exchange};
use crate::accel::ClusterSize;
use crate::backend::precision::PositionKind;
use crate::backend::{Backend, Precision, StepInput};
use crate::field::{FieldSettings, particle_reaches};
use crate::values::{Bounds, FrameParams, Image, Integrator, Step};

/// What every rank renders with: the same on all of them (series-wide values, never one
/// rank's), so that every brick's field is the single-rank field over its leaf.
#[derive(Clone, Copy, Debug)]
pub struct DistScene<'a> {
    /// The field every brick renders: attribute, radius, maps, kernel.
    pub field: &'a FieldSettings,
    /// The cluster size every brick's BVH is built with.
    pub cluster: ClusterSize,
    /// The series' bounds: the Hilbert grid and local origin of every brick.
    pub series_bounds: Bounds,
    /// The attribute's range over the series (never a brick's).
    pub series_range: Option<(f64, f64)>,
    /// Asked of every brick; where bricks would choose differently (`auto`), all take f64.
    pub precision: Precision,
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
    /// Every rank's report, rank order.
    pub reports: Vec<RankReport>,
}

impl DistImage {
    /// The image as a backend returns it (the f64 mean rounded to f32).
    pub fn image(&self) -> Image {
        Image {
            width: self.width,
            height: self.height,
            pixels: self.mean.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
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
/// Every rank calls it with its own `local` and the same `scene` and `frames`.
pub fn render_distributed(
    comm: &dyn Comm,
    backend: &mut dyn Backend,
    local: &Step,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
) -> Result<Option<DistImage>, DistError> {
    check_frames(frames)?;
    let mut report = RankReport {
        read: local.len() as u64,
        ..RankReport::default()
    };

    let started = Instant::now();
    let reaches = particle_reaches(local, scene.field, scene.series_range)?;
    let tree = decompose(comm, &local.positions)?;
    let (brick, counts) = exchange(comm, &tree, local, &reaches)?;
    drop(reaches);
    report.owned = brick.owned as u64;
    report.ghosts = brick.ghosts() as u64;
    report.particle_bytes = counts.bytes_sent as u64;
    report.exchange_seconds = started.elapsed().as_secs_f64();

    let started = Instant::now();
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
    report.build_seconds = started.elapsed().as_secs_f64();

    let grid = TileGrid {
        width: frames[0].width,
        height: frames[0].height,
        ranks: comm.size(),
    };
    let mut sums = TileSums::new(grid, comm.rank());
    for frame in frames {
        let started = Instant::now();
        let march_box = Bounds {
            min: frame.box_min,
            max: frame.box_max,
        };
        let rect = screen_rect(frame, leaf.clipped_to(march_box));
        let layer = backend.render_owned(frame, &leaf, rect)?;
        report.render_seconds += started.elapsed().as_secs_f64();

        let started = Instant::now();
        let order = tree.front_to_back(frame.camera.eye);
        let blended = direct_send(comm, &grid, rect, &layer, &order)?;
        sums.add(&blended.tiles, frame.background);
        report.tile_bytes += blended.bytes_sent as u64;
        report.composite_seconds += started.elapsed().as_secs_f64();
    }

    let tiles = comm.gather_of(0, &sums.flat())?;
    let reports = comm.gather_of(0, &[report])?;
    let (Some(tiles), Some(reports)) = (tiles, reports) else {
        return Ok(None);
    };
    let n = f64::from(sums.frames.max(1));
    let mean = assemble(&grid, &tiles)?
        .into_iter()
        .map(|s| s.map(|v| v / n))
        .collect();
    Ok(Some(DistImage {
        width: grid.width,
        height: grid.height,
        frames: sums.frames,
        mean,
        reports: reports.concat(),
    }))
}
