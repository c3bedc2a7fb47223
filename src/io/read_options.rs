//! What to read from a file that holds more than one kind of particle, or in more than one
//! system of units: HDF5 snapshots keep each particle type in a group of its own, and
//! cosmological codes store comoving quantities.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The particle types of GADGET-style snapshots (`/PartType0` .. `/PartType5`), named as
/// GADGET names them; SWIFT numbers gas, stars (4) and black holes (5) the same way.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct ParticleType(u8);

impl ParticleType {
    /// Type 0, gas (SPH) particles: the default.
    pub const GAS: ParticleType = ParticleType(0);
    /// The names of types 0 to 5, in order.
    pub const NAMES: [&'static str; 6] = ["gas", "dm", "disk", "bulge", "stars", "bh"];

    /// The type's number: the N of `/PartTypeN`.
    pub fn index(self) -> usize {
        usize::from(self.0)
    }

    /// The HDF5 group holding particles of this type.
    pub fn group(self) -> String {
        format!("PartType{}", self.0)
    }

    /// The type's name as GADGET names it: gas, dm, disk, bulge, stars or bh.
    pub fn name(self) -> &'static str {
        Self::NAMES[self.index()]
    }
}

impl fmt::Display for ParticleType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for ParticleType {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let lower = s.trim().to_ascii_lowercase();
        if let Ok(n) = lower.parse::<u8>()
            && usize::from(n) < Self::NAMES.len()
        {
            return Ok(ParticleType(n));
        }
        Self::NAMES
            .iter()
            .position(|n| *n == lower)
            .map(|i| ParticleType(i as u8))
            .ok_or_else(|| {
                format!(
                    "unknown particle type '{s}'; use 0..5 or one of: {}",
                    Self::NAMES.join(", ")
                )
            })
    }
}

impl TryFrom<String> for ParticleType {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<ParticleType> for String {
    fn from(t: ParticleType) -> String {
        t.name().to_owned()
    }
}

/// Options for formats whose files hold a choice of data (HDF5 snapshots); the other
/// formats ignore them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ReadOptions {
    /// The particle type read (default gas).
    #[serde(default)]
    pub particle_type: ParticleType,
    /// Positions, smoothing lengths and every dataset with a known scale-factor exponent in
    /// physical units (multiplied by a^exponent) instead of the file's comoving ones.
    #[serde(default)]
    pub physical: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn particle_types_by_number_or_name() {
        assert_eq!("gas".parse::<ParticleType>(), Ok(ParticleType::GAS));
        assert_eq!("4".parse::<ParticleType>().unwrap().name(), "stars");
        assert_eq!("BH".parse::<ParticleType>().unwrap().group(), "PartType5");
        assert_eq!("dm".parse::<ParticleType>().unwrap().index(), 1);
        let e = "6".parse::<ParticleType>().unwrap_err();
        assert!(e.contains("0..5") && e.contains("bulge"), "{e}");
        assert!("halo".parse::<ParticleType>().is_err());
    }
}
