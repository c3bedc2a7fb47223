//! The attributes the field asks the data for: its colour, the per-particle radius, and an
//! SPH kernel's masses and densities, from the flags over the scene file, and from the data's
//! names where a default needs them.

use super::DataReads;
use super::args::{DataArgs, FieldOptions};
use super::first_step::FirstStep;
use super::first_step::SMOOTHING_LENGTH_NAMES;
use super::source::Source;
use crate::field::{Kernel, PerParticle};
use crate::scene::smoothing::Smoothing;
use crate::scene_file::SceneFile;

/// What the field asks of the data, before the series opens.
pub(super) struct Wanted {
    /// The attribute the field carries (its colour), if any.
    pub attribute: Option<String>,
    pub radius_attribute: Option<String>,
    pub kernel: Kernel,
    /// An SPH kernel's masses and densities (`None` for the Gaussian RBF).
    pub mass: Option<PerParticle>,
    pub density: Option<PerParticle>,
    pub smoothing: Option<Smoothing>,
}

impl Wanted {
    /// The attributes the masses and the densities are read from (none where either is one
    /// value for every particle).
    pub(super) fn mass_and_density_attributes(&self) -> (Option<String>, Option<String>) {
        let attribute_of = |q: &Option<PerParticle>| match q {
            Some(PerParticle::Attribute(name)) => Some(name.clone()),
            _ => None,
        };
        (attribute_of(&self.mass), attribute_of(&self.density))
    }
}

/// The attributes the field asks for, with the data's first step whole where a default needed
/// it read (the first attribute for an image's colour, an SPH kernel's smoothing length, mass
/// or density found by name).
pub(super) fn choose(
    source: &Source,
    scene: &SceneFile,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
    reads: &dyn DataReads,
) -> anyhow::Result<(Wanted, Option<FirstStep>)> {
    let mut attribute = options.attribute.clone().or(scene.data.attribute.clone());
    // The first step with every attribute it holds, read where a default needs it.
    let mut first: Option<FirstStep> = None;
    if attribute.is_none() && first_attribute_by_default {
        first = source.first_step(reads)?;
        attribute = first_attribute(first.as_ref());
    }
    let smoothing = data.smoothing.or(scene.data.smoothing);
    let radius_attribute = options
        .radius_attribute
        .clone()
        .or(scene.data.radius_attribute.clone())
        .or(smoothing.map(|s| s.attribute()));
    let kernel = options.kernel.or(scene.field.kernel).unwrap_or_default();
    let (radius_attribute, mass, density) = if kernel.is_sph() {
        let mass = options.mass.clone().or(scene.field.mass.clone());
        let density = options.density.clone().or(scene.field.density.clone());
        if first.is_none() && (radius_attribute.is_none() || mass.is_none() || density.is_none()) {
            first = source.first_step(reads)?;
        }
        let sph = crate::scene_file::kernel::resolve(
            kernel,
            radius_attribute,
            mass,
            density,
            &first.as_ref().map(FirstStep::names).unwrap_or_default(),
            &SMOOTHING_LENGTH_NAMES,
            options.radius.or(scene.field.radius).is_some(),
        )?;
        (sph.radius_attribute, Some(sph.mass), Some(sph.density))
    } else {
        (radius_attribute, None, None)
    };
    let wanted = Wanted {
        attribute,
        radius_attribute,
        kernel,
        mass,
        density,
        smoothing,
    };
    Ok((wanted, first))
}

/// The data's first attribute, the colour of an image given none, said with the others.
fn first_attribute(first: Option<&FirstStep>) -> Option<String> {
    let names = first.map(FirstStep::names).unwrap_or_default();
    let attribute = names.first().cloned();
    match &attribute {
        Some(first) => tracing::info!(
            "colour: '{first}', the data's first attribute (no --attribute given); the \
             others: {} (--attribute NAME picks one, --color-by-density colours by \
             density)",
            if names.len() > 1 {
                names[1..].join(", ")
            } else {
                "none".to_owned()
            }
        ),
        None => tracing::info!("colour: by density (the data has no attributes)"),
    }
    attribute
}
