//! The optical-density map: extinction from normalised density.

use serde::{Deserialize, Serialize};

use super::{MapError, PiecewiseLinear, invalid};

/// Extinction `sigma_t = scale · D(Phi / Phi_ref)`: D piecewise linear over the normalised
/// density in [0, 1] (the renderer picks `Phi_ref`), `scale` the extinction per unit length
/// where D is 1 (`None`: chosen from the particles' radius). Extinction is never negative.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OpticalDensityMap {
    map: PiecewiseLinear,
    scale: Option<f64>,
}

impl OpticalDensityMap {
    /// Checks the map (D >= 0 everywhere) and the scale (positive and finite).
    pub fn new(map: PiecewiseLinear, scale: Option<f64>) -> Result<OpticalDensityMap, MapError> {
        if map.min_value() < 0.0 {
            return Err(invalid(
                "optical-density map",
                format!(
                    "extinction must be >= 0, but the map reaches {} (control points {:?})",
                    map.min_value(),
                    map.points()
                ),
            ));
        }
        if let Some(s) = scale
            && !(s.is_finite() && s > 0.0)
        {
            return Err(invalid(
                "density scale",
                format!("must be a positive finite extinction per unit length, got {s}"),
            ));
        }
        Ok(OpticalDensityMap { map, scale })
    }

    /// The optical-density map D over Phi / Phi_ref.
    pub fn map(&self) -> &PiecewiseLinear {
        &self.map
    }

    /// The extinction per unit length where D is 1, if set.
    pub fn scale(&self) -> Option<f64> {
        self.scale
    }
}

impl Default for OpticalDensityMap {
    fn default() -> Self {
        OpticalDensityMap {
            map: PiecewiseLinear::ramp(0.0, 1.0),
            scale: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_extinction_and_bad_scales_are_refused() {
        let e = OpticalDensityMap::new("0:-0.1,1:1".parse().unwrap(), None).unwrap_err();
        assert!(e.to_string().contains("extinction must be >= 0"), "{e}");
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = OpticalDensityMap::new(PiecewiseLinear::ramp(0.0, 1.0), Some(bad));
            assert!(e.unwrap_err().to_string().contains("density scale"));
        }
        assert!(OpticalDensityMap::new("0:0.3,1:1".parse().unwrap(), Some(2.0)).is_ok());
    }
}
