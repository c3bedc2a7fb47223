//! The radius map m(t).

use serde::{Deserialize, Serialize};

use super::{MapError, PiecewiseLinear, invalid};

/// Radius map m(t) in [0, 1]: a particle's radius as a fraction of the global radius.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RadiusMap(pub PiecewiseLinear);

impl RadiusMap {
    /// The radius map `map`; an error where a value lies outside [0, 1].
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::maps::DensityMap;

    #[test]
    fn maps_check_their_ranges() {
        assert!(RadiusMap::new("0:0,1:1.5".parse().unwrap()).is_err());
        assert!(DensityMap::new("-1".parse().unwrap()).is_err());
        assert!(DensityMap::new("ramp".parse().unwrap()).is_ok());
    }
}
