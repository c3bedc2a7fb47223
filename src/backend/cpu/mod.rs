//! The CPU backend: the field of a step and the integrators of [`integrators`] (the twin of
//! `shaders_glsl/shared/integrators.glsl`), rayon over image tiles, each tile's pixels in
//! packets of 4 x 2 whose rays the marching integrators advance in step. It is the reference
//! renderer GPU backends are compared with, and the renderer where no GPU driver exists. Two
//! precisions, chosen per scene by the rule the GPU backends use for their positions
//! ([`Precision`]): the f64 reference ([`ReferenceField`]: the particles in a grid of cells,
//! each term computed exactly, four distance tests at a time; what every test compares
//! against), and f32 ([`F32Field`]: the same cells, evaluated eight at a time with a polynomial
//! exponential), where the scene's positions and radii let f32 keep the error asked for. Both
//! skip empty space along rays cell by cell (the image is unchanged: the field there is 0),
//! and a scene builds only the one it uses (the splatter adds the reference's cluster BVH).

mod accumulator;
pub mod integrators;
mod owned;
pub mod splat;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use self::accumulator::Accumulator;
use self::integrators::{FieldSampler, PACKET, PACKET_SIZE, PixelScratch, render_pixels_with};
use super::precision::{PositionKind, Representation, SceneNumbers, choose_cpu};
use super::voxel::{VoxelGeometry, VoxelGrid};
use super::{
    Backend, BackendError, BrickShare, Capabilities, DepthRays, MemoryReport, Precision, StepInput,
    Timings,
};
use crate::accel::CellRuns;
use crate::field::splat::{SplatCounts, SplatScratch};
use crate::field::{
    F32Batch, F32Field, F32Packet, F32Ray, FieldSettings, Particles, ReferenceField,
};
use crate::values::{FrameParams, HalfOpenBox, Image, Step};

const TILE: u32 = 16;

/// Point queries a task: consecutive ones (in Hilbert order) share cells, and enough tasks
/// balance the threads.
const QUERY_CHUNK: usize = 512;

/// The uploaded step (shared with the series' cache, never copied), kept to re-evaluate its
/// particles' radii and maps when those change.
struct Uploaded {
    step: Arc<Step>,
    field: FieldSettings,
    cluster: crate::accel::ClusterSize,
    series_range: Option<(f64, f64)>,
    series_bounds: crate::values::Bounds,
    precision: Precision,
}

/// The particles, sorted once per upload, and the structure built over them for the precision
/// the scene gets: nothing yet, the f64 reference's cells, or the f32 cells (one at a time, so
/// a scene pays only for the structure it renders with).
#[allow(clippy::large_enum_variant)]
enum Prepared {
    Sorted(Particles),
    Reference(ReferenceField),
    Cells(Particles, F32Field),
}

impl Prepared {
    fn particles(&self) -> &Particles {
        match self {
            Prepared::Sorted(p) | Prepared::Cells(p, _) => p,
            Prepared::Reference(f) => &f.particles,
        }
    }

    fn particles_mut(&mut self) -> &mut Particles {
        match self {
            Prepared::Sorted(p) | Prepared::Cells(p, _) => p,
            Prepared::Reference(f) => &mut f.particles,
        }
    }

    fn into_particles(self) -> Particles {
        match self {
            Prepared::Sorted(p) | Prepared::Cells(p, _) => p,
            Prepared::Reference(f) => f.particles,
        }
    }
}

/// The CPU backend: the reference renderer, the field in f64 or in f32 over a grid of cells, rayon
/// over image tiles (module docs).
pub struct CpuBackend {
    capabilities: Capabilities,
    uploaded: Option<Uploaded>,
    prepared: Option<Prepared>,
    /// How the uploaded scene is held and summed, with its error bound (`backend::precision`).
    representation: Option<Representation>,
    accumulator: Option<Accumulator>,
    /// The voxel baseline's grid of the last [`Backend::voxelize`].
    voxels: Option<VoxelGrid>,
    timings: Timings,
    abandon: Option<Arc<AtomicBool>>,
}

