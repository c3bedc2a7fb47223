//! One time step of particles, as it lives in memory.

use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the data's coordinates. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    pub const EMPTY: Bounds = Bounds {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn of_points(points: &[Vec3]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, &p| b.grown_by(p))
    }

    pub fn grown_by(self, p: Vec3) -> Bounds {
        Bounds {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    pub fn union(self, other: Bounds) -> Bounds {
        Bounds {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn extent(&self) -> DVec3 {
        if self.is_empty() {
            DVec3::ZERO
        } else {
            self.max.as_dvec3() - self.min.as_dvec3()
        }
    }

    pub fn diagonal(&self) -> f64 {
        self.extent().length()
    }

    /// The centre (the origin for an empty box).
    pub fn center(&self) -> DVec3 {
        if self.is_empty() {
            DVec3::ZERO
        } else {
            (self.min.as_dvec3() + self.max.as_dvec3()) * 0.5
        }
    }
}

/// A named per-particle scalar array.
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    pub name: String,
    pub values: Vec<f32>,
}

/// One time step: positions and any number of named f32 attributes, all of equal length.
///
/// A per-particle radius (smoothing length) is one of the attributes, chosen by name where the
/// field is set up, so a file's `h` or `radius` array needs no special treatment while reading.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// A name for messages: the file name, or the step name in a `.particles` header.
    pub name: String,
    pub positions: Vec<Vec3>,
    pub attributes: Vec<Attribute>,
}

impl Step {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    pub fn attribute_names(&self) -> Vec<&str> {
        self.attributes.iter().map(|a| a.name.as_str()).collect()
    }

    pub fn bounds(&self) -> Bounds {
        Bounds::of_points(&self.positions)
    }

    /// Bytes this step occupies in memory (what the cache counts).
    pub fn bytes(&self) -> usize {
        self.positions.len() * std::mem::size_of::<Vec3>()
            + self
                .attributes
                .iter()
                .map(|a| a.values.len() * 4)
                .sum::<usize>()
    }
}

/// Minimum and maximum of `values` (ignoring nothing: callers pass finite data).
pub fn value_range(values: &[f32]) -> Option<(f32, f32)> {
    values.iter().fold(None, |acc, &v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}
