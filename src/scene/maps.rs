//! The user's 1D maps over the normalised attribute `t` in [0, 1] (method.md §1): the colour
//! map C(t), the density map w(t), the radius map m(t), and the optical-density map from
//! normalised density to extinction. All are piecewise linear between control points and
//! serialisable; colour maps also come as presets or from ParaView's colour-map JSON.

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// A problem with a map definition.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error("{what}: {problem}")]
    Invalid { what: String, problem: String },
    #[error("cannot read colour map {path}: {problem}")]
    File { path: String, problem: String },
}

fn invalid(what: &str, problem: impl Into<String>) -> MapError {
    MapError::Invalid {
        what: what.to_owned(),
        problem: problem.into(),
    }
}

/// A function on [0, 1], linear between control points `(x, y)` with ascending `x`, constant
/// beyond the first and last points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Vec<[f64; 2]>", into = "Vec<[f64; 2]>")]
pub struct PiecewiseLinear {
    points: Vec<[f64; 2]>,
}

impl PiecewiseLinear {
    pub fn constant(y: f64) -> PiecewiseLinear {
        PiecewiseLinear {
            points: vec![[0.0, y], [1.0, y]],
        }
    }

    /// The ramp from `y0` at t = 0 to `y1` at t = 1.
    pub fn ramp(y0: f64, y1: f64) -> PiecewiseLinear {
        PiecewiseLinear {
            points: vec![[0.0, y0], [1.0, y1]],
        }
    }

    /// Checks the points: at least one, `x` in [0, 1] and ascending, `y` finite.
    pub fn new(points: Vec<[f64; 2]>) -> Result<PiecewiseLinear, MapError> {
        let what = "piecewise-linear map";
        if points.is_empty() {
            return Err(invalid(what, "needs at least one control point"));
        }
        for (i, p) in points.iter().enumerate() {
            if !(0.0..=1.0).contains(&p[0]) {
                return Err(invalid(
                    what,
                    format!("control point {i}: x = {} is outside [0, 1]", p[0]),
                ));
            }
            if !p[1].is_finite() {
                return Err(invalid(
                    what,
                    format!("control point {i}: y = {} is not finite", p[1]),
                ));
            }
            if i > 0 && p[0] < points[i - 1][0] {
                return Err(invalid(
                    what,
                    format!(
                        "control point {i}: x = {} is smaller than the one before",
                        p[0]
                    ),
                ));
            }
        }
        Ok(PiecewiseLinear { points })
    }

    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    pub fn eval(&self, t: f64) -> f64 {
        let p = &self.points;
        let t = if t.is_nan() { 0.0 } else { t };
        if t <= p[0][0] {
            return p[0][1];
        }
        let last = p[p.len() - 1];
        if t >= last[0] {
            return last[1];
        }
        // First point with x > t; t lies in [p[i-1].x, p[i].x).
        let i = p.partition_point(|q| q[0] <= t);
        let (a, b) = (p[i - 1], p[i]);
        let u = (t - a[0]) / (b[0] - a[0]);
        a[1] + u * (b[1] - a[1])
    }

    /// Whether the map has the same value everywhere (so a scene can skip evaluating it).
    pub fn is_constant(&self) -> bool {
        self.points.iter().all(|p| p[1] == self.points[0][1])
    }

