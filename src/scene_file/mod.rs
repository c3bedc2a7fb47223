//! The TOML scene file: data, attribute, radius, maps (and later camera and render options)
//! in one place. Relative paths are relative to the scene file. Command-line flags override it.
//!
//! ```toml
//! [data]
//! path = "dambreak/dambreak-demo.particles"
//! step = 10
//! attribute = "velocity"
//! attribute_range = [0.0, 3.0]
//!
//! [field]
//! radius = "1.5%"            # of the series' bounding-box diagonal, or a length
//! radius_map = "0:0.5,1:1"   # or [[0.0, 0.5], [1.0, 1.0]]
//! density_map = 1.0
//! colormap = "viridis"       # a preset, or a ParaView JSON file
//! classification = "post"
//! cluster = 4
//! ```

mod kernel;
pub mod names;
pub mod periodic;
pub mod resolve;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use glam::DVec3;

use crate::accel::ClusterSize;
use crate::field::{Classification, Kernel, PerParticle};
use crate::io::{Format, ParticleType};
use crate::render::{RenderSettings, Resolved};
use crate::scene::maps::{MapError, OpticalDensityMap, PiecewiseLinear};
use crate::scene::{Camera, UpAxis};
use crate::values::Bounds;

/// Where the data comes from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DataSection {
    /// The particle file or directory (relative to the scene file).
    pub path: Option<PathBuf>,
    /// The file format; unset: from the path's extension.
    pub format: Option<Format>,
    /// The time step to show, counted from 0; unset: the first.
    pub step: Option<usize>,
    /// The attribute the field carries (colour and the maps' input); unset: the first attribute
    /// where an image needs a colour, else density only.
    pub attribute: Option<String>,
    /// `[lo, hi]`, or `"series"`, `"robust"`, `"step"`, `"robust-step"` ([`RangeSpec`]).
    pub attribute_range: Option<RangeSpec>,
    /// The attribute holding each particle's radius h (a multiple of the global radius).
    pub radius_attribute: Option<String>,
    /// An HDF5 snapshot's particle type (`gas`, `dm`, ... or 0..5).
    pub particle_type: Option<ParticleType>,
    /// An HDF5 snapshot's comoving quantities in physical units.
    pub physical: Option<bool>,
    /// Smoothing lengths from neighbours (`"knn:32"`), as `--smoothing` gives them.
    pub smoothing: Option<crate::scene::smoothing::Smoothing>,
    /// The periodic box the field wraps at: `true` (the snapshot header's), `false` (open),
    /// or `[LX, LY, LZ]` (the box [0, L)); unset, the header decides.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periodic: Option<periodic::PeriodicSetting>,
}

/// The range of the attribute the colour map spans.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RangeText", into = "RangeText")]
pub enum RangeSpec {
    /// `LO,HI`, as given.
    Fixed(f64, f64),
    /// From the least to the largest value in the series (the default).
    Series,
    /// From the lowest step's 1st percentile to the highest step's 99th: a few outliers in any
    /// step do not wash the rest into one colour.
    Robust,
    /// From the least to the largest value of the step shown (each frame of a sequence its
    /// own).
    Step,
    /// The 1st to the 99th percentile of the step shown.
    RobustStep,
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum RangeText {
    Pair([f64; 2]),
    Text(String),
}

impl TryFrom<RangeText> for RangeSpec {
    type Error = String;
    fn try_from(r: RangeText) -> Result<Self, String> {
        match r {
            RangeText::Pair([lo, hi]) => format!("{lo},{hi}").parse(),
            RangeText::Text(s) => s.parse(),
        }
    }
}

impl From<RangeSpec> for RangeText {
    fn from(r: RangeSpec) -> Self {
        match r {
            RangeSpec::Fixed(lo, hi) => RangeText::Pair([lo, hi]),
            other => RangeText::Text(other.to_string()),
        }
    }
}

impl std::str::FromStr for RangeSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Ok(match s.trim() {
            "series" => RangeSpec::Series,
            "robust" => RangeSpec::Robust,
            "step" => RangeSpec::Step,
            "robust-step" => RangeSpec::RobustStep,
            text => {
                let v: Vec<f64> = text
                    .split(',')
                    .map(|x| x.trim().parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| {
                        format!(
                            "range '{s}': expected LO,HI or one of series, robust, step, \
                             robust-step"
                        )
                    })?;
                match v[..] {
                    [lo, hi] if lo.is_finite() && hi.is_finite() && lo <= hi => {
                        RangeSpec::Fixed(lo, hi)
                    }
                    _ => return Err(format!("range '{s}' is not an ascending pair LO,HI")),
                }
            }
        })
    }
}

