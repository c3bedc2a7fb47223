//! What a user chooses about a rendering.

use serde::{Deserialize, Serialize};

use super::camera::Camera;
use crate::scene::maps::PiecewiseLinear;

/// How a pixel's light is computed.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Emission–absorption ray marching with a jittered start (paper §3.3.1).
    #[default]
    Ea,
    /// Single scattering; free-flight distance by delta tracking against a majorant.
    Delta,
    /// Single scattering; free-flight distance by stochastic ray marching with one random
    /// number (paper eqs. 6–8).
    Marching,
    /// Single scattering by deterministic marching with a shadow ray at every sample: the
    /// reference the stochastic integrators converge to.
    #[value(name = "ss-reference")]
    SsReference,
}

impl Integrator {
    pub fn scatters(self) -> bool {
        self != Integrator::Ea
    }
}

/// Where random numbers come from.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "lowercase")]
pub enum NoiseKind {
    /// Spatiotemporal blue noise (our own void-and-cluster masks).
    #[default]
    Stbn,
    /// A hash of pixel, frame, dimension and seed.
    White,
}

/// What the colour of a sample comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ColourMode {
    /// C(Theta): the averaged attribute, colour-mapped.
    Post,
    /// Theta: the average of colour-mapped particles.
    Pre,
    /// C(Phi / Phi_ref): density only; no attribute is carried.
    Density,
}

/// A directional light and an ambient term (single scattering).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Light {
    /// Degrees around the vertical (y) axis.
    pub azimuth: f64,
    /// Degrees above the horizon.
    pub elevation: f64,
    pub intensity: f64,
    pub ambient: f64,
}

impl Default for Light {
    fn default() -> Self {
        Light {
            azimuth: 45.0,
            elevation: 60.0,
            intensity: 1.0,
            ambient: 0.25,
        }
    }
}

impl Light {
    /// Unit vector towards the light.
    pub fn direction(&self) -> glam::DVec3 {
        let (a, e) = (self.azimuth.to_radians(), self.elevation.to_radians());
        glam::DVec3::new(e.cos() * a.sin(), e.sin(), e.cos() * a.cos())
    }
}

/// Everything about an image except the data and the field.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub integrator: Integrator,
    pub noise: NoiseKind,
    pub seed: u32,
    /// `None`: a default view of the data's bounds.
    pub camera: Option<Camera>,
    /// Ray-marching step; `None`: from the radius and the mean particle spacing.
    pub step_size: Option<f64>,
    /// Extinction per unit length where the optical-density map is 1; `None`: 0.3 / radius.
    pub density_scale: Option<f64>,
    /// The density normalising Phi for colour and extinction; `None`: estimated from the data.
    pub phi_ref: Option<f64>,
    /// Optical-density map D over Phi / Phi_ref in [0, 1].
    pub optical_map: PiecewiseLinear,
    /// Colour by density instead of the attribute.
    pub colour_by_density: bool,
    pub light: Light,
    pub background: [f64; 3],
    /// Ray marching stops when a pixel's opacity reaches this.
    pub opacity_threshold: f64,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 512,
            height: 512,
            integrator: Integrator::Ea,
            noise: NoiseKind::Stbn,
            seed: 1,
            camera: None,
            step_size: None,
            density_scale: None,
            phi_ref: None,
            optical_map: PiecewiseLinear::ramp(0.0, 1.0),
            colour_by_density: false,
            light: Light::default(),
            background: [0.0; 3],
            opacity_threshold: 0.99,
        }
    }
}