    pub fn min_value(&self) -> f64 {
        self.points
            .iter()
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min)
    }

    pub fn max_value(&self) -> f64 {
        self.points
            .iter()
            .map(|p| p[1])
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

impl TryFrom<Vec<[f64; 2]>> for PiecewiseLinear {
    type Error = MapError;
    fn try_from(points: Vec<[f64; 2]>) -> Result<Self, MapError> {
        PiecewiseLinear::new(points)
    }
}

impl From<PiecewiseLinear> for Vec<[f64; 2]> {
    fn from(m: PiecewiseLinear) -> Self {
        m.points
    }
}

/// The CLI spelling of a map: a number (constant), `ramp` (0 to 1), `ramp:a:b` (a to b), or
/// control points `x:y,x:y,...`.
impl FromStr for PiecewiseLinear {
    type Err = MapError;
    fn from_str(s: &str) -> Result<Self, MapError> {
        let s = s.trim();
        let what = format!("map '{s}'");
        if let Ok(y) = s.parse::<f64>() {
            if !y.is_finite() {
                return Err(invalid(&what, "the constant is not finite"));
            }
            return Ok(PiecewiseLinear::constant(y));
        }
        if s == "ramp" {
            return Ok(PiecewiseLinear::ramp(0.0, 1.0));
        }
        if let Some(rest) = s.strip_prefix("ramp:") {
            let v: Vec<f64> = rest.split(':').filter_map(|v| v.parse().ok()).collect();
            if let [a, b] = v[..] {
                return PiecewiseLinear::new(vec![[0.0, a], [1.0, b]]);
            }
            return Err(invalid(&what, "expected ramp:<start>:<end>"));
        }
        let mut points = Vec::new();
        for part in s.split(',') {
            let xy: Vec<&str> = part.split(':').collect();
            let parsed = match xy[..] {
                [x, y] => x
                    .trim()
                    .parse::<f64>()
                    .ok()
                    .zip(y.trim().parse::<f64>().ok()),
                _ => None,
            };
            let (x, y) = parsed.ok_or_else(|| {
                invalid(
                    &what,
                    format!(
                        "'{part}' is not x:y (use a number, 'ramp', 'ramp:a:b' or x:y,x:y,...)"
                    ),
                )
            })?;
            points.push([x, y]);
        }
        PiecewiseLinear::new(points).map_err(|e| invalid(&what, e.to_string()))
    }
}

/// Density map w(t) >= 0: a particle's weight in the density sum (method.md eq. 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct DensityMap(pub PiecewiseLinear);

impl DensityMap {
    pub fn new(map: PiecewiseLinear) -> Result<DensityMap, MapError> {
        if map.min_value() < 0.0 {
            return Err(invalid(
                "density map",
                format!("weights must be >= 0, found {}", map.min_value()),
            ));
        }
        Ok(DensityMap(map))
    }
}

impl Default for DensityMap {
    fn default() -> Self {
        DensityMap(PiecewiseLinear::constant(1.0))
    }
}

/// Radius map m(t) in [0, 1]: a particle's radius as a fraction of the global radius.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RadiusMap(pub PiecewiseLinear);

impl RadiusMap {
    pub fn new(map: PiecewiseLinear) -> Result<RadiusMap, MapError> {
        if map.min_value() < 0.0 || map.max_value() > 1.0 {
            return Err(invalid(
                "radius map",
                format!(
                    "values must lie in [0, 1] (fractions of the global radius), found {}..{}",
                    map.min_value(),
                    map.max_value()
                ),
            ));
        }
        Ok(RadiusMap(map))
    }
}

impl Default for RadiusMap {
    fn default() -> Self {
        RadiusMap(PiecewiseLinear::constant(1.0))
    }
}

/// Optical-density map: extinction `sigma_t = scale * D(Phi / Phi_ref)` with D piecewise
/// linear over the normalised density in [0, 1] (the renderer picks `Phi_ref`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OpticalDensityMap {
    pub map: PiecewiseLinear,
    pub scale: f64,
}

impl Default for OpticalDensityMap {
    fn default() -> Self {
        OpticalDensityMap {
            map: PiecewiseLinear::ramp(0.0, 1.0),
            scale: 1.0,
        }
    }
}

/// One control point of a colour map: position in [0, 1] and an sRGB colour in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorPoint {
    pub x: f64,
    pub rgb: [f64; 3],
}

/// A colour map C(t): sRGB control points, interpolated linearly in sRGB between them (as
/// ParaView does for RGB maps). [`ColorMap::linear_rgb`] gives linear-light colour, the space
/// colours are averaged and composited in.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorMap {
    pub name: String,
    pub points: Vec<ColorPoint>,
}

/// The preset names.
pub const PRESETS: [&str; 7] = [
    "viridis",
    "plasma",
    "inferno",
    "magma",
    "turbo",
    "cool-warm",
    "grayscale",
];

/// Samples taken from a continuous map (a preset or a non-RGB ParaView map).
const SAMPLES: usize = 256;

