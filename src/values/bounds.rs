//! Axis-aligned boxes in the data's coordinates.

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
