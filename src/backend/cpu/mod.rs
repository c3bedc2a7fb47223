//! The CPU backend: the f64 reference field (a BVH over Hilbert-sorted cluster boxes) and the
//! integrators of [`integrators`] (the twin of `shaders_glsl/shared/integrators.glsl`), rayon over image tiles. It is the reference renderer
//! GPU backends are compared with, and the fallback where no GPU driver exists. It computes in
//! f64 throughout (as fast as f32 here, and one path instead of two), and skips empty space
//! along rays with the BVH (the image is unchanged: the field there is 0).

mod accumulator;
pub mod integrators;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glam::DVec3;
use rayon::prelude::*;

use self::accumulator::Accumulator;
use self::integrators::{FieldSampler, render_pixel};
use super::{Backend, BackendError, Capabilities, MemoryReport, StepInput, Timings};
use crate::field::{FieldSettings, Particles, ReferenceField};
use crate::values::{FrameParams, Image, Step};

const TILE: u32 = 16;

/// The uploaded step (shared with the series' cache, never copied), kept to re-evaluate its
/// particles' radii and maps when those change.
struct Uploaded {
    step: Arc<Step>,
    field: FieldSettings,
    cluster: crate::accel::ClusterSize,
    series_range: Option<(f64, f64)>,
}

/// The particles, sorted once per upload, before and after the structure is built over them
/// (one of them at a time, so the size difference costs nothing).
#[allow(clippy::large_enum_variant)]
enum Prepared {
    Sorted(Particles),
    Built(ReferenceField),
}

impl Prepared {
    fn particles_mut(&mut self) -> &mut Particles {
        match self {
            Prepared::Sorted(p) => p,
            Prepared::Built(f) => &mut f.particles,
        }
    }

    fn into_particles(self) -> Particles {
        match self {
            Prepared::Sorted(p) => p,
            Prepared::Built(f) => f.particles,
        }
    }
}

pub struct CpuBackend {
    capabilities: Capabilities,
    uploaded: Option<Uploaded>,
    prepared: Option<Prepared>,
    accumulator: Option<Accumulator>,
    timings: Timings,
    abandon: Option<Arc<AtomicBool>>,
}

impl Default for CpuBackend {
    fn default() -> Self {
        Self::new()
    }
}

impl CpuBackend {
    pub fn new() -> CpuBackend {
        CpuBackend {
            capabilities: Capabilities {
                name: "cpu",
                device: format!("CPU, {} threads", rayon::current_num_threads()),
                hardware_rt: false,
                software: false,
                max_particles: None,
            },
            uploaded: None,
            prepared: None,
            accumulator: None,
            timings: Timings::default(),
            abandon: None,
        }
    }

    fn field(&self) -> Result<&ReferenceField, BackendError> {
        match &self.prepared {
            Some(Prepared::Built(f)) => Ok(f),
            _ => Err(BackendError::NothingUploaded("cpu")),
        }
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
}

impl FieldSampler for ReferenceField {
    fn sample(&self, x: DVec3) -> (f64, [f64; 3]) {
        self.eval_sums(x)
    }

    fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        self.occupied_intervals(origin, dir, t0, t1, out);
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
        });
        self.prepared = Some(Prepared::Sorted(particles));
        // Nothing moves to a device: preparing is the whole upload.
        self.timings.prepare = started.elapsed();
        self.timings.upload = std::time::Duration::ZERO;
        Ok(())
    }

    fn build(&mut self) -> Result<(), BackendError> {
        let (Some(up), Some(prepared)) = (&self.uploaded, self.prepared.take()) else {
            return Err(BackendError::NothingUploaded("cpu"));
        };
        let started = Instant::now();
        self.prepared = Some(Prepared::Built(ReferenceField::new(
            prepared.into_particles(),
            up.cluster,
        )));
        self.timings.build = started.elapsed();
        Ok(())
    }

    fn refit(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        let started = Instant::now();
        let cluster = self.apply_field(field)?.cluster;
        // Boxes change with the radii; the CPU BVH is rebuilt over them (obvhs builds in tens of
        // milliseconds per million boxes, and clusters that became empty leave the tree).
        let particles = self
            .prepared
            .take()
            .expect("applied above")
            .into_particles();
        self.prepared = Some(Prepared::Built(ReferenceField::new(particles, cluster)));
        self.timings.refit = started.elapsed();
        Ok(())
    }

    fn update_maps(&mut self, field: &FieldSettings) -> Result<(), BackendError> {
        self.apply_field(field)?;
        Ok(())
    }

    fn query(&mut self, points: &[DVec3]) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let field = self.field()?;
        let out = points.par_iter().map(|&x| field.eval_sums(x)).collect();
        self.timings.query = started.elapsed();
        Ok(out)
    }

    fn query_grid(
        &mut self,
        grid: &crate::field::RegularGrid,
    ) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let out = self.field()?.eval_grid_sums(grid);
        self.timings.query = started.elapsed();
        Ok(out)
    }

    fn render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let field = self.field()?;
        let (w, h) = (frame.width, frame.height);
        let tiles_x = w.div_ceil(TILE);
        let abandoned = || {
            self.abandon
                .as_ref()
                .is_some_and(|f| f.load(Ordering::Relaxed))
        };
        let tiles: Vec<Vec<[f64; 4]>> = (0..tiles_x * h.div_ceil(TILE))
            .into_par_iter()
            .map(|tile| {
                let (tx, ty) = (tile % tiles_x, tile / tiles_x);
                if abandoned() {
                    return Vec::new();
                }
                let mut out = Vec::with_capacity((TILE * TILE) as usize);
                for y in ty * TILE..((ty + 1) * TILE).min(h) {
                    for x in tx * TILE..((tx + 1) * TILE).min(w) {
                        out.push(render_pixel(frame, field, x, y));
                    }
                }
                out
            })
            .collect();
        // Checked once more after every tile: a tile that saw no flag may have been followed
        // by one that did; the accumulation is untouched either way.
        if abandoned() {
            return Err(BackendError::Abandoned);
        }
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
        self.timings.frame = started.elapsed();
        Ok(())
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

    fn positions(&self) -> Option<super::Positions> {
        self.uploaded.as_ref().map(|_| super::Positions::F64)
    }

    fn memory(&self) -> MemoryReport {
        let particles = match &self.prepared {
            Some(Prepared::Sorted(p)) => Some(p),
            Some(Prepared::Built(f)) => Some(&f.particles),
            None => None,
        };
        let particle_bytes = particles.map_or(0, |p| {
            p.len() * (24 + 8 + 8 + 4)
                + match &p.theta {
                    crate::field::Theta::None => 0,
                    crate::field::Theta::Scalar(v) => v.len() * 8,
                    crate::field::Theta::Rgb(v) => v.len() * 24,
                }
        });
        MemoryReport {
            particle_bytes,
            structure_bytes: self.field().map_or(0, ReferenceField::structure_bytes),
            image_bytes: self.accumulator.as_ref().map_or(0, Accumulator::bytes),
            preparation_bytes: 0,
        }
    }
}
