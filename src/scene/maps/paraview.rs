//! ParaView colour-map JSON import (`File > Export` in ParaView's colour-map editor).

use std::path::Path;

use super::colour::SAMPLES;
use super::{ColorMap, ColorPoint, MapError, invalid};
use crate::values::color_space;

impl ColorMap {
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

    /// The map in ParaView's JSON colour-map text: one map, or the first of an array that has
    /// `RGBPoints`.
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

#[cfg(test)]
mod tests {
    use super::*;

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