impl Default for CpuBackend {
    fn default() -> Self {
        Self::new()
    }
}

impl CpuBackend {
    /// A CPU backend with nothing uploaded.
    pub fn new() -> CpuBackend {
        CpuBackend {
            capabilities: Capabilities {
                name: "cpu",
                device: format!("CPU, {} threads", rayon::current_num_threads()),
                hardware_rt: false,
                software: false,
                max_particles: None,
                scatters_grids: true,
                frame_timer: super::FrameTimer::WallClock,
            },
            uploaded: None,
            prepared: None,
            representation: None,
            accumulator: None,
            voxels: None,
            timings: Timings::default(),
            abandon: None,
        }
    }

    fn prepared(&self) -> Result<&Prepared, BackendError> {
        self.prepared
            .as_ref()
            .ok_or(BackendError::NothingUploaded("cpu"))
    }

    /// Re-evaluates the particles under `field` (checked first: on an error nothing changes),
    /// returning them with the uploaded step.
    fn apply_field(&mut self, field: &FieldSettings) -> Result<&mut Uploaded, BackendError> {
        let (Some(up), Some(prepared)) = (self.uploaded.as_mut(), self.prepared.as_mut()) else {
            return Err(BackendError::NothingUploaded("cpu"));
        };
        prepared
            .particles_mut()
            .apply_field(&up.step, field, up.series_range)?;
        up.field = field.clone();
        Ok(up)
    }

    /// Builds the structure for the scene's precision ([`Precision`], decided by the f32
    /// error bound of `gpu_data`, one rule for every backend): the f32 cells where f32 is
    /// allowed, the f64 reference otherwise.
    fn build_structure(&mut self) -> Result<(), BackendError> {
        let (Some(up), Some(prepared)) = (&self.uploaded, self.prepared.take()) else {
            return Err(BackendError::NothingUploaded("cpu"));
        };
        let particles = prepared.into_particles();
        let positive = |v: &[f64]| {
            v.par_iter()
                .filter(|&&x| x > 0.0)
                .fold(
                    || (f64::INFINITY, 0.0f64),
                    |(lo, hi), &x| (lo.min(x), hi.max(x)),
                )
                .reduce(|| (f64::INFINITY, 0.0), |a, b| (a.0.min(b.0), a.1.max(b.1)))
        };
        let (r_min, r_max) = positive(&particles.radii);
        let (w_min, w_max) = positive(&particles.weights);
        // Local coordinates are relative to the series' centre: none exceeds its half-extent.
        let b = up.series_bounds;
        let largest = if b.is_empty() {
            0.0
        } else {
            (b.max - b.min).max_element() * 0.5
        };
        // The f32 kernel takes radii and weights rounded from f64: no map slopes. Its sums are
        // blocked in f64, so the count of terms barely enters the bound: every particle bounds
        // it (no count of the overlap needed).
        let scene = SceneNumbers {
            largest,
            r_min,
            r_max,
            max_terms: particles.centers.len(),
            w_min,
            w_max,
            radius_varies: false,
            density_slope: 0.0,
            radius_slope: 0.0,
            kernel: particles.kernel,
        };
        let representation = choose_cpu(
            up.precision,
            &scene,
            crate::field::f32_kernel::LANE_TERMS as u32,
            crate::field::f32_kernel::exp_error_in_use(),
        );
        self.representation = Some(representation);
        let f32_allowed = representation.positions == PositionKind::F32;
        self.prepared = Some(if f32_allowed {
            let cells = F32Field::new(&particles);
            Prepared::Cells(particles, cells)
        } else {
            Prepared::Reference(ReferenceField::new(particles, up.cluster))
        });
        Ok(())
    }

