//! How far each particle reaches: the distance beyond which it adds nothing to the field.
//! Under the paper's truncated Gaussian (method.md §2) that is the particle's radius, the
//! radius rule [`particle_radius`] evaluated as every backend evaluates it (through the maps'
//! baked tables). An SPH kernel's support is its radius too (`R = support` in units of h,
//! `values::Kernel`), so it needs nothing more here; this is the one place that says how far a
//! particle is felt: the periodic images ([`super::periodic`]) and anything else that needs to
//! know how far a particle is felt go through these functions.

use rayon::prelude::*;

use super::{FieldError, FieldInputs, FieldSettings, FieldTables, normalise, particle_radius};
use crate::values::Step;
use crate::values::tables::lookup;

/// The reach of each particle of `step` under `settings`, in the step's order: 0 for a
/// particle the radius map or its radius attribute switches off. `series_range` is the
/// attribute's range over the series, as for [`super::Particles::prepare`].
pub fn particle_reaches(
    step: &Step,
    settings: &FieldSettings,
    series_range: Option<(f64, f64)>,
) -> Result<Vec<f64>, FieldError> {
    let FieldInputs {
        attribute,
        radius,
        range,
        ..
    } = FieldInputs::check(step, settings, series_range)?;
    let table = FieldTables::of(settings).radius;
    Ok((0..step.len())
        .into_par_iter()
        .map(|i| {
            let t = attribute.map_or(0.5, |a| normalise(a.values[i], range));
            particle_radius(
                settings.radius,
                lookup(&table, t),
                radius.map(|h| h.values[i]),
            )
        })
        .collect())
}

impl FieldSettings {
    /// The largest reach of any particle of `step` (0 for an empty step).
    pub fn largest_reach(
        &self,
        step: &Step,
        series_range: Option<(f64, f64)>,
    ) -> Result<f64, FieldError> {
        Ok(particle_reaches(step, self, series_range)?
            .into_iter()
            .fold(0.0, f64::max))
    }
}
