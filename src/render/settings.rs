//! What a user chooses about a rendering.

use crate::scene::camera::{Camera, UpAxis};
use crate::scene::maps::OpticalDensityMap;
use crate::values::frame::{Integrator, Light, NoiseKind};

/// Everything about an image except the data and the field.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// How a ray's radiance is integrated: emission–absorption or single scattering.
    pub integrator: Integrator,
    /// The noise that jitters samples: spatiotemporal blue noise or white noise.
    pub noise: NoiseKind,
    /// The noise's seed.
    pub seed: u32,
    /// `None`: a default view of the data's bounds.
    pub camera: Option<Camera>,
    /// Ray-marching step; `None`: from the radius and the mean particle spacing.
    pub step_size: Option<f64>,
    /// The density normalising Phi for colour and extinction; `None`: estimated from the data.
    pub phi_ref: Option<f64>,
    /// Extinction from normalised density: the optical-density map D over Phi / Phi_ref and
    /// its scale (`None`: 0.4 / radius).
    pub optical: OpticalDensityMap,
    /// Colour by density instead of the attribute.
    pub colour_by_density: bool,
    /// The directional light and ambient term for single scattering.
    pub light: Light,
    /// The scene's vertical, which the light's azimuth and elevation are about (kept apart
    /// from the camera's up vector, which turns as the viewer's trackball does).
    pub up_axis: UpAxis,
    /// Linear RGB behind the volume.
    pub background: [f64; 3],
    /// Ray marching stops when a pixel's opacity reaches this.
    pub opacity_threshold: f64,
    /// `Some(k)`: frames are Knoll et al.'s splatter with k hits per slab (the Table 3
    /// baseline, emission-absorption whatever `integrator` says) instead of the RBF renderer.
    pub splat_k: Option<usize>,
    /// `Some(n)`: frames march the voxel-grid baseline instead (the particles splatted into a
    /// grid with n cells along its longest side, re-voxelised whenever the accumulation
    /// restarts: a new step, field or view). At most one of `splat_k` and `voxel_grid` is set.
    pub voxel_grid: Option<usize>,
}

impl RenderSettings {
    /// The largest image side a render accepts.
    pub const MAX_SIDE: u32 = 16384;

    /// Checks what can be checked before any data or device is touched, so a bad flag is
    /// reported at once (not after opening the data and probing the GPUs).
    pub fn check(&self) -> Result<(), String> {
        let side = 1..=Self::MAX_SIDE;
        if !side.contains(&self.width) || !side.contains(&self.height) {
            return Err(format!(
                "image size {}x{} (--width, --height): each side must lie in 1..={}",
                self.width,
                self.height,
                Self::MAX_SIDE
            ));
        }
        if !(self.opacity_threshold > 0.0 && self.opacity_threshold <= 1.0) {
            return Err(format!(
                "opacity threshold {} must lie in (0, 1]",
                self.opacity_threshold
            ));
        }
        if !self.background.iter().all(|c| c.is_finite()) {
            return Err(format!(
                "background {:?} (--background): each channel must be a finite number",
                self.background
            ));
        }
        Ok(())
    }
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
            phi_ref: None,
            optical: OpticalDensityMap::default(),
            colour_by_density: false,
            light: Light::default(),
            up_axis: UpAxis::Y,
            background: [0.0; 3],
            opacity_threshold: 0.99,
            splat_k: None,
            voxel_grid: None,
        }
    }
}

/// How an image is rendered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum Method {
    /// The attribute-aware RBFs: every sample queries the particles (the paper's method).
    #[default]
    Rbf,
    /// The voxel baseline: particles splatted into a grid, the grid ray-marched.
    Voxel,
    /// Knoll et al.'s RT splatter, the other Table 3 baseline: each slab of a ray collects at
    /// most k particles, sorted and composited front to back.
    Splat,
}

/// Cells along the voxel baseline's longest side unless asked (`aarbf render --voxel-grid`,
/// the viewer): the paper's 512 is 2 GiB of sums and most of a second to voxelise on a CPU;
/// 256 keeps the grid's error near the RBF image's noise at a tenth of that.
pub const VOXEL_GRID: usize = 256;

/// Hits per slab in the splatter: 15, as the RBF paper's port of Knoll et al. (31 in their
/// book chapter).
pub const SPLAT_K: usize = 15;