    /// The field as the integrators and queries use it: f32 or the f64 reference.
    fn sampler(&self) -> Result<Sampler<'_>, BackendError> {
        match self.prepared()? {
            Prepared::Reference(f) => Ok(Sampler::F64(f)),
            Prepared::Cells(_, cells) => Ok(Sampler::F32(cells)),
            Prepared::Sorted(_) => Err(BackendError::NothingUploaded("cpu")),
        }
    }
}

/// The field a frame or a query reads.
enum Sampler<'a> {
    F64(&'a ReferenceField),
    F32(&'a F32Field),
}

impl FieldSampler for ReferenceField {
    type Ray = CellRuns;
    type Packet = ();

    fn begin(
        &self,
        _: &mut CellRuns,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        occupied: &mut Vec<(f64, f64)>,
    ) {
        self.occupied_intervals(origin, dir, t0, t1, occupied);
    }

    fn sample(&self, ray: &mut CellRuns, x: DVec3) -> (f64, [f64; 3]) {
        self.eval_sums_with(x, ray)
    }
}

impl FieldSampler for VoxelGrid {
    type Ray = ();
    type Packet = ();

    // `begin` is the default, the whole interval: the grid does not skip empty space (as the
    // baseline it models).

    fn sample(&self, _: &mut (), x: DVec3) -> (f64, [f64; 3]) {
        self.trilinear(x)
    }
}

impl FieldSampler for F32Field {
    type Ray = F32Ray;

    fn begin(
        &self,
        _: &mut F32Ray,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        occupied: &mut Vec<(f64, f64)>,
    ) {
        self.occupied(origin, dir, t0, t1, occupied);
    }

    fn sample(&self, ray: &mut F32Ray, x: DVec3) -> (f64, [f64; 3]) {
        self.eval_sums(x, ray)
    }

    type Packet = F32Packet;

    fn sample_packet(
        &self,
        packet: &mut F32Packet,
        rays: &mut [F32Ray; PACKET],
        points: &[Option<DVec3>; PACKET],
        out: &mut [(f64, [f64; 3]); PACKET],
    ) {
        // How many were evaluated together is for tests.
        let _ = self.eval_sums_packet(points, packet, rays, out);
    }
}

/// Renders one frame's pixels with `field`, rayon over tiles, each tile's pixels in packets
/// of [`PACKET_SIZE`] (neighbouring rays, marched together), the rays' state reused; None when
/// `abandoned` said so before a tile.
fn render_tiles<F: FieldSampler>(
    frame: &FrameParams,
    field: &F,
    abandoned: &(dyn Fn() -> bool + Sync),
) -> Vec<Vec<[f64; 4]>> {
    tiles_of(
        frame,
        abandoned,
        |scratch: &mut PixelScratch<F>, lo: [u32; 2], hi: [u32; 2], out: &mut [[f64; 4]]| {
            let width = (hi[0] - lo[0]) as usize;
            let (pw, ph) = PACKET_SIZE;
            let mut values = [[0.0; 4]; PACKET];
            let mut pixels = Vec::with_capacity(PACKET);
            for by in (lo[1]..hi[1]).step_by(ph as usize) {
                for bx in (lo[0]..hi[0]).step_by(pw as usize) {
                    pixels.clear();
                    for y in by..(by + ph).min(hi[1]) {
                        for x in bx..(bx + pw).min(hi[0]) {
                            pixels.push((x, y));
                        }
                    }
                    render_pixels_with(frame, field, &pixels, scratch, &mut values);
                    for (&(x, y), v) in pixels.iter().zip(values) {
                        out[(y - lo[1]) as usize * width + (x - lo[0]) as usize] = v;
                    }
                }
            }
        },
    )
}

/// Each tile's pixels (row-major within the tile), rayon over tiles, `tile` called with the
/// tile's corners (`lo` inclusive, `hi` exclusive), its row-major pixels to fill and a scratch
/// made once per rayon job; a tile started after `abandoned` said so is left empty.
fn tiles_of<S: Default + Send>(
    frame: &FrameParams,
    abandoned: &(dyn Fn() -> bool + Sync),
    tile: impl Fn(&mut S, [u32; 2], [u32; 2], &mut [[f64; 4]]) + Sync,
) -> Vec<Vec<[f64; 4]>> {
    let (w, h) = (frame.width, frame.height);
    let tiles_x = w.div_ceil(TILE);
    (0..tiles_x * h.div_ceil(TILE))
        .into_par_iter()
        .map_init(S::default, |scratch, index| {
            let (tx, ty) = (index % tiles_x, index / tiles_x);
            if abandoned() {
                return Vec::new();
            }
            let lo = [tx * TILE, ty * TILE];
            let hi = [((tx + 1) * TILE).min(w), ((ty + 1) * TILE).min(h)];
            let mut out = vec![[0.0; 4]; ((hi[0] - lo[0]) * (hi[1] - lo[1])) as usize];
            tile(scratch, lo, hi, &mut out);
            out
        })
        .collect()
}

/// [`tiles_of`] with `pixel` called for each pixel of a tile in row-major order.
fn pixels_of<S: Default + Send>(
    frame: &FrameParams,
    abandoned: &(dyn Fn() -> bool + Sync),
    pixel: impl Fn(&mut S, u32, u32) -> [f64; 4] + Sync,
) -> Vec<Vec<[f64; 4]>> {
    tiles_of(frame, abandoned, |scratch: &mut S, lo, hi, out| {
        let mut values = out.iter_mut();
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                *values.next().expect("one value per pixel") = pixel(scratch, x, y);
            }
        }
    })
}

