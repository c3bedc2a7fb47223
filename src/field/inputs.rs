//! The one check of a field's inputs against a step, used by every backend on upload, refit
//! and map updates, so every backend refuses the same input with the same message.

use rayon::prelude::*;

use super::{FieldError, FieldSettings, PerParticle};
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
    /// An SPH kernel's per-particle volumes `m/ρ`; `None` for the Gaussian RBF.
    pub volume: Option<Volume<'a>>,
}

/// Where an SPH kernel's particle volumes `m_i / ρ_i` come from, checked: every mass finite
/// and >= 0, every density finite and > 0.
#[derive(Clone, Copy)]
pub struct Volume<'a> {
    pub mass: Values<'a>,
    pub density: Values<'a>,
}

/// A checked per-particle quantity: one for all, or an attribute.
#[derive(Clone, Copy)]
pub enum Values<'a> {
    Constant(f64),
    Attribute(&'a Attribute),
}

impl Values<'_> {
    #[inline]
    fn at(&self, i: usize) -> f64 {
        match self {
            Values::Constant(v) => *v,
            Values::Attribute(a) => a.values[i],
        }
    }
}

impl Volume<'_> {
    /// Particle i's volume `m_i / ρ_i`.
    #[inline]
    pub fn of(&self, i: usize) -> f64 {
        self.mass.at(i) / self.density.at(i)
    }
}

impl FieldInputs<'_> {
    /// Particle i's volume (1 without an SPH kernel, where nothing reads it).
    #[inline]
    pub fn volume(&self, i: usize) -> f64 {
        self.volume.as_ref().map_or(1.0, |v| v.of(i))
    }
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

        let volume = if settings.kernel.is_sph() {
            Some(Self::check_volume(step, settings, &lookup)?)
        } else {
            None
        };
        let inputs = FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
            volume,
        };
        inputs.warn_if_meaningless(step, settings);
        Ok(inputs)
    }

    /// An SPH kernel's masses and densities: present, finite, masses >= 0 and densities > 0.
    fn check_volume(
        step: &'a Step,
        settings: &FieldSettings,
        lookup: &dyn Fn(&str) -> Result<&'a Attribute, FieldError>,
    ) -> Result<Volume<'a>, FieldError> {
        let kernel = settings.kernel;
        let checked = |given: Option<&PerParticle>,
                       what: &'static str,
                       ok: fn(f64) -> bool,
                       need: &'static str|
         -> Result<Values<'a>, FieldError> {
            let bad = |name: &str, value: f64, index: usize| FieldError::BadVolume {
                step: step.name.clone(),
                what,
                name: name.to_owned(),
                value,
                index,
                need,
            };
            match given.ok_or(FieldError::SphNeedsVolume { kernel, what })? {
                PerParticle::Constant(v) if ok(*v) => Ok(Values::Constant(*v)),
                PerParticle::Constant(v) => Err(bad("the value given", *v, 0)),
                PerParticle::Attribute(name) => {
                    let a = lookup(name)?;
                    match a.values.par_iter().position_first(|&v| !ok(v)) {
                        Some(index) => Err(bad(&a.name, a.values[index], index)),
                        None => Ok(Values::Attribute(a)),
                    }
                }
            }
        };
        Ok(Volume {
            mass: checked(
                settings.mass.as_ref(),
                "mass",
                |v| v.is_finite() && v >= 0.0,
                "masses >= 0",
            )?,
            density: checked(
                settings.density.as_ref(),
                "density",
                |v| v.is_finite() && v > 0.0,
                "densities > 0",
            )?,
        })
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
