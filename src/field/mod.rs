//! The f64 reference field (method.md §2): density Phi and attribute field Theta at query
//! points, by brute force over all particles and through a grid of cells (each term computed
//! exactly as the brute-force sum does). This is the oracle every GPU stage is tested against.
//!
//! For particle i with centre c_i, attribute s_i, normalised t_i = (s_i - s_min) / (s_max -
//! s_min), radius r_i = R · m(t_i) · h_i (h_i the per-particle radius when the data has one):
//!
//! ```text
//! phi_i(x) = w(t_i) · exp(-0.5 · (3 d / r_i)^2)   for d = |x - c_i| <= r_i, else 0
//! Phi(x)   = Σ phi_i(x)
//! Theta(x) = Σ theta_i · phi_i(x) / Phi(x)       (0 where Phi is 0 or denormal)
//! ```
//! with theta_i = s_i (post-classification; reported in the attribute's own units) or the
//! linear-light colour C(t_i) (pre-classification).

pub mod f32_field;
pub mod f32_kernel;
mod f64_kernel;
mod grid;
mod inputs;
mod particles;
pub mod periodic;
mod reach;
mod reference;
pub mod splat;

use serde::{Deserialize, Serialize};

pub use f32_field::{F32Batch, F32Field, F32Packet, F32Ray};
pub use grid::RegularGrid;
pub use inputs::{FieldInputs, normalise};
pub use particles::{FieldTables, Particles, Theta, particle_radius};
pub use periodic::PeriodicBox;
pub use reach::particle_reaches;
pub use reference::{ReferenceField, Sample, finish_sums};

use crate::scene::maps::{ColorMap, DensityMap, RadiusMap};
pub use crate::values::Kernel;

/// How attribute values become colour (method.md §2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Classification {
    /// Average the attribute, then colour-map the average.
    #[default]
    Post,
    /// Colour-map each particle, then average the colours.
    Pre,
}

/// Everything that defines the field of one step.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldSettings {
    /// The attribute the field carries; `None` for density only (maps must then be constant).
    pub attribute: Option<String>,
    /// Overrides the attribute's range over the series for normalisation.
    pub attribute_range: Option<(f64, f64)>,
    /// Global radius R, in data units.
    pub radius: f64,
    /// Per-particle radius attribute h (scaled by R).
    pub radius_attribute: Option<String>,
    /// Radius map m(t) in [0, 1]: a particle's radius as a fraction of R, by its normalised
    /// attribute t (constant without an attribute).
    pub radius_map: RadiusMap,
    /// Density map w(t) >= 0: a particle's weight in the density sum, by its normalised
    /// attribute t (constant without an attribute).
    pub density_map: DensityMap,
    /// Colour map C(t): the colour of the normalised attribute (of the averaged one for
    /// post-classification, of each particle's for pre-).
    pub color_map: ColorMap,
    /// Whether the attribute is averaged then coloured (post) or coloured then averaged (pre).
    pub classification: Classification,
    /// The kernel (the paper's Gaussian RBF by default). An SPH kernel weights each term by
    /// the particle's volume `m/ρ`, from [`Self::mass`] and [`Self::density`].
    pub kernel: Kernel,
    /// The particles' mass for an SPH kernel: an attribute, or one value for all.
    pub mass: Option<PerParticle>,
    /// The particles' density ρ for an SPH kernel: an attribute, or one value for all (1 makes
    /// Phi the SPH density estimate Σ m W itself).
    pub density: Option<PerParticle>,
}

/// Where an SPH kernel takes a per-particle quantity (mass, density) from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum PerParticle {
    /// One value for every particle (a mass table's).
    Constant(f64),
    /// An attribute of the step.
    Attribute(String),
}

impl std::str::FromStr for PerParticle {
    type Err = std::convert::Infallible;

    /// A number is a constant mass; anything else names an attribute.
    fn from_str(text: &str) -> Result<PerParticle, Self::Err> {
        Ok(match text.parse::<f64>() {
            Ok(m) => PerParticle::Constant(m),
            Err(_) => PerParticle::Attribute(text.to_owned()),
        })
    }
}

impl std::fmt::Display for PerParticle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PerParticle::Constant(m) => write!(f, "{m}"),
            PerParticle::Attribute(name) => write!(f, "'{name}'"),
        }
    }
}

impl FieldSettings {
    /// A field over `attribute` with radius `radius` and default maps (w = 1, m = 1).
    pub fn new(attribute: Option<&str>, radius: f64) -> FieldSettings {
        FieldSettings {
            attribute: attribute.map(str::to_owned),
            attribute_range: None,
            radius,
            radius_attribute: None,
            radius_map: RadiusMap::default(),
            density_map: DensityMap::default(),
            color_map: ColorMap::default(),
            classification: Classification::Post,
            kernel: Kernel::GaussianRbf,
            mass: None,
            density: None,
        }
    }
}

/// Why a field cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    /// A named attribute (the field's, the radius attribute, or an SPH mass or density) is not in
    /// the step.
    #[error("step '{step}' has no attribute '{name}'; it has: {available}")]
    MissingAttribute {
        /// The step's name (its file's, or a `.particles` header's step name).
        step: String,
        /// The attribute asked for.
        name: String,
        /// The step's attribute names, comma-separated.
        available: String,
    },
    /// The global radius R is not positive and finite (the value given).
    #[error("the global radius must be a positive finite number, got {0}")]
    BadRadius(f64),
    /// A radius or density map varies with t, but no attribute gives t; which map it is
    /// ("radius map" or "density map").
    #[error("the {0} varies with the attribute, but no attribute was chosen")]
    MapNeedsAttribute(&'static str),
    /// The attribute range given is not finite and ascending (lo, hi).
    #[error("the attribute range {0}..{1} is not a finite ascending pair")]
    BadRange(f64, f64),
    /// The radius attribute holds a negative value.
    #[error(
        "step '{step}': radius attribute '{name}' holds {value} for particle {index}; radii must be >= 0"
    )]
    NegativeRadius {
        /// The step's name (its file's, or a `.particles` header's step name).
        step: String,
        /// The radius attribute's name.
        name: String,
        /// The first negative value.
        value: f64,
        /// Its particle's index in the step.
        index: usize,
    },
    /// An SPH kernel was chosen without a mass or a density to weight each particle's volume by.
    #[error(
        "the {kernel} kernel weights each particle by its volume m/rho: it needs a {what} (--mass and --density, each an attribute or one value)"
    )]
    SphNeedsVolume {
        /// The SPH kernel chosen.
        kernel: Kernel,
        /// What is missing: "mass" or "density".
        what: &'static str,
    },
    /// An SPH kernel's mass is negative or not finite, or its density is not positive and finite.
    #[error(
        "step '{step}': {what} '{name}' holds {value} for particle {index}; an SPH kernel needs {need}"
    )]
    BadVolume {
        /// The step's name (its file's, or a `.particles` header's step name).
        step: String,
        /// "mass" or "density".
        what: &'static str,
        /// The attribute's name, or "the value given" for a constant.
        name: String,
        /// The first bad value.
        value: f64,
        /// Its particle's index in the step (0 for a constant).
        index: usize,
        /// What is required: "masses >= 0" or "densities > 0".
        need: &'static str,
    },
    /// The periodic box cannot be used.
    #[error(transparent)]
    Periodic(#[from] periodic::PeriodicError),
}