impl CpuBackend {
    /// The mean of the frames accumulated so far in f64, before [`Backend::image`] rounds it to
    /// f32 (what distributed renders are compared with to f64 rounding).
    pub fn mean_f64(&self) -> Option<Vec<[f64; 4]>> {
        self.accumulator.as_ref().map(Accumulator::mean)
    }

    fn abandoned(&self) -> bool {
        self.abandon
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// Puts a frame's tiles in image order and adds them to the accumulation (a frame of
    /// another size restarts it); nothing is added when the frame was abandoned.
    fn accumulate_tiles(
        &mut self,
        frame: &FrameParams,
        tiles: Vec<Vec<[f64; 4]>>,
    ) -> Result<(), BackendError> {
        // Checked once more after every tile: a tile that saw no flag may have been followed
        // by one that did; the accumulation is untouched either way.
        if self.abandoned() {
            return Err(BackendError::Abandoned);
        }
        let (w, h) = (frame.width, frame.height);
        let tiles_x = w.div_ceil(TILE);
        let mut pixels = vec![[0.0; 4]; (w as usize) * (h as usize)];
        for (tile, values) in tiles.into_iter().enumerate() {
            let (tx, ty) = (tile as u32 % tiles_x, tile as u32 / tiles_x);
            let mut values = values.into_iter();
            for y in ty * TILE..((ty + 1) * TILE).min(h) {
                for x in tx * TILE..((tx + 1) * TILE).min(w) {
                    pixels[(y * w + x) as usize] = values.next().expect("one value per pixel");
                }
            }
        }
        let acc = match &mut self.accumulator {
            Some(a) if a.width == w && a.height == h => a,
            slot => slot.insert(Accumulator::new(w, h)),
        };
        acc.add(&pixels);
        Ok(())
    }
}

impl Backend for CpuBackend {
    fn capabilities(&self) -> &Capabilities {
        &self.capabilities
    }

    fn upload(&mut self, input: &StepInput<'_>) -> Result<(), BackendError> {
        let started = Instant::now();
        let particles = Particles::prepare(
            input.step,
            input.field,
            input.series_bounds,
            input.series_range,
        )?;
        self.uploaded = Some(Uploaded {
            step: input.step.clone(),
            field: input.field.clone(),
            cluster: input.cluster,
            series_range: input.series_range,
            series_bounds: input.series_bounds,
            precision: input.precision,
        });
        self.prepared = Some(Prepared::Sorted(particles));
        // Nothing moves to a device: preparing is the whole upload.
        self.timings.prepare = started.elapsed();
        self.timings.upload = std::time::Duration::ZERO;
        Ok(())
    }