impl ColorMap {
    pub fn preset(name: &str) -> Result<ColorMap, MapError> {
        let gradient = match name {
            "viridis" => Some(colorous::VIRIDIS),
            "plasma" => Some(colorous::PLASMA),
            "inferno" => Some(colorous::INFERNO),
            "magma" => Some(colorous::MAGMA),
            "turbo" => Some(colorous::TURBO),
            _ => None,
        };
        let points: Vec<ColorPoint> = if let Some(g) = gradient {
            (0..SAMPLES)
                .map(|i| {
                    let c = g.eval_rational(i, SAMPLES);
                    ColorPoint {
                        x: i as f64 / (SAMPLES - 1) as f64,
                        rgb: [c.r, c.g, c.b].map(|v| v as f64 / 255.0),
                    }
                })
                .collect()
        } else if name == "cool-warm" {
            // Moreland's diverging map (ParaView's "Cool to Warm").
            let cool = [0.230, 0.299, 0.754];
            let warm = [0.706, 0.016, 0.150];
            (0..SAMPLES)
                .map(|i| {
                    let x = i as f64 / (SAMPLES - 1) as f64;
                    ColorPoint {
                        x,
                        rgb: color_space::diverging(cool, warm, x),
                    }
                })
                .collect()
        } else if name == "grayscale" {
            vec![
                ColorPoint {
                    x: 0.0,
                    rgb: [0.0; 3],
                },
                ColorPoint {
                    x: 1.0,
                    rgb: [1.0; 3],
                },
            ]
        } else {
            return Err(invalid(
                &format!("colour map '{name}'"),
                format!("not a preset ({}) nor a .json file", PRESETS.join(", ")),
            ));
        };
        Ok(ColorMap {
            name: name.to_owned(),
            points,
        })
    }

    /// A preset name, or a path to a ParaView colour-map JSON file.
    pub fn from_name_or_file(spec: &str) -> Result<ColorMap, MapError> {
        if PRESETS.contains(&spec) {
            ColorMap::preset(spec)
        } else if spec.ends_with(".json") {
            ColorMap::from_paraview_json_file(Path::new(spec))
        } else {
            ColorMap::preset(spec)
        }
    }

    /// Imports a ParaView colour map (`File > Export` in its colour-map editor): a JSON array
    /// of objects (or one object) with `Name`, `ColorSpace` and `RGBPoints` (x, r, g, b, ...).
    /// The first map in the file is taken; `x` is rescaled to [0, 1]. Maps in Lab or
    /// Diverging space are resampled so linear-RGB interpolation reproduces them.
    pub fn from_paraview_json_file(path: &Path) -> Result<ColorMap, MapError> {
        let file_err = |problem: String| MapError::File {
            path: path.display().to_string(),
            problem,
        };
        let text = std::fs::read_to_string(path).map_err(|e| file_err(e.to_string()))?;
        ColorMap::from_paraview_json(&text).map_err(|e| file_err(e.to_string()))
    }