impl std::fmt::Display for RangeSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RangeSpec::Fixed(lo, hi) => write!(f, "{lo},{hi}"),
            RangeSpec::Series => f.write_str("series"),
            RangeSpec::Robust => f.write_str("robust"),
            RangeSpec::Step => f.write_str("step"),
            RangeSpec::RobustStep => f.write_str("robust-step"),
        }
    }
}

/// A resolved range (`None`: the series', the field's default) and what it is, in words.
pub type RangeAndMeaning = (Option<(f64, f64)>, &'static str);

impl RangeSpec {
    /// A few words for a legend.
    pub fn label(self) -> &'static str {
        match self {
            RangeSpec::Fixed(..) => "set range",
            RangeSpec::Series => "series range",
            RangeSpec::Robust => "series 1-99%",
            RangeSpec::Step => "step range",
            RangeSpec::RobustStep => "step 1-99%",
        }
    }

    /// Whether each step has its own range.
    pub fn per_step(self) -> bool {
        matches!(self, RangeSpec::Step | RangeSpec::RobustStep)
    }

    /// The range of `attribute` this spells over `series` at step `step` (`None`: the series'
    /// range, which the field takes by default), and what it is, for messages.
    pub fn resolve(
        self,
        series: &crate::scene::TimeSeries,
        attribute: Option<&str>,
        step: usize,
    ) -> Result<RangeAndMeaning, crate::io::DataError> {
        let Some(name) = attribute else {
            return Ok((None, "no attribute"));
        };
        let of_step = |robust: bool| -> Result<Option<(f64, f64)>, crate::io::DataError> {
            // The step's statistics, from the index or the scan: the same values as a read.
            if let Some(info) = series.step_info(step).filter(|i| i.scanned)
                && let Some(a) = info.attributes.iter().find(|a| a.name == name)
            {
                return Ok(Some(if robust {
                    (a.p01, a.p99)
                } else {
                    (a.min, a.max)
                }));
            }
            let step = series.step(step)?;
            Ok(step.attribute(name).and_then(|a| {
                if robust {
                    crate::scene::index::robust_range(&a.values)
                } else {
                    crate::values::value_range(&a.values)
                }
            }))
        };
        Ok(match self {
            RangeSpec::Fixed(lo, hi) => (Some((lo, hi)), "set"),
            RangeSpec::Series => (None, "the series' least to largest value"),
            RangeSpec::Robust => (
                series.attribute(name).map(|a| (a.p01, a.p99)),
                "the series' 1st to 99th percentile (of its lowest and highest step)",
            ),
            RangeSpec::Step => (of_step(false)?, "this step's least to largest value"),
            RangeSpec::RobustStep => (of_step(true)?, "this step's 1st to 99th percentile"),
        })
    }
}

/// A map written as CLI text (`"ramp"`, `"0:0,1:1"`, `1.0`) or as control points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MapSpec {
    /// The same value for every attribute value.
    Constant(f64),
    /// A map's CLI text (`"ramp"`, `"0:0.5,1:1"`).
    Text(String),
    /// Control points `[x, y]`, x the normalised attribute in [0, 1].
    Points(Vec<[f64; 2]>),
}

impl MapSpec {
    /// The piecewise-linear map it describes.
    pub fn to_map(&self) -> Result<PiecewiseLinear, MapError> {
        match self {
            MapSpec::Constant(y) => y.to_string().parse(),
            MapSpec::Text(s) => s.parse(),
            MapSpec::Points(p) => PiecewiseLinear::new(p.clone()),
        }
    }
}

/// A radius: a length in data units, or a percentage of the bounding-box diagonal (`"1%"`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RadiusText", into = "RadiusText")]
pub enum RadiusSpec {
    /// A length in data units.
    Absolute(f64),
    /// A percentage (1.0 is 1%) of the bounding-box diagonal.
    PercentOfDiagonal(f64),
}

#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum RadiusText {
    Number(f64),
    Text(String),
}

