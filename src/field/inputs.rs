//! The one check of a field's inputs against a step, used by every backend on upload, refit
//! and map updates, so every backend refuses the same input with the same message.

use rayon::prelude::*;

use super::{FieldError, FieldSettings};
use crate::values::{Attribute, Step};

/// The arrays a field reads from a step, checked against its settings: what every backend
/// needs before it prepares anything.
pub struct FieldInputs<'a> {
    /// The attribute the field carries, if any.
    pub attribute: Option<&'a Attribute>,
    /// The per-particle radius attribute, if any.
    pub radius: Option<&'a Attribute>,
    /// The range t is normalised over.
    pub range: (f64, f64),
}

impl<'a> FieldInputs<'a> {
    /// Checks `settings` against `step`: a positive finite radius, the attributes present, no
    /// negative per-particle radius, constant maps when no attribute is carried, a valid range.
    pub fn check(
        step: &'a Step,
        settings: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<FieldInputs<'a>, FieldError> {
        if !(settings.radius.is_finite() && settings.radius > 0.0) {
            return Err(FieldError::BadRadius(settings.radius));
        }
        let lookup = |name: &str| {
            step.attribute(name)
                .ok_or_else(|| FieldError::MissingAttribute {
                    step: step.name.clone(),
                    name: name.to_owned(),
                    available: step.attribute_names().join(", "),
                })
        };
        let attribute = settings.attribute.as_deref().map(lookup).transpose()?;
        let per_particle_radius = settings
            .radius_attribute
            .as_deref()
            .map(lookup)
            .transpose()?;
        if let Some(h) = per_particle_radius
            && let Some((index, &value)) = h.values.iter().enumerate().find(|(_, v)| **v < 0.0)
        {
            return Err(FieldError::NegativeRadius {
                step: step.name.clone(),
                name: h.name.clone(),
                value,
                index,
            });
        }
        if attribute.is_none() {
            if !settings.radius_map.0.is_constant() {
                return Err(FieldError::MapNeedsAttribute("radius map"));
            }
            if !settings.density_map.0.is_constant() {
                return Err(FieldError::MapNeedsAttribute("density map"));
            }
        }
        let range = match (settings.attribute_range, attribute) {
            (Some((lo, hi)), _) => {
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                    return Err(FieldError::BadRange(lo, hi));
                }
                (lo, hi)
            }
            (None, Some(a)) => series_range
                .unwrap_or_else(|| crate::values::value_range(&a.values).unwrap_or((0.0, 0.0))),
            (None, None) => (0.0, 0.0),
        };

        let inputs = FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
        };
        inputs.warn_if_meaningless(step, settings);
        Ok(inputs)
    }

    /// Warns (once per preparation, on every backend) when the settings leave this step no
    /// density anywhere, so the image is empty for a reason the user can fix.
    fn warn_if_meaningless(&self, step: &Step, settings: &FieldSettings) {
        if step.is_empty() {
            return;
        }
        let t_of = |i: usize| {
            self.attribute
                .map_or(0.5, |a| normalise(a.values[i], self.range))
        };
        let no_radius = (0..step.len()).into_par_iter().all(|i| {
            let h = self.radius.map_or(1.0, |h| h.values[i]);
            settings.radius_map.0.eval(t_of(i)) * h <= 0.0
        });
        if no_radius {
            tracing::warn!(
                "step '{}': every particle has radius 0 under the radius map{}, so the field is 0 everywhere",
                step.name,
                self.radius
                    .map(|h| format!(" and radius attribute '{}'", h.name))
                    .unwrap_or_default()
            );
        } else if (0..step.len())
            .into_par_iter()
            .all(|i| settings.density_map.0.eval(t_of(i)) <= 0.0)
        {
            tracing::warn!(
                "step '{}': the density map gives every particle weight 0, so the field is 0 everywhere",
                step.name
            );
        }
    }
}

/// Normalises s into t over `range`; a zero-width range maps everything to 0.5.
pub fn normalise(s: f64, range: (f64, f64)) -> f64 {
    let width = range.1 - range.0;
    if width > 0.0 {
        (s - range.0) / width
    } else {
        0.5
    }
}
