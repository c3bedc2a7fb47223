//! Axis-aligned boxes in the data's coordinates, in f64 (the precision positions keep).

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the data's coordinates. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    pub min: DVec3,
    pub max: DVec3,
}

impl Bounds {
    pub const EMPTY: Bounds = Bounds {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    pub fn of_points(points: &[DVec3]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, &p| b.grown_by(p))
    }

    pub fn grown_by(self, p: DVec3) -> Bounds {
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
            self.max - self.min
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
            (self.min + self.max) * 0.5
        }
    }

    /// The box grown by `margin` on every side (an empty box stays empty).
    pub fn grown(self, margin: f64) -> Bounds {
        if self.is_empty() {
            self
        } else {
            Bounds {
                min: self.min - DVec3::splat(margin),
                max: self.max + DVec3::splat(margin),
            }
        }
    }
}