impl TryFrom<RadiusText> for RadiusSpec {
    type Error = String;
    fn try_from(r: RadiusText) -> Result<Self, String> {
        match r {
            RadiusText::Number(v) => Ok(RadiusSpec::Absolute(v)),
            RadiusText::Text(s) => s.parse(),
        }
    }
}

impl From<RadiusSpec> for RadiusText {
    fn from(r: RadiusSpec) -> Self {
        match r {
            RadiusSpec::Absolute(v) => RadiusText::Number(v),
            RadiusSpec::PercentOfDiagonal(p) => RadiusText::Text(format!("{p}%")),
        }
    }
}

impl std::str::FromStr for RadiusSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.trim();
        let (number, percent) = match s.strip_suffix('%') {
            Some(n) => (n.trim(), true),
            None => (s, false),
        };
        let v: f64 = number
            .parse()
            .map_err(|_| format!("radius '{s}' is not a number or a percentage like '1%'"))?;
        if !(v.is_finite() && v > 0.0) {
            return Err(format!("radius '{s}' must be positive"));
        }
        Ok(if percent {
            RadiusSpec::PercentOfDiagonal(v)
        } else {
            RadiusSpec::Absolute(v)
        })
    }
}

impl std::fmt::Display for RadiusSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RadiusSpec::Absolute(r) => write!(f, "{r}"),
            RadiusSpec::PercentOfDiagonal(p) => write!(f, "{p}%"),
        }
    }
}

impl RadiusSpec {
    /// The paper's sample code's default, 1% of the bounding-box diagonal: ours only where the
    /// data has no spacing to measure (see `resolve::default_radius`).
    pub const DEFAULT: RadiusSpec = RadiusSpec::PercentOfDiagonal(1.0);

    /// The radius in data units, given the bounding-box diagonal.
    pub fn resolve(self, diagonal: f64) -> f64 {
        match self {
            RadiusSpec::Absolute(r) => r,
            RadiusSpec::PercentOfDiagonal(p) => p / 100.0 * diagonal,
        }
    }
}

/// How the field is defined.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldSection {
    /// The global radius R; unset: derived from the data's spacing.
    pub radius: Option<RadiusSpec>,
    /// A particle's radius as a fraction of the global radius, per normalised attribute value,
    /// in [0, 1]; unset: 1 everywhere.
    pub radius_map: Option<MapSpec>,
    /// The density weight per normalised attribute value; unset: 1 everywhere.
    pub density_map: Option<MapSpec>,
    /// A colour-map preset's name or a ParaView JSON file; unset: viridis.
    pub colormap: Option<String>,
    /// Whether the attribute is averaged before (`post`, the default) or after (`pre`) colour
    /// mapping.
    pub classification: Option<Classification>,
    /// The BVH's particles per cluster K; unset: chosen from how much the particles overlap.
    pub cluster: Option<ClusterSize>,
    /// The kernel (`gaussian-rbf`, `sph-cubic`, ...).
    pub kernel: Option<Kernel>,
    /// An SPH kernel's masses: an attribute's name or one value.
    pub mass: Option<PerParticle>,
    /// An SPH kernel's densities: an attribute's name or one value.
    pub density: Option<PerParticle>,
}

/// The view: an explicit look-at camera, or a position on the benchmark orbit.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    /// The camera's position, data units.
    pub eye: Option<[f64; 3]>,
    /// The point the camera looks at, data units.
    pub at: Option<[f64; 3]>,
    /// The camera's up vector.
    pub up: Option<[f64; 3]>,
    /// Vertical field of view, degrees.
    pub fovy: Option<f64>,
    /// `"i/n"`: camera i of the n-camera benchmark orbit (instead of eye/at/up).
    pub orbit: Option<String>,
    /// `"AZ,EL"` or `"AZ,EL,DIST"`: the camera at azimuth and elevation (degrees, about the up
    /// axis) around the data's centre, DIST away (default: the data fills the view), instead
    /// of eye/at.
    pub from: Option<String>,
    /// The scene's vertical (`"z"`, `"-y"`, ...), which views by angles and the light are
    /// about. Default: `up` where it points along an axis, else the data's default (z, or
    /// face on to planar data).
    pub up_axis: Option<UpAxis>,
}

