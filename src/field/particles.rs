//! A step's particles prepared for the f64 reference field: Hilbert-sorted, with radius,
//! weight and theta evaluated once per particle, through the maps' baked tables (the one
//! definition of a map every backend uses).

use glam::DVec3;
use rayon::prelude::*;

use super::{Classification, FieldError, FieldInputs, FieldSettings, normalise};
use crate::accel::hilbert_order;
use crate::values::tables::{lookup, lookup_colour};
use crate::values::{Bounds, Kernel, Step};

/// Per-particle values theta_i.
#[derive(Clone, Debug, PartialEq)]
pub enum Theta {
    /// Density only: no attribute is carried.
    None,
    /// Post-classification: t_i (normalised attribute).
    Scalar(Vec<f64>),
    /// Pre-classification: linear-light C(t_i).
    Rgb(Vec<[f64; 3]>),
}

/// The particles of one step, prepared for the field: Hilbert-sorted, with radius, weight and
/// theta evaluated once per particle, and centres relative to a local origin (the series'
/// centre), subtracted in f64 once: far from the data's origin, distances then keep the
/// digits that the subtraction of two large coordinates per query would lose.
#[derive(Clone, Debug)]
pub struct Particles {
    /// Data coordinates are `origin + centers[i]`.
    pub origin: DVec3,
    /// Particle centres relative to `origin` (local coordinates), in Hilbert order.
    pub centers: Vec<DVec3>,
    /// Radii r_i = R · m(t_i) · h_i in data units (0: the particle reaches nothing); empty
    /// before a field is applied.
    pub radii: Vec<f64>,
    /// Weights: the density map's w(t_i), times the normalisation and the volume m/ρ for an
    /// SPH kernel; empty before a field is applied.
    pub weights: Vec<f64>,
    /// theta_i per particle: none, t_i (post-classification) or linear-light colour (pre).
    pub theta: Theta,
    /// The attribute range t is normalised over (`lo == hi` for a constant attribute, where
    /// every t is 0.5).
    pub range: (f64, f64),
    /// `order[k]` is the step's index of sorted particle k.
    pub order: Vec<u32>,
    /// The kernel the weights were computed for (each term is `weights[i]` times its
    /// profile).
    pub kernel: Kernel,
}

/// A field's maps baked into the tables every backend looks them up in (`values::tables`):
/// the maps as the field means them (a control point between the table's samples is rounded
/// onto them; [`crate::scene::maps::PiecewiseLinear::table_error`] says by how much).
#[derive(Clone, Debug, PartialEq)]
pub struct FieldTables {
    /// The density map w(t), one sample per table entry.
    pub density: Vec<f32>,
    /// The radius map m(t), one sample per table entry.
    pub radius: Vec<f32>,
    /// The colour map as linear-light RGB, one sample per table entry.
    pub colour: Vec<[f32; 3]>,
}

impl FieldTables {
    /// The tables of `settings`' density, radius and colour maps.
    pub fn of(settings: &FieldSettings) -> FieldTables {
        FieldTables {
            density: settings.density_map.0.bake(),
            radius: settings.radius_map.0.bake(),
            colour: settings.color_map.bake(),
        }
    }
}

/// The radius rule (method.md §1), in any precision: `R · m · h`, with `m` the radius map at
/// the particle's t and `h` its radius attribute, if the scene has one. A particle of radius 0
/// is left out of the structure. `rbf.glsl`'s `particle_radius` is the GPU's (f32) form.
#[inline]
pub fn particle_radius<F: num_traits::Float>(global: F, m: F, h: Option<F>) -> F {
    let r = global * m;
    match h {
        Some(h) => r * h,
        None => r,
    }
}