    pub fn from_paraview_json(text: &str) -> Result<ColorMap, MapError> {
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| invalid("colour-map JSON", e.to_string()))?;
        let object = match &value {
            serde_json::Value::Array(maps) => maps
                .iter()
                .find(|m| m.get("RGBPoints").is_some())
                .ok_or_else(|| invalid("colour-map JSON", "no map with RGBPoints in the array"))?,
            serde_json::Value::Object(_) => &value,
            _ => {
                return Err(invalid(
                    "colour-map JSON",
                    "expected an array of maps or one map",
                ));
            }
        };
        let name = object
            .get("Name")
            .and_then(|n| n.as_str())
            .unwrap_or("imported")
            .to_owned();
        let what = format!("colour map '{name}'");
        let numbers: Vec<f64> = object
            .get("RGBPoints")
            .and_then(|p| p.as_array())
            .ok_or_else(|| invalid(&what, "RGBPoints is missing or not an array"))?
            .iter()
            .map(|v| {
                v.as_f64()
                    .ok_or_else(|| invalid(&what, format!("RGBPoints holds '{v}', not a number")))
            })
            .collect::<Result<_, _>>()?;
        if numbers.len() < 4 || !numbers.len().is_multiple_of(4) {
            return Err(invalid(
                &what,
                format!(
                    "RGBPoints must hold x, r, g, b quadruples; it has {} numbers",
                    numbers.len()
                ),
            ));
        }
        let mut points: Vec<ColorPoint> = numbers
            .chunks_exact(4)
            .map(|q| ColorPoint {
                x: q[0],
                rgb: [q[1], q[2], q[3]],
            })
            .collect();
        for (i, p) in points.iter().enumerate() {
            if p.rgb.iter().any(|c| !(0.0..=1.0).contains(c)) || !p.x.is_finite() {
                return Err(invalid(
                    &what,
                    format!("point {i} has a colour outside [0, 1] or a bad x"),
                ));
            }
            if i > 0 && p.x < points[i - 1].x {
                return Err(invalid(&what, format!("point {i}: x values must ascend")));
            }
        }
        let (lo, hi) = (points[0].x, points[points.len() - 1].x);
        for p in &mut points {
            p.x = if hi > lo { (p.x - lo) / (hi - lo) } else { 0.0 };
        }
        let space = object
            .get("ColorSpace")
            .and_then(|s| s.as_str())
            .unwrap_or("RGB")
            .to_ascii_lowercase();
        let points = match space.as_str() {
            "rgb" | "hsv" => points,
            "lab" | "cielab" | "diverging" | "lab/ciede2000" | "step" => {
                resample(&points, |a, b, u| match space.as_str() {
                    "diverging" => color_space::diverging(a, b, u),
                    "step" => {
                        if u < 1.0 {
                            a
                        } else {
                            b
                        }
                    }
                    _ => color_space::lab_mix(a, b, u),
                })
            }
            other => {
                tracing::warn!("{what}: colour space '{other}' is interpolated in RGB");
                points
            }
        };
        Ok(ColorMap { name, points })
    }

    /// sRGB colour at `t` (clamped to [0, 1]).
    pub fn srgb(&self, t: f64) -> [f64; 3] {
        let p = &self.points;
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        if t <= p[0].x {
            return p[0].rgb;
        }
        if t >= p[p.len() - 1].x {
            return p[p.len() - 1].rgb;
        }
        let i = p.partition_point(|q| q.x <= t);
        let (a, b) = (p[i - 1], p[i]);
        let u = (t - a.x) / (b.x - a.x);
        std::array::from_fn(|c| a.rgb[c] + u * (b.rgb[c] - a.rgb[c]))
    }

    /// Linear-light colour at `t`.
    pub fn linear_rgb(&self, t: f64) -> [f64; 3] {
        self.srgb(t).map(color_space::srgb_to_linear)
    }
}

impl Default for ColorMap {
    fn default() -> Self {
        ColorMap::preset("viridis").expect("viridis is a preset")
    }
}