/// Parses `AZ,EL` or `AZ,EL,DIST` (degrees, degrees, data units).
pub fn parse_camera_from(text: &str) -> Result<(f64, f64, Option<f64>), String> {
    let bad = || {
        format!(
            "camera from '{text}': expected AZ,EL or AZ,EL,DIST (degrees, degrees, a positive distance)"
        )
    };
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad())?;
    match v[..] {
        [az, el] if az.is_finite() && el.is_finite() => Ok((az, el, None)),
        [az, el, d] if az.is_finite() && el.is_finite() && d.is_finite() && d > 0.0 => {
            Ok((az, el, Some(d)))
        }
        _ => Err(bad()),
    }
}

/// How to render.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSection {
    /// Image width in pixels; unset: 512.
    pub width: Option<u32>,
    /// Image height in pixels; unset: 512.
    pub height: Option<u32>,
    /// Samples per pixel (frames accumulated); unset: [`DEFAULT_SPP`].
    pub spp: Option<u32>,
    /// The integrator; unset: emission–absorption.
    pub integrator: Option<crate::values::Integrator>,
    /// The noise that jitters samples; unset: spatiotemporal blue noise.
    pub noise: Option<crate::values::NoiseKind>,
    /// The noise's seed; unset: 1.
    pub seed: Option<u32>,
    /// Ray-marching step in data units; unset: from the radius and the mean particle spacing.
    pub step_size: Option<f64>,
    /// Extinction per unit optical density; unset: 0.4 / radius.
    pub density_scale: Option<f64>,
    /// The density normalising Phi for colour and extinction; unset: estimated from the data.
    pub phi_ref: Option<f64>,
    /// The optical-density map D over Phi / Phi_ref; unset: the ramp from 0 to 1.
    pub optical_map: Option<MapSpec>,
    /// Colour by density instead of the attribute; unset: false.
    pub color_by_density: Option<bool>,
    /// Linear RGB behind the volume; unset: black.
    pub background: Option<[f64; 3]>,
    /// The opacity in (0, 1] at which a ray stops; unset: 0.99.
    pub opacity_threshold: Option<f64>,
    /// The light for single scattering; unset: [`crate::values::Light`]'s default.
    pub light: Option<crate::values::Light>,
    /// How GPU backends hold positions (`auto`, `auto:TOLERANCE`, `f32`, `ds`).
    pub precision: Option<String>,
    /// Render until the estimated error (in `error_metric`) is at most this, choosing the
    /// step and the samples per pixel (`spp` is then ignored).
    pub target_error: Option<f64>,
    /// Render for this many seconds, choosing the step with the least estimated error.
    pub time_budget: Option<f64>,
    /// The measure of `target_error`: `rmse` (linear RGB, the default) or `flip`.
    pub error_metric: Option<crate::render::target::ErrorMetric>,
    /// Render with Knoll et al.'s splatter, this many hits per slab, instead of the RBFs
    /// (`aarbf render --method splat --splat-k K`).
    pub splat_k: Option<usize>,
    /// Render the voxel-grid baseline, this many cells along the grid's longest side, instead
    /// of the RBFs (`aarbf render --method voxel --voxel-grid N`).
    pub voxel_grid: Option<usize>,
}

/// A scene file.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// `[data]`: where the particles come from.
    #[serde(default)]
    pub data: DataSection,
    /// `[field]`: the radius, maps and kernel.
    #[serde(default)]
    pub field: FieldSection,
    /// `[camera]`: the view.
    #[serde(default)]
    pub camera: CameraSection,
    /// `[render]`: image size, samples and the integrator's settings.
    #[serde(default)]
    pub render: RenderSection,
}

/// A scene file that cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("scene file {path}: {problem}")]
pub struct SceneFileError {
    /// The scene file.
    pub path: PathBuf,
    /// What is wrong with it (a read, parse or write error).
    pub problem: String,
}

/// Samples per pixel when neither the scene nor a flag says.
pub const DEFAULT_SPP: u32 = 16;

/// Parses `i/n`: camera i of the n-camera benchmark orbit.
pub fn parse_orbit(text: &str) -> Result<(usize, usize), String> {
    let bad = || format!("orbit '{text}': expected i/n with 0 <= i < n");
    let (i, n) = text.split_once('/').ok_or_else(bad)?;
    let (i, n): (usize, usize) = (
        i.trim().parse().map_err(|_| bad())?,
        n.trim().parse().map_err(|_| bad())?,
    );
    if n == 0 || i >= n {
        return Err(bad());
    }
    Ok((i, n))
}