impl Particles {
    /// Prepares `step` under `settings`. `series_bounds` fixes the Hilbert grid and
    /// `series_range` the attribute's range (both over the whole series).
    pub fn prepare(
        step: &Step,
        settings: &FieldSettings,
        series_bounds: Bounds,
        series_range: Option<(f64, f64)>,
    ) -> Result<Particles, FieldError> {
        // Checked before the sort, so bad input costs no work.
        FieldInputs::check(step, settings, series_range)?;
        let mut particles = Particles::sorted(step, series_bounds);
        particles.apply_field(step, settings, series_range)?;
        Ok(particles)
    }

    /// The step's particles in Hilbert order, in local coordinates, before any field is
    /// applied (radius 0, weight 0, no theta).
    pub fn sorted(step: &Step, series_bounds: Bounds) -> Particles {
        let order = hilbert_order(&step.positions, series_bounds);
        let origin = series_bounds.center();
        let centers = order
            .par_iter()
            .map(|&i| step.positions[i as usize] - origin)
            .collect();
        Particles {
            origin,
            centers,
            radii: Vec::new(),
            weights: Vec::new(),
            theta: Theta::None,
            range: (0.0, 0.0),
            order,
            kernel: Kernel::GaussianRbf,
        }
    }

    /// Evaluates radius, weight and theta per particle under `settings` (the order and the
    /// centres stay: a map or radius change never sorts again). `step` is the step these
    /// particles were sorted from. On an error nothing changes.
    pub fn apply_field(
        &mut self,
        step: &Step,
        settings: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<(), FieldError> {
        let inputs = FieldInputs::check(step, settings, series_range)?;
        let FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
            ..
        } = inputs;
        let kernel = settings.kernel;
        let tables = FieldTables::of(settings);
        let order = &self.order;
        // One pass over the sorted particles reads each one's attribute and radius once (the
        // reads go through `order`, so they are the cost) and writes radius, weight and theta
        // together, into the buffers of the last call.
        let evaluate = |i: u32| {
            let i = i as usize;
            let t = attribute.map_or(0.5, |a| normalise(a.values[i], range));
            let r = particle_radius(
                settings.radius,
                lookup(&tables.radius, t),
                per_particle_radius.map(|h| h.values[i]),
            );
            // An SPH kernel's normalisation and the particle's volume (1 for the Gaussian).
            let w = lookup(&tables.density, t) * kernel.weight_factor(r, inputs.volume(i));
            (t, (r, w))
        };
        let n = order.len();
        // Sized once and overwritten in place (a step of the same size allocates nothing).
        self.radii.resize(n, 0.0);
        self.weights.resize(n, 0.0);
        let (radii, weights) = (&mut self.radii[..], &mut self.weights[..]);
        let old_theta = std::mem::replace(&mut self.theta, Theta::None);
        self.theta = match (attribute, settings.classification) {
            (None, _) => {
                (order, radii, weights)
                    .into_par_iter()
                    .for_each(|(&i, r, w)| (_, (*r, *w)) = evaluate(i));
                Theta::None
            }
            (Some(_), Classification::Post) => {
                let mut t = match old_theta {
                    Theta::Scalar(v) => v,
                    _ => Vec::new(),
                };
                t.resize(n, 0.0);
                (order, radii, weights, &mut t[..])
                    .into_par_iter()
                    .for_each(|(&i, r, w, t)| (*t, (*r, *w)) = evaluate(i));
                Theta::Scalar(t)
            }
            (Some(_), Classification::Pre) => {
                let mut c = match old_theta {
                    Theta::Rgb(v) => v,
                    _ => Vec::new(),
                };
                c.resize(n, [0.0; 3]);
                (order, radii, weights, &mut c[..])
                    .into_par_iter()
                    .for_each(|(&i, r, w, c)| {
                        let t;
                        (t, (*r, *w)) = evaluate(i);
                        *c = lookup_colour(&tables.colour, t);
                    });
                Theta::Rgb(c)
            }
        };
        self.range = range;
        self.kernel = kernel;
        Ok(())
    }

    /// The number of particles.
    pub fn len(&self) -> usize {
        self.centers.len()
    }

    /// Whether the step has no particles.
    pub fn is_empty(&self) -> bool {
        self.centers.is_empty()
    }
}
