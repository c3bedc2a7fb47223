//! The optical-density map D from normalised density to extinction.

use serde::{Deserialize, Serialize};

use super::PiecewiseLinear;

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