    fn build(&mut self) -> Result<(), BackendError> {
        let started = Instant::now();
        self.build_structure()?;
        self.timings.build = started.elapsed();
        Ok(())
    }

    fn refit(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let started = Instant::now();
        self.apply_field(field)?;
        // The structure follows the radii: the cells are made again (their levels and widths
        // follow the radii), and the precision decided again.
        self.build_structure()?;
        self.timings.refit = started.elapsed();
        Ok(())
    }

    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        self.apply_field(field)?;
        // The cells hold copies of the weights and theta the maps gave.
        match &mut self.prepared {
            Some(Prepared::Cells(particles, cells)) => *cells = F32Field::new(particles),
            Some(Prepared::Reference(field)) => field.values_changed(),
            _ => {}
        }
        Ok(())
    }

    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let out = match self.sampler()? {
            Sampler::F64(field) => points
                .par_iter()
                .map_init(CellRuns::default, |scratch, &x| {
                    field.eval_sums_with(x, scratch)
                })
                .collect(),
            Sampler::F32(field) => {
                let mut out = vec![(0.0, [0.0; 3]); points.len()];
                // Consecutive points a task (queries come in Hilbert order): those close
                // together are evaluated in groups.
                out.par_chunks_mut(QUERY_CHUNK)
                    .zip(points.par_chunks(QUERY_CHUNK))
                    .for_each_init(F32Batch::default, |scratch, (out, points)| {
                        field.eval_sums_many(points, scratch, out);
                    });
                out
            }
        };
        self.timings.query = started.elapsed();
        Ok(out)
    }

    fn query_grid(
        &mut self,
        grid: &crate::field::RegularGrid,
    ) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let out = self.prepared()?.particles().eval_grid_sums(grid);
        self.timings.query = started.elapsed();
        Ok(out)
    }

    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let abandoned = || self.abandoned();
        let tiles = match self.sampler()? {
            Sampler::F64(field) => render_tiles(frame, field, &abandoned),
            Sampler::F32(field) => render_tiles(frame, field, &abandoned),
        };
        self.accumulate_tiles(frame, tiles)?;
        self.timings.frame = started.elapsed();
        Ok(())
    }

    fn render_owned(
        &mut self,
        frame: &FrameParams,
        share: &BrickShare<'_>,
    ) -> Result<Vec<[f64; 4]>, BackendError> {
        let started = Instant::now();
        let pixels = match self.sampler()? {
            Sampler::F64(field) => owned::render_rect(frame, field, share),
            Sampler::F32(field) => owned::render_rect(frame, field, share),
        };
        self.timings.frame = started.elapsed();
        Ok(pixels)
    }

    fn owned_depth(
        &mut self,
        frame: &FrameParams,
        owned: &HalfOpenBox,
        rays: DepthRays<'_>,
    ) -> Result<Vec<f64>, BackendError> {
        Ok(match self.sampler()? {
            Sampler::F64(field) => owned::depth_rect(frame, field, owned, rays),
            Sampler::F32(field) => owned::depth_rect(frame, field, owned, rays),
        })
    }

    /// The splatter collects its hits through the f64 reference's cluster BVH: a scene
    /// prepared in f32 cells gets the reference first, and the reference its BVH (timed as a
    /// build), and keeps them.
    fn render_splat(
        &mut self,
        frame: &FrameParams,
        k: usize,
    ) -> Result<Option<SplatCounts>, BackendError> {
        let started = Instant::now();
        let mut built = false;
        if let Some(Prepared::Cells(..)) = &self.prepared {
            let (Some(up), Some(prepared)) = (&self.uploaded, self.prepared.take()) else {
                unreachable!("checked above")
            };
            self.prepared = Some(Prepared::Reference(ReferenceField::new(
                prepared.into_particles(),
                up.cluster,
            )));
            built = true;
        }
        if let Some(Prepared::Reference(field)) = &self.prepared {
            built |= field.build_clusters();
        }
        if built {
            self.timings.build = started.elapsed();
        }
        let started = Instant::now();
        let Prepared::Reference(field) = self.prepared()? else {
            return Err(BackendError::NothingUploaded("cpu"));
        };
        let (kept, lost) = (AtomicU64::new(0), AtomicU64::new(0));
        let abandoned = || self.abandoned();
        let tiles = pixels_of(frame, &abandoned, |scratch: &mut SplatScratch, x, y| {
            let (pixel, counts) = splat::splat_pixel(frame, field, x, y, k, scratch);
            kept.fetch_add(counts.kept, Ordering::Relaxed);
            lost.fetch_add(counts.lost, Ordering::Relaxed);
            pixel
        });
        self.accumulate_tiles(frame, tiles)?;
        self.timings.frame = started.elapsed();
        Ok(Some(SplatCounts {
            kept: kept.into_inner(),
            lost: lost.into_inner(),
        }))
    }

    /// Scatters each particle onto the cell centres it reaches, in f64, slab by slab
    /// ([`Particles::eval_grid_sums`]), the sums rounded to f32.
    fn voxelize(&mut self, frame: &FrameParams, n: usize) -> Result<(), BackendError> {
        let started = Instant::now();
        let geometry = VoxelGeometry::new("cpu", frame.box_min, frame.box_max, n)?;
        let particles = self.prepared()?.particles();
        let grid = VoxelGrid::splat_with(geometry, |slab| Ok(particles.eval_grid_sums(slab)))?;
        self.voxels = Some(grid);
        self.timings.voxelize = started.elapsed();
        Ok(())
    }

    fn render_voxels(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let grid = self
            .voxels
            .as_ref()
            .ok_or(BackendError::NoVoxelGrid("cpu"))?;
        let abandoned = || self.abandoned();
        let tiles = render_tiles(frame, grid, &abandoned);
        self.accumulate_tiles(frame, tiles)?;
        self.timings.frame = started.elapsed();
        Ok(())
    }

    fn voxel_grid(&mut self) -> Result<VoxelGrid, BackendError> {
        self.voxels.clone().ok_or(BackendError::NoVoxelGrid("cpu"))
    }

    fn reset(&mut self) {
        if let Some(a) = &mut self.accumulator {
            a.reset();
        }
    }

    fn set_abandon_flag(&mut self, flag: Option<Arc<AtomicBool>>) {
        self.abandon = flag;
    }

    fn image(&mut self) -> Result<Image, BackendError> {
        self.accumulator
            .as_ref()
            .map(Accumulator::image)
            .ok_or(BackendError::NothingUploaded("cpu"))
    }

    fn timings(&self) -> Timings {
        self.timings
    }

    fn representation(&self) -> Option<Representation> {
        self.uploaded.as_ref().and(self.representation)
    }

    fn memory(&self) -> MemoryReport {
        let particle_bytes = self.prepared.as_ref().map_or(0, |prepared| {
            let p = prepared.particles();
            p.len() * (24 + 8 + 8 + 4)
                + match &p.theta {
                    crate::field::Theta::None => 0,
                    crate::field::Theta::Scalar(v) => v.len() * 8,
                    crate::field::Theta::Rgb(v) => v.len() * 24,
                }
        });
        let (packed_bytes, structure_bytes) = match &self.prepared {
            Some(Prepared::Reference(f)) => (0, f.structure_bytes()),
            Some(Prepared::Cells(_, cells)) => (cells.particle_bytes(), cells.grid_bytes()),
            _ => (0, 0),
        };
        MemoryReport {
            particle_bytes: particle_bytes + packed_bytes,
            structure_bytes,
            image_bytes: self.accumulator.as_ref().map_or(0, Accumulator::bytes),
            preparation_bytes: 0,
            voxel_bytes: self.voxels.as_ref().map_or(0, VoxelGrid::bytes),
        }
    }
}
