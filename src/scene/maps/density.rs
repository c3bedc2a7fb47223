//! The density map w(t).

use serde::{Deserialize, Serialize};

use super::{MapError, PiecewiseLinear, invalid};

/// Density map w(t) >= 0: a particle's weight in the density sum (method.md eq. 1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct DensityMap(pub PiecewiseLinear);

impl DensityMap {
    /// The density map `map`; an error where it has a negative weight.
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