/// Resamples a map whose segments interpolate by `mix` into SAMPLES RGB points.
fn resample(
    points: &[ColorPoint],
    mix: impl Fn([f64; 3], [f64; 3], f64) -> [f64; 3],
) -> Vec<ColorPoint> {
    if points.len() < 2 {
        return points.to_vec();
    }
    (0..SAMPLES)
        .map(|i| {
            let x = i as f64 / (SAMPLES - 1) as f64;
            let k = points
                .partition_point(|q| q.x <= x)
                .clamp(1, points.len() - 1);
            let (a, b) = (points[k - 1], points[k]);
            let u = if b.x > a.x {
                ((x - a.x) / (b.x - a.x)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            ColorPoint {
                x,
                rgb: mix(a.rgb, b.rgb, u),
            }
        })
        .collect()
}

/// Colour-space conversions for map interpolation.
pub mod color_space {
    pub fn srgb_to_linear(c: f64) -> f64 {
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    }

    pub fn linear_to_srgb(c: f64) -> f64 {
        if c <= 0.0031308 {
            c * 12.92
        } else {
            1.055 * c.powf(1.0 / 2.4) - 0.055
        }
    }

    const WHITE: [f64; 3] = [0.95047, 1.0, 1.08883];

    fn srgb_to_lab(rgb: [f64; 3]) -> [f64; 3] {
        let [r, g, b] = rgb.map(srgb_to_linear);
        let xyz = [
            0.4124 * r + 0.3576 * g + 0.1805 * b,
            0.2126 * r + 0.7152 * g + 0.0722 * b,
            0.0193 * r + 0.1192 * g + 0.9505 * b,
        ];
        let f = |t: f64| {
            if t > 0.008856 {
                t.cbrt()
            } else {
                7.787 * t + 16.0 / 116.0
            }
        };
        let [fx, fy, fz] = [0, 1, 2].map(|i| f(xyz[i] / WHITE[i]));
        [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
    }

    fn lab_to_srgb(lab: [f64; 3]) -> [f64; 3] {
        let fy = (lab[0] + 16.0) / 116.0;
        let fx = fy + lab[1] / 500.0;
        let fz = fy - lab[2] / 200.0;
        let finv = |t: f64| {
            if t.powi(3) > 0.008856 {
                t.powi(3)
            } else {
                (t - 16.0 / 116.0) / 7.787
            }
        };
        let [x, y, z] = [fx, fy, fz].map(finv);
        let (x, y, z) = (x * WHITE[0], y * WHITE[1], z * WHITE[2]);
        let r = 3.2406 * x - 1.5372 * y - 0.4986 * z;
        let g = -0.9689 * x + 1.8758 * y + 0.0415 * z;
        let b = 0.0557 * x - 0.2040 * y + 1.0570 * z;
        [r, g, b].map(|c| linear_to_srgb(c.clamp(0.0, 1.0)))
    }

    pub fn lab_mix(a: [f64; 3], b: [f64; 3], u: f64) -> [f64; 3] {
        let (la, lb) = (srgb_to_lab(a), srgb_to_lab(b));
        lab_to_srgb(std::array::from_fn(|i| la[i] + u * (lb[i] - la[i])))
    }

    fn lab_to_msh(lab: [f64; 3]) -> [f64; 3] {
        let m = (lab[0] * lab[0] + lab[1] * lab[1] + lab[2] * lab[2]).sqrt();
        let s = if m > 0.001 {
            (lab[0] / m).clamp(-1.0, 1.0).acos()
        } else {
            0.0
        };
        let h = if s > 0.001 { lab[2].atan2(lab[1]) } else { 0.0 };
        [m, s, h]
    }

    fn msh_to_lab(msh: [f64; 3]) -> [f64; 3] {
        let [m, s, h] = msh;
        [m * s.cos(), m * s.sin() * h.cos(), m * s.sin() * h.sin()]
    }

    fn adjust_hue(msh: [f64; 3], unsaturated_m: f64) -> f64 {
        let [m, s, h] = msh;
        if m >= unsaturated_m - 0.1 {
            h
        } else {
            let spin = s * (unsaturated_m * unsaturated_m - m * m).sqrt() / (m * s.sin());
            if h > -std::f64::consts::FRAC_PI_3 {
                h + spin
            } else {
                h - spin
            }
        }
    }

    /// Moreland's diverging interpolation ("Diverging Color Maps for Scientific Visualization",
    /// 2009) in Msh space, as ParaView's "Diverging" colour space.
    pub fn diverging(a: [f64; 3], b: [f64; 3], u: f64) -> [f64; 3] {
        let mut ma = lab_to_msh(srgb_to_lab(a));
        let mut mb = lab_to_msh(srgb_to_lab(b));
        let mut u = u;
        // Two saturated, distinct colours pass through an unsaturated white in the middle.
        if ma[1] > 0.05 && mb[1] > 0.05 && (ma[2] - mb[2]).abs() > std::f64::consts::FRAC_PI_3 {
            let mid = ma[0].max(mb[0]).max(88.0);
            if u < 0.5 {
                mb = [mid, 0.0, 0.0];
                u *= 2.0;
            } else {
                ma = [mid, 0.0, 0.0];
                u = 2.0 * u - 1.0;
            }
        }
        if ma[1] < 0.05 && mb[1] > 0.05 {
            ma[2] = adjust_hue(mb, ma[0]);
        } else if mb[1] < 0.05 && ma[1] > 0.05 {
            mb[2] = adjust_hue(ma, mb[0]);
        }
        let msh = std::array::from_fn(|i| (1.0 - u) * ma[i] + u * mb[i]);
        lab_to_srgb(msh_to_lab(msh))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn piecewise_linear_interpolates_and_clamps() {
        let m: PiecewiseLinear = "0:0,0.5:1,1:0".parse().unwrap();
        assert_eq!(m.eval(0.25), 0.5);
        assert_eq!(m.eval(0.5), 1.0);
        assert_eq!(m.eval(0.75), 0.5);
        assert_eq!(m.eval(-1.0), 0.0);
        assert_eq!(m.eval(2.0), 0.0);
        assert_eq!("2.5".parse::<PiecewiseLinear>().unwrap().eval(0.3), 2.5);
        assert_eq!("ramp".parse::<PiecewiseLinear>().unwrap().eval(0.3), 0.3);
        assert!("0:1,x".parse::<PiecewiseLinear>().is_err());
        assert!("0.5:1,0.2:0".parse::<PiecewiseLinear>().is_err());
        assert!("1.5:1".parse::<PiecewiseLinear>().is_err());
    }

    #[test]
    fn maps_check_their_ranges() {
        assert!(RadiusMap::new("0:0,1:1.5".parse().unwrap()).is_err());
        assert!(DensityMap::new("-1".parse().unwrap()).is_err());
        assert!(DensityMap::new("ramp".parse().unwrap()).is_ok());
    }

    #[test]
    fn maps_round_trip_through_toml() {
        #[derive(Serialize, Deserialize, PartialEq, Debug)]
        struct S {
            d: DensityMap,
            c: ColorMap,
        }
        let s = S {
            d: DensityMap("0:0.2,1:1".parse().unwrap()),
            c: ColorMap::preset("grayscale").unwrap(),
        };
        let text = toml::to_string(&s).unwrap();
        assert_eq!(toml::from_str::<S>(&text).unwrap(), s);
        assert!(
            toml::from_str::<S>("d = [[0.5, 1.0], [0.2, 0.0]]\n[c]\nname='x'\npoints=[]").is_err()
        );
    }

    #[test]
    fn presets_exist_and_end_where_they_should() {
        for name in PRESETS {
            let m = ColorMap::preset(name).unwrap();
            assert!(m.points.len() >= 2, "{name}");
        }
        let viridis = ColorMap::preset("viridis").unwrap();
        // viridis starts dark purple (#440154) and ends yellow (#fde725).
        let s = viridis.srgb(0.0);
        assert!(
            (s[0] - 0x44 as f64 / 255.0).abs() < 0.01 && (s[2] - 0x54 as f64 / 255.0).abs() < 0.01
        );
        let e = viridis.srgb(1.0);
        assert!(
            (e[0] - 0xfd as f64 / 255.0).abs() < 0.01 && (e[1] - 0xe7 as f64 / 255.0).abs() < 0.01
        );
        // cool-warm: blue, a light grey in the middle, red.
        let cw = ColorMap::preset("cool-warm").unwrap();
        let mid = cw.srgb(0.5);
        assert!(mid.iter().all(|c| (0.8..0.95).contains(c)), "{mid:?}");
        assert!(cw.srgb(0.0)[2] > 0.7 && cw.srgb(1.0)[0] > 0.65);
        assert_eq!(
            ColorMap::preset("grayscale").unwrap().linear_rgb(0.5),
            [color_space::srgb_to_linear(0.5); 3]
        );
    }

    #[test]
    fn paraview_json_imports() {
        let json =
            r#"[{"ColorSpace":"RGB","Name":"Two","RGBPoints":[-2,0,0,1, 0,1,1,1, 2,1,0,0]}]"#;
        let m = ColorMap::from_paraview_json(json).unwrap();
        assert_eq!(m.name, "Two");
        assert_eq!(m.points.len(), 3);
        assert_eq!(m.srgb(0.5), [1.0, 1.0, 1.0]);
        assert_eq!(m.srgb(0.25), [0.5, 0.5, 1.0]);
        let div = r#"{"ColorSpace":"Diverging","Name":"CW","RGBPoints":[0,0.230,0.299,0.754,1,0.706,0.016,0.150]}"#;
        let d = ColorMap::from_paraview_json(div).unwrap();
        let cw = ColorMap::preset("cool-warm").unwrap();
        for t in [0.0, 0.3, 0.5, 0.8, 1.0] {
            let (a, b) = (d.srgb(t), cw.srgb(t));
            assert!(
                (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9),
                "{t}: {a:?} {b:?}"
            );
        }
        let err =
            ColorMap::from_paraview_json(r#"[{"Name":"x","RGBPoints":[0,1,1]}]"#).unwrap_err();
        assert!(err.to_string().contains("quadruples"), "{err}");
    }
}