impl CameraSection {
    /// The camera this section states over data with `bounds`: an orbit position (which wins),
    /// an explicit eye and target, or `None` (a default view of the data).
    pub fn camera(&self, bounds: Bounds) -> Result<Option<Camera>, String> {
        let fovy = self.fovy.unwrap_or(40.0);
        if let Some(orbit) = &self.orbit {
            let (i, n) = parse_orbit(orbit)?;
            return Ok(Some(Camera::benchmark_orbit(bounds, i, n, fovy)));
        }
        let up = self.up.map(DVec3::from);
        let axis = || -> Result<UpAxis, String> {
            match (self.up_axis, up) {
                (None, Some(u)) if UpAxis::along(u).is_none() => Err(format!(
                    "camera up {u} must point along an axis to place a view by angles"
                )),
                _ => Ok(self.up_axis(bounds)),
            }
        };
        if let Some(from) = &self.from {
            if self.eye.is_some() || self.at.is_some() {
                return Err("camera: `from` and eye/at each place the camera; give one".into());
            }
            let (azimuth, elevation, distance) = parse_camera_from(from)?;
            let camera = match distance {
                Some(d) => Camera::from_angles(bounds, axis()?, azimuth, elevation, d, fovy),
                None => Camera::orbit(bounds, axis()?, azimuth, elevation, fovy),
            };
            return Ok(Some(camera));
        }
        Ok(match (self.eye, self.at) {
            (Some(eye), Some(at)) => Some(Camera {
                eye: DVec3::from(eye),
                at: DVec3::from(at),
                up: up.unwrap_or_else(|| Camera::default_for(bounds).up),
                fovy,
            }),
            (None, None) if up.is_some() || self.up_axis.is_some() => Some(Camera {
                fovy,
                ..Camera::default_upright(bounds, axis()?)
            }),
            (None, None) => None,
            _ => return Err("camera: eye and at go together".into()),
        })
    }

    /// The scene's vertical over data with `bounds`: `up_axis`, else `up` where it points
    /// along an axis, else the data's default view's.
    pub fn up_axis(&self, bounds: Bounds) -> UpAxis {
        self.up_axis
            .or_else(|| self.up.and_then(|u| UpAxis::along(DVec3::from(u))))
            .or_else(|| UpAxis::along(Camera::default_for(bounds).up))
            .unwrap_or(UpAxis::Z)
    }

    /// A look-at camera, exactly.
    pub fn of(camera: Camera) -> CameraSection {
        CameraSection {
            eye: Some(camera.eye.to_array()),
            at: Some(camera.at.to_array()),
            up: Some(camera.up.to_array()),
            fovy: Some(camera.fovy),
            orbit: None,
            from: None,
            up_axis: None,
        }
    }
}

impl SceneFile {
    /// The render settings the scene states, over data with `bounds`, defaults where it is
    /// silent: the one reading of `[render]` and `[camera]` for the batch renderer and the
    /// viewer.
    pub fn render_settings(&self, bounds: Bounds) -> Result<RenderSettings, String> {
        let r = &self.render;
        let d = RenderSettings::default();
        let optical_map = match &r.optical_map {
            Some(spec) => spec.to_map().map_err(|e| e.to_string())?,
            None => PiecewiseLinear::ramp(0.0, 1.0),
        };
        if let (Some(k), Some(n)) = (r.splat_k, r.voxel_grid) {
            return Err(format!(
                "[render] splat_k = {k} and voxel_grid = {n} each choose a baseline renderer \
                 instead of the RBFs: give at most one"
            ));
        }
        let settings = RenderSettings {
            width: r.width.unwrap_or(d.width),
            height: r.height.unwrap_or(d.height),
            integrator: r.integrator.unwrap_or(d.integrator),
            noise: r.noise.unwrap_or(d.noise),
            seed: r.seed.unwrap_or(d.seed),
            camera: self.camera.camera(bounds)?,
            step_size: r.step_size,
            phi_ref: r.phi_ref,
            optical: OpticalDensityMap::new(optical_map, r.density_scale)
                .map_err(|e| e.to_string())?,
            colour_by_density: r.color_by_density.unwrap_or(d.colour_by_density),
            light: r.light.unwrap_or(d.light),
            up_axis: self.camera.up_axis(bounds),
            background: r.background.unwrap_or(d.background),
            opacity_threshold: r.opacity_threshold.unwrap_or(d.opacity_threshold),
            splat_k: r.splat_k,
            voxel_grid: r.voxel_grid,
        };
        settings.check()?;
        Ok(settings)
    }

