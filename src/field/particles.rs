//! A step's particles prepared for the f64 reference field: Hilbert-sorted, with radius,
//! weight and theta evaluated once per particle, through the maps' baked tables (the one
//! definition of a map every backend uses).

use glam::DVec3;
use rayon::prelude::*;

use super::{Classification, FieldError, FieldInputs, FieldSettings, normalise};
use crate::accel::hilbert_order;
use crate::values::tables::{lookup, lookup_colour};
use crate::values::{Bounds, Step};

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
    pub centers: Vec<DVec3>,
    pub radii: Vec<f64>,
    pub weights: Vec<f64>,
    pub theta: Theta,
    /// The attribute range t is normalised over (`lo == hi` for a constant attribute, where
    /// every t is 0.5).
    pub range: (f64, f64),
    /// `order[k]` is the step's index of sorted particle k.
    pub order: Vec<u32>,
}

/// A field's maps baked into the tables every backend looks them up in (`values::tables`):
/// the maps as the field means them (a control point between the table's samples is rounded
/// onto them; [`crate::scene::maps::PiecewiseLinear::table_error`] says by how much).
#[derive(Clone, Debug, PartialEq)]
pub struct FieldTables {
    pub density: Vec<f32>,
    pub radius: Vec<f32>,
    pub colour: Vec<[f32; 3]>,
}

impl FieldTables {
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
        let FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
        } = FieldInputs::check(step, settings, series_range)?;
        let tables = FieldTables::of(settings);
        let order = hilbert_order(&step.positions, series_bounds);
        let t_of = |i: usize| attribute.map_or(0.5, |a| normalise(a.values[i], range));
        let origin = series_bounds.center();
        let centers = order
            .par_iter()
            .map(|&i| step.positions[i as usize] - origin)
            .collect();
        let radii: Vec<f64> = order
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                particle_radius(
                    settings.radius,
                    lookup(&tables.radius, t_of(i)),
                    per_particle_radius.map(|h| h.values[i]),
                )
            })
            .collect();
        let weights = order
            .par_iter()
            .map(|&i| lookup(&tables.density, t_of(i as usize)))
            .collect();
        let theta = match (attribute, settings.classification) {
            (None, _) => Theta::None,
            (Some(_), Classification::Post) => {
                Theta::Scalar(order.par_iter().map(|&i| t_of(i as usize)).collect())
            }
            (Some(_), Classification::Pre) => Theta::Rgb(
                order
                    .par_iter()
                    .map(|&i| lookup_colour(&tables.colour, t_of(i as usize)))
                    .collect(),
            ),
        };
        Ok(Particles {
            origin,
            centers,
            radii,
            weights,
            theta,
            range,
            order,
        })
    }

    pub fn len(&self) -> usize {
        self.centers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.centers.is_empty()
    }
}
