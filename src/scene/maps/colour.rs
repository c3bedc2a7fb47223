//! Colour maps: sRGB control points, the presets, and linear-light lookups.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{MapError, invalid};
use crate::values::color_space;
use crate::values::tables::TABLE_SIZE;

/// One control point of a colour map: position in [0, 1] and an sRGB colour in [0, 1].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorPoint {
    /// Position along the map, in [0, 1].
    pub x: f64,
    /// sRGB colour, each channel in [0, 1].
    pub rgb: [f64; 3],
}

/// A colour map C(t): sRGB control points, interpolated linearly in sRGB between them (as
/// ParaView does for RGB maps). [`ColorMap::linear_rgb`] gives linear-light colour, the space
/// colours are averaged and composited in.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ColorMap {
    /// The preset's name, or the ParaView map's `Name` (`imported` where it has none).
    pub name: String,
    /// Control points, ascending in `x`.
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
pub(super) const SAMPLES: usize = 256;

impl ColorMap {
    /// The preset called `name` (one of [`PRESETS`]).
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

    /// The map as linear-light RGB sampled at `TABLE_SIZE` equally spaced points: the table
    /// every backend looks it up in ([`crate::values::tables`]).
    pub fn bake(&self) -> Vec<[f32; 3]> {
        (0..TABLE_SIZE)
            .map(|i| {
                self.linear_rgb(i as f64 / (TABLE_SIZE - 1) as f64)
                    .map(|c| c as f32)
            })
            .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::maps::DensityMap;
    use crate::values::tables::lookup_colour;

    #[test]
    fn baked_colour_matches_the_map() {
        let grey = ColorMap::preset("grayscale").unwrap().bake();
        let mid = ColorMap::preset("grayscale").unwrap().linear_rgb(0.5);
        let got = lookup_colour(&grey, 0.5);
        assert!((got[0] - mid[0]).abs() < 1e-4, "{got:?} vs {mid:?}");
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
}