    /// The samples per pixel the scene asks for.
    pub fn spp(&self) -> u32 {
        self.render.spp.unwrap_or(DEFAULT_SPP)
    }

    /// A scene that renders the image of `settings` at `spp` samples per pixel: every section
    /// filled, the camera explicit. With `used`, the automatic values as it resolved them, so
    /// the image is reproduced exactly whatever later changes to the data's statistics;
    /// without, what `settings` left automatic stays automatic.
    pub fn reproducing(
        data: DataSection,
        field: FieldSection,
        settings: &RenderSettings,
        used: Option<&Resolved>,
        camera: Camera,
        spp: u32,
        precision: &str,
    ) -> SceneFile {
        SceneFile {
            data,
            field,
            camera: CameraSection {
                up_axis: Some(settings.up_axis),
                ..CameraSection::of(camera)
            },
            render: RenderSection {
                width: Some(settings.width),
                height: Some(settings.height),
                spp: Some(spp),
                integrator: Some(settings.integrator),
                noise: Some(settings.noise),
                seed: Some(settings.seed),
                step_size: used.map(|u| u.step_size).or(settings.step_size),
                density_scale: used.map(|u| u.density_scale).or(settings.optical.scale()),
                phi_ref: used.map(|u| u.phi_ref).or(settings.phi_ref),
                optical_map: Some(MapSpec::Points(settings.optical.map().points().to_vec())),
                color_by_density: Some(settings.colour_by_density),
                background: Some(settings.background),
                opacity_threshold: Some(settings.opacity_threshold),
                light: Some(settings.light),
                precision: Some(precision.to_owned()),
                // The step and samples a targeted render chose are written above: the scene
                // reproduces its image, not its search.
                target_error: None,
                time_budget: None,
                error_metric: None,
                splat_k: settings.splat_k,
                voxel_grid: settings.voxel_grid,
            },
        }
    }

    /// What a targeted render aims for, if the scene asks for one.
    pub fn target(&self) -> Result<Option<crate::render::target::Target>, String> {
        let r = &self.render;
        if r.target_error.is_none() && r.time_budget.is_none() {
            return Ok(None);
        }
        let time_budget = r
            .time_budget
            .map(|s| {
                std::time::Duration::try_from_secs_f64(s)
                    .map_err(|_| format!("time budget {s} s must be a positive number of seconds"))
            })
            .transpose()?;
        let target = crate::render::target::Target {
            error: r.target_error,
            time_budget,
            metric: r.error_metric.unwrap_or_default(),
            max_spp: crate::render::target::Target::DEFAULT_MAX_SPP,
        };
        target.check().map_err(|e| e.to_string())?;
        Ok(Some(target))
    }

    /// Writes the scene as TOML, atomically; an existing file only with `force`.
    pub fn save(&self, path: &Path, force: bool) -> Result<(), SceneFileError> {
        let err = |problem: String| SceneFileError {
            path: path.to_path_buf(),
            problem,
        };
        let text = toml::to_string(self).map_err(|e| err(e.to_string()))?;
        crate::io::output::write_atomically(path, force, |tmp| std::fs::write(tmp, &text))
            .map_err(|e| err(e.to_string()))
    }

    /// Reads and parses the scene file at `path`, its relative data path and colour-map file
    /// joined to the scene file's directory.
    pub fn load(path: &Path) -> Result<SceneFile, SceneFileError> {
        let err = |problem: String| SceneFileError {
            path: path.to_path_buf(),
            problem,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        let mut scene: SceneFile = toml::from_str(&text).map_err(|e| err(e.to_string()))?;
        // Paths inside the file are relative to it.
        let base = path.parent().unwrap_or(Path::new("."));
        if let Some(p) = &scene.data.path
            && p.is_relative()
        {
            scene.data.path = Some(base.join(p));
        }
        if let Some(c) = &scene.field.colormap
            && c.ends_with(".json")
            && Path::new(c).is_relative()
        {
            scene.field.colormap = Some(base.join(c).to_string_lossy().into_owned());
        }
        Ok(scene)
    }
}

#[cfg(test)]
mod tests;
