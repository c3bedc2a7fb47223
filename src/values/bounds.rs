//! Axis-aligned boxes in the data's coordinates, in f64 (the precision positions keep).

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// An axis-aligned box in the data's coordinates. An empty box has `min > max`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// The least corner.
    pub min: DVec3,
    /// The largest corner.
    pub max: DVec3,
}

impl Bounds {
    /// The box holding no point (`min` +∞, `max` -∞): the identity of [`Bounds::union`].
    pub const EMPTY: Bounds = Bounds {
        min: DVec3::splat(f64::INFINITY),
        max: DVec3::splat(f64::NEG_INFINITY),
    };

    /// The smallest box holding every point (empty for none).
    pub fn of_points(points: &[DVec3]) -> Bounds {
        points.iter().fold(Bounds::EMPTY, |b, &p| b.grown_by(p))
    }

    /// The smallest box holding this one and `p`.
    pub fn grown_by(self, p: DVec3) -> Bounds {
        Bounds {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    pub fn union(self, other: Bounds) -> Bounds {
        Bounds {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// Whether it holds no point (`min > max` on some axis).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// The side lengths (zero for an empty box).
    pub fn extent(&self) -> DVec3 {
        if self.is_empty() {
            DVec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// The length of its diagonal (0 for an empty box).
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
