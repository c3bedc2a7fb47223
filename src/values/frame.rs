//! What one frame is, as every backend receives it: the camera's frame, the march box, the
//! lighting and the user's choices of integrator, noise and colour, with everything automatic
//! already resolved (`render::session` resolves it).

use std::sync::Arc;

use glam::DVec3;
use serde::{Deserialize, Serialize};

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
    /// Whether it computes single scattering (every integrator but emission–absorption).
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

impl NoiseKind {
    /// The name the command line and the scene file use.
    pub fn name(self) -> &'static str {
        match self {
            NoiseKind::Stbn => "stbn",
            NoiseKind::White => "white",
        }
    }
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
    /// Degrees around the scene's up axis (the render settings' `up_axis`).
    pub azimuth: f64,
    /// Degrees above the horizon.
    pub elevation: f64,
    /// The directional light's radiance (1 by default).
    pub intensity: f64,
    /// Light reaching every point regardless of shadowing (0.25 by default).
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
    /// Unit vector towards the light, with y up (azimuth 0 towards +z, 90 towards +x).
    pub fn direction(&self) -> glam::DVec3 {
        self.direction_about(DVec3::Y, DVec3::X, DVec3::Z)
    }

    /// Unit vector towards the light, the elevation measured from the plane normal to `up`
    /// and the azimuth from `front` towards `side` (a right-handed frame side, up, front).
    pub fn direction_about(&self, up: DVec3, side: DVec3, front: DVec3) -> DVec3 {
        let (a, e) = (self.azimuth.to_radians(), self.elevation.to_radians());
        e.cos() * (a.sin() * side + a.cos() * front) + e.sin() * up
    }
}

/// A camera's orthonormal frame, scaled for generating rays: a pixel at normalised device
/// coordinates (sx, sy) in [-1, 1] looks along `forward + sx * right + sy * up`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraFrame {
    /// The camera's position, data units.
    pub eye: DVec3,
    /// The unit view direction.
    pub forward: DVec3,
    /// Rightwards in the image, as long as the tangent of half the horizontal field of view.
    pub right: DVec3,
    /// Upwards in the image, as long as the tangent of half the vertical field of view.
    pub up: DVec3,
}

impl CameraFrame {
    /// The frame of the half-resolution lattice of a `width` x `height` image: in an image of
    /// [`half_lattice_size`], pixel (i, j) looks along the ray of the full image's pixel
    /// (2i, 2j). Only the basis changes (`forward` is then no longer the unit view direction;
    /// every backend normalises the ray).
    pub fn on_half_lattice(&self, width: u32, height: u32) -> CameraFrame {
        let (w, h) = (f64::from(width), f64::from(height));
        let (lw, lh) = half_lattice_size(width, height);
        let (lw, lh) = (f64::from(lw), f64::from(lh));
        // Full pixel 2i sits at sx = (4i + 1) / w - 1, lattice pixel i at (2i + 1) / lw - 1
        // (and the same downwards in y): match the terms in i and the constant ones.
        CameraFrame {
            eye: self.eye,
            forward: self.forward
                + self.right * ((2.0 * lw - 1.0) / w - 1.0)
                + self.up * (1.0 + 1.0 / h - 2.0 * lh / h),
            right: self.right * (2.0 * lw / w),
            up: self.up * (2.0 * lh / h),
        }
    }
}

/// The size of a `width` x `height` image's half-resolution lattice (every other pixel in x
/// and in y, from the first).
pub fn half_lattice_size(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(2), height.div_ceil(2))
}

/// Everything fixed for one frame.
#[derive(Clone, Debug)]
pub struct FrameParams {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The frame's index in the accumulation (the noise's time coordinate).
    pub frame: u32,
    /// The noise's seed.
    pub seed: u32,
    /// The camera's frame for generating rays.
    pub camera: CameraFrame,
    /// The march box's least corner: the domain grown by the margin.
    pub box_min: DVec3,
    /// The march box's largest corner.
    pub box_max: DVec3,
    /// The ray-marching step, data units.
    pub dt: f64,
    /// The opacity at which a ray stops, in (0, 1].
    pub opacity_threshold: f64,
    /// The density that maps to 1 for colour and extinction.
    pub phi_ref: f64,
    /// Extinction per unit optical density (per data unit).
    pub density_scale: f64,
    /// `density_scale * max D`: bounds sigma everywhere (delta tracking's majorant).
    pub majorant: f64,
    /// Unit vector towards the light, in data coordinates.
    pub light_dir: DVec3,
    /// The directional light's radiance.
    pub light_intensity: f64,
    /// Light reaching every point regardless of shadowing.
    pub ambient: f64,
    /// Linear RGB behind the volume.
    pub background: [f64; 3],
    /// How a ray's radiance is integrated.
    pub integrator: Integrator,
    /// The noise that jitters samples.
    pub noise: NoiseKind,
    /// What the colour map is applied to.
    pub colour: ColourMode,
    /// The optical-density map D baked to `TABLE_SIZE` samples over [0, 1].
    pub optical_table: Arc<Vec<f32>>,
    /// The colour map baked to `TABLE_SIZE` linear-RGB samples over [0, 1].
    pub colour_table: Arc<Vec<[f32; 3]>>,
}

impl FrameParams {
    /// The box primary and shadow rays are marched in.
    pub fn march_box(&self) -> super::Bounds {
        super::Bounds {
            min: self.box_min,
            max: self.box_max,
        }
    }

    /// This frame on its image's half-resolution lattice ([`CameraFrame::on_half_lattice`]):
    /// the same rays as the full frame's even pixels, a quarter of the work.
    pub fn on_half_lattice(self) -> FrameParams {
        let (width, height) = half_lattice_size(self.width, self.height);
        FrameParams {
            width,
            height,
            camera: self.camera.on_half_lattice(self.width, self.height),
            ..self
        }
    }
}
