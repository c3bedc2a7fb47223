//! Periodic boxes: the field of a box whose faces wrap (a cosmological volume), by ghost
//! images. Each particle is first wrapped into the box (codes write some slightly outside);
//! then every particle within its reach of a face gets an image on the far side of the box,
//! one per face, edge and corner it is near (up to 7). The images are appended to the step
//! before any backend sees it, so every backend (cpu, wgpu, ash) evaluates the periodic field
//! with no change of its own: inside the box, the field is the sum over the particles and all
//! their periodic images (the 26 neighbouring copies of the box), exactly.
//!
//! A particle whose reach is half the box's side or more would meet its own image (it would
//! be summed twice at some points, which no SPH code does): that is an error, naming the
//! particle, its reach and the box, rather than an image that silently differs from the
//! simulation's.

use glam::DVec3;
use rayon::prelude::*;

use super::{FieldError, FieldSettings, particle_reaches};
use crate::values::{Attribute, Bounds, Step};

/// Why a periodic box cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum PeriodicError {
    /// A side of the box is not positive and finite (the sides given).
    #[error(
        "the periodic box must have positive finite sides, got {} x {} x {}",
        .0[0], .0[1], .0[2]
    )]
    BadBox([f64; 3]),
    /// A particle reaches half the box's side or more, so it would meet its own image.
    #[error(
        "step '{step}': particle {index} reaches {reach} (its radius), but the periodic box's \
         {axis} side is {side}: a particle must reach less than half the box, or it would meet \
         its own periodic image. Pass a smaller --radius, or --no-periodic for an open box"
    )]
    ReachTooLarge {
        /// The step's name (its file's, or a `.particles` header's step name).
        step: String,
        /// The particle's index in the step.
        index: usize,
        /// Its reach (its radius), in data units.
        reach: f64,
        /// The axis whose side it reaches half of: 'x', 'y' or 'z'.
        axis: char,
        /// That side of the box, in data units.
        side: f64,
    },
}

/// A box `[min, min + size)` whose opposite faces are one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodicBox {
    /// The lower corner, in data coordinates.
    pub min: DVec3,
    /// The sides along x, y and z, in data units (each positive).
    pub size: DVec3,
}

/// A step with its periodic images: the particles wrapped into the box, then the images.
#[derive(Clone, Debug)]
pub struct Images {
    /// The wrapped particles (the first [`Images::originals`]) and their images after them,
    /// each image carrying its particle's attributes.
    pub step: std::sync::Arc<Step>,
    /// The particles of the step itself, at the front of `step`; the images are the rest.
    pub originals: usize,
    /// The largest reach of any particle: the images lie within it of the box.
    pub largest_reach: f64,
    /// Particles that lay outside the box and were wrapped into it.
    pub wrapped: usize,
}

impl PeriodicBox {
    /// The box `[min, min + size)`: every side positive and finite.
    pub fn new(min: DVec3, size: DVec3) -> Result<PeriodicBox, PeriodicError> {
        if !(min.is_finite() && size.is_finite() && size.cmpgt(DVec3::ZERO).all()) {
            return Err(PeriodicError::BadBox(size.to_array()));
        }
        Ok(PeriodicBox { min, size })
    }

    /// The box `[0, size)`, as simulation codes' `BoxSize` means it.
    pub fn from_origin(size: [f64; 3]) -> Result<PeriodicBox, PeriodicError> {
        PeriodicBox::new(DVec3::ZERO, DVec3::from_array(size))
    }

    /// The box as bounds: the domain a slice, a grid or a render of the periodic field covers.
    pub fn bounds(&self) -> Bounds {
        Bounds {
            min: self.min,
            max: self.min + self.size,
        }
    }

    /// `p` wrapped into `[min, min + size)` on every axis.
    pub fn wrap(&self, p: DVec3) -> DVec3 {
        let mut x = (p - self.min).rem_euclid(self.size);
        // rem_euclid of a tiny negative number rounds up to `size` itself.
        for a in 0..3 {
            if x[a] >= self.size[a] {
                x[a] = 0.0;
            }
        }
        self.min + x
    }

    /// Whether `p` lies in `[min, min + size)`.
    pub fn contains(&self, p: DVec3) -> bool {
        let x = p - self.min;
        x.cmpge(DVec3::ZERO).all() && x.cmplt(self.size).all()
    }

    /// `step` wrapped into the box, with an image of every particle within its reach of a face
    /// on the far side of the box (and of each edge and corner it is near), so that the field
    /// at any point of the closed box `[min, min + size]` is the periodic field. `step` is not
    /// modified. A particle that reaches half the box's side or more is an error.
    pub fn images(
        &self,
        step: &Step,
        settings: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<Images, FieldError> {
        let reaches = particle_reaches(step, settings, series_range)?;
        let half = self.size * 0.5;
        if let Some((index, &reach)) = reaches
            .iter()
            .enumerate()
            .find(|(_, r)| DVec3::splat(**r).cmpge(half).any())
        {
            let a = (0..3).find(|&a| reach >= half[a]).unwrap_or(0);
            return Err(PeriodicError::ReachTooLarge {
                step: step.name.clone(),
                index,
                reach,
                axis: ['x', 'y', 'z'][a],
                side: self.size[a],
            }
            .into());
        }
        let positions: Vec<DVec3> = step.positions.par_iter().map(|&p| self.wrap(p)).collect();
        let wrapped = step
            .positions
            .par_iter()
            .filter(|&&p| !self.contains(p))
            .count();
        // Each image as (its particle, its position). A particle with reach r is felt in the
        // box through its image shifted by +size on an axis where it lies within r of the low
        // face, by -size where within r of the high face (never both: r < size / 2); an edge
        // or corner image shifts on two or three axes.
        let images: Vec<(u32, DVec3)> = positions
            .par_iter()
            .zip(&reaches)
            .enumerate()
            .flat_map_iter(|(i, (&p, &r))| {
                let mut shifts = [[0.0; 2]; 3];
                let mut counts = [1usize; 3];
                if r > 0.0 {
                    for a in 0..3 {
                        let from_low = p[a] - self.min[a];
                        let from_high = self.min[a] + self.size[a] - p[a];
                        if from_low <= r {
                            shifts[a][1] = self.size[a];
                            counts[a] = 2;
                        } else if from_high <= r {
                            shifts[a][1] = -self.size[a];
                            counts[a] = 2;
                        }
                    }
                }
                let mut out = Vec::new();
                for x in 0..counts[0] {
                    for y in 0..counts[1] {
                        for z in 0..counts[2] {
                            if x + y + z > 0 {
                                let shift = DVec3::new(shifts[0][x], shifts[1][y], shifts[2][z]);
                                out.push((i as u32, p + shift));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        let mut all = positions;
        all.reserve(images.len());
        all.extend(images.iter().map(|(_, p)| *p));
        let attributes = step
            .attributes
            .iter()
            .map(|a| {
                let mut values = Vec::with_capacity(all.len());
                values.extend_from_slice(&a.values);
                values.extend(images.iter().map(|(i, _)| a.values[*i as usize]));
                Attribute {
                    name: a.name.clone(),
                    values,
                }
            })
            .collect();
        Ok(Images {
            step: std::sync::Arc::new(Step {
                name: step.name.clone(),
                positions: all,
                attributes,
            }),
            originals: step.len(),
            largest_reach: reaches.into_iter().fold(0.0, f64::max),
            wrapped,
        })
    }
}
