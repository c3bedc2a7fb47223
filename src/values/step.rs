//! One time step of particles, as it lives in memory: in f64, whatever the file held, so data
//! written in double precision keeps every digit (f32 files convert exactly).

use glam::DVec3;

use super::Bounds;

/// A named per-particle scalar array.
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    /// The attribute's name as the file spells it.
    pub name: String,
    /// One value per particle, in the step's particle order.
    pub values: Vec<f64>,
}

/// One time step: positions and any number of named attributes, all of equal length.
///
/// A per-particle radius (smoothing length) is one of the attributes, chosen by name where the
/// field is set up, so a file's `h` or `radius` array needs no special treatment while reading.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// A name for messages: the file name, or the step name in a `.particles` header.
    pub name: String,
    /// Particle positions, data units.
    pub positions: Vec<DVec3>,
    /// Per-particle attributes, each as long as `positions`.
    pub attributes: Vec<Attribute>,
}

impl Step {
    /// Particles in the step.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether it has no particles.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The attribute called `name`, if the step has it.
    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// The attributes' names, in order.
    pub fn attribute_names(&self) -> Vec<&str> {
        self.attributes.iter().map(|a| a.name.as_str()).collect()
    }

    /// The smallest box holding every position.
    pub fn bounds(&self) -> Bounds {
        Bounds::of_points(&self.positions)
    }

    /// Bytes this step occupies in memory (what the cache counts).
    pub fn bytes(&self) -> usize {
        self.positions.len() * std::mem::size_of::<DVec3>()
            + self
                .attributes
                .iter()
                .map(|a| a.values.len() * std::mem::size_of::<f64>())
                .sum::<usize>()
    }
}

/// Minimum and maximum of `values` (ignoring nothing: callers pass finite data).
pub fn value_range(values: &[f64]) -> Option<(f64, f64)> {
    values.iter().fold(None, |acc, &v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}
