//! The parts of space and of the screen a partial frame covers: a half-open box of space (the
//! samples a rank of a distributed render owns) and a rectangle of pixels (the part of the
//! image its box can touch).

use glam::DVec3;

use super::Bounds;

/// The points `x` with `lo <= x < hi` on every axis. Faces may be infinite, so that boxes
/// which tile space leave no point unowned: every point lies in exactly one box of a tiling
/// whose boxes share faces, because each shared face belongs to the box above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalfOpenBox {
    /// The least corner, on the box (may be -∞).
    pub lo: DVec3,
    /// The largest corner, just outside the box (may be +∞).
    pub hi: DVec3,
}

impl HalfOpenBox {
    /// All of space.
    pub const EVERYWHERE: HalfOpenBox = HalfOpenBox {
        lo: DVec3::splat(f64::NEG_INFINITY),
        hi: DVec3::splat(f64::INFINITY),
    };

    /// Whether `x` lies in the box (`lo <= x < hi` on every axis).
    pub fn contains(&self, x: DVec3) -> bool {
        x.cmpge(self.lo).all() && x.cmplt(self.hi).all()
    }

    /// The closed box's part within `bounds` (finite where `bounds` is), empty if they do not
    /// meet.
    pub fn clipped_to(&self, bounds: Bounds) -> Bounds {
        Bounds {
            min: self.lo.max(bounds.min),
            max: self.hi.min(bounds.max),
        }
    }

    /// The squared distance from `x` to the closed box (0 inside it).
    pub fn distance_squared(&self, x: DVec3) -> f64 {
        let below = (self.lo - x).max(DVec3::ZERO);
        let above = (x - self.hi).max(DVec3::ZERO);
        (below + above).length_squared()
    }
}

/// The pixels `(x, y)` with `x0 <= x < x1` and `y0 <= y < y1`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct PixelRect {
    /// The first column.
    pub x0: u32,
    /// The first row.
    pub y0: u32,
    /// One past the last column.
    pub x1: u32,
    /// One past the last row.
    pub y1: u32,
}

impl PixelRect {
    /// The whole of a `width` x `height` image.
    pub fn full(width: u32, height: u32) -> PixelRect {
        PixelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// Columns it spans (0 where `x1 <= x0`).
    pub fn width(&self) -> u32 {
        self.x1.saturating_sub(self.x0)
    }

    /// Rows it spans (0 where `y1 <= y0`).
    pub fn height(&self) -> u32 {
        self.y1.saturating_sub(self.y0)
    }

    /// Whether it holds no pixel.
    pub fn is_empty(&self) -> bool {
        self.width() == 0 || self.height() == 0
    }

    /// Pixels it holds.
    pub fn len(&self) -> usize {
        self.width() as usize * self.height() as usize
    }

    /// The pixels in both (empty if they do not meet).
    pub fn intersection(&self, other: &PixelRect) -> PixelRect {
        let r = PixelRect {
            x0: self.x0.max(other.x0),
            y0: self.y0.max(other.y0),
            x1: self.x1.min(other.x1),
            y1: self.y1.min(other.y1),
        };
        if r.is_empty() {
            PixelRect::default()
        } else {
            r
        }
    }

    /// The least rectangle holding both (the other where one is empty).
    pub fn around(&self, other: &PixelRect) -> PixelRect {
        if self.is_empty() {
            return *other;
        }
        if other.is_empty() {
            return *self;
        }
        PixelRect {
            x0: self.x0.min(other.x0),
            y0: self.y0.min(other.y0),
            x1: self.x1.max(other.x1),
            y1: self.y1.max(other.y1),
        }
    }

    /// Whether it holds pixel `(x, y)`.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// Its pixels `(x, y)`, row-major.
    pub fn pixels(self) -> impl Iterator<Item = (u32, u32)> {
        (self.y0..self.y1).flat_map(move |y| (self.x0..self.x1).map(move |x| (x, y)))
    }

    /// The index of pixel (x, y) in the rectangle's row-major pixels.
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y - self.y0) as usize * self.width() as usize + (x - self.x0) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn neighbouring_boxes_share_no_point_of_their_common_face() {
        let below = HalfOpenBox {
            lo: DVec3::splat(f64::NEG_INFINITY),
            hi: DVec3::new(0.5, f64::INFINITY, f64::INFINITY),
        };
        let above = HalfOpenBox {
            lo: DVec3::new(0.5, f64::NEG_INFINITY, f64::NEG_INFINITY),
            hi: DVec3::splat(f64::INFINITY),
        };
        for x in [
            0.5 - 1e-17,
            0.5f64.next_down(),
            0.5,
            0.5f64.next_up(),
            -1e300,
            1e300,
        ] {
            let p = DVec3::new(x, 3.0, -7.0);
            assert_eq!(
                u32::from(below.contains(p)) + u32::from(above.contains(p)),
                1,
                "{x}"
            );
        }
        assert_eq!(below.distance_squared(DVec3::new(1.5, 0.0, 0.0)), 1.0);
        assert_eq!(above.distance_squared(DVec3::new(1.5, 9.0, -9.0)), 0.0);
    }

    #[test]
    fn rectangles_intersect_to_their_common_pixels() {
        let a = PixelRect {
            x0: 2,
            y0: 3,
            x1: 10,
            y1: 8,
        };
        let b = PixelRect::full(5, 100);
        let c = a.intersection(&b);
        assert_eq!((c.x0, c.y0, c.x1, c.y1), (2, 3, 5, 8));
        assert_eq!(c.len(), 15);
        assert_eq!(c.index(4, 7), 4 * 3 + 2);
        assert!(a.intersection(&PixelRect::full(2, 2)).is_empty());
        let d = a.around(&PixelRect {
            x0: 12,
            y0: 1,
            x1: 13,
            y1: 4,
        });
        assert_eq!((d.x0, d.y0, d.x1, d.y1), (2, 1, 13, 8));
        assert_eq!(a.around(&PixelRect::default()), a);
        assert_eq!(PixelRect::default().around(&a), a);
    }
}
