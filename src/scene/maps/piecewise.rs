//! Piecewise-linear functions on [0, 1]: what every scalar map is.

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{MapError, invalid};
use crate::values::tables::TABLE_SIZE;

/// A function on [0, 1], linear between control points `(x, y)` with ascending `x`, constant
/// beyond the first and last points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "Vec<[f64; 2]>", into = "Vec<[f64; 2]>")]
pub struct PiecewiseLinear {
    points: Vec<[f64; 2]>,
}

impl PiecewiseLinear {
    /// The map with the value `y` everywhere.
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

    /// The map sampled at `TABLE_SIZE` equally spaced points: the table every backend looks
    /// it up in ([`crate::values::tables`]).
    pub fn bake(&self) -> Vec<f32> {
        (0..TABLE_SIZE)
            .map(|i| self.eval(i as f64 / (TABLE_SIZE - 1) as f64) as f32)
            .collect()
    }

    /// How far the map as every backend uses it (its [`bake`](Self::bake)d table) is from its
    /// control points: the largest |f(x) - table(x)| over [0, 1]. Between two table samples
    /// with no control point between them both are linear and agree at the samples (to f32
    /// rounding), so the largest gap is at a control point that falls between samples.
    pub fn table_error(&self) -> f64 {
        let table = self.bake();
        let rounding =
            self.points.iter().map(|p| p[1].abs()).fold(0.0, f64::max) * f64::from(f32::EPSILON);
        self.points
            .iter()
            .map(|p| (self.eval(p[0]) - crate::values::tables::lookup(&table, p[0])).abs())
            .fold(rounding, f64::max)
    }

    /// The control points `[x, y]`, ascending in x.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }

    /// The value at `t` (NaN taken as 0).
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

    /// The least value over [0, 1].
    pub fn min_value(&self) -> f64 {
        self.points
            .iter()
            .map(|p| p[1])
            .fold(f64::INFINITY, f64::min)
    }

    /// The largest value over [0, 1].
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_error_is_zero_on_the_grid_and_bounds_off_grid_points() {
        let on_grid: PiecewiseLinear = "0:0,0.2:1,1:0".parse().unwrap();
        assert!(on_grid.table_error() < 1e-6, "{}", on_grid.table_error());
        let off: PiecewiseLinear = "0:0,0.333:1,0.71:0.2,1:1".parse().unwrap();
        let e = off.table_error();
        let table = off.bake();
        let worst = (0..=100_000)
            .map(|i| {
                let x = f64::from(i) / 100_000.0;
                (off.eval(x) - crate::values::tables::lookup(&table, x)).abs()
            })
            .fold(0.0, f64::max);
        assert!(
            e > 1e-4 && worst <= e * 1.0001 + 1e-9,
            "bound {e}, found {worst}"
        );
    }

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
}
