//! Morton keys of cluster boxes (stage 2; `lbvh_keys.wgsl` on the GPU).

use glam::DVec3;

use super::boxes::{GpuBox, box_is_empty};
use crate::values::Bounds;
use crate::values::shader_constants::{LBVH_EMPTY_KEY, MORTON_CELLS};

/// The Morton grid over the series' bounds, in local coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyGrid {
    /// The grid's lower corner (local coordinates).
    pub lo: [f32; 3],
    /// Cells per unit length on each axis (0 on an axis of zero extent).
    pub scale: [f32; 3],
}

impl KeyGrid {
    /// The grid over `series_bounds`, with local coordinates relative to `origin`.
    pub fn new(series_bounds: Bounds, origin: DVec3) -> KeyGrid {
        let extent = series_bounds.extent();
        let lo = if series_bounds.is_empty() {
            DVec3::ZERO
        } else {
            series_bounds.min - origin
        };
        let scale = |e: f64| {
            if e > 0.0 {
                (f64::from(MORTON_CELLS) / e) as f32
            } else {
                0.0
            }
        };
        KeyGrid {
            lo: [lo.x as f32, lo.y as f32, lo.z as f32],
            scale: [scale(extent.x), scale(extent.y), scale(extent.z)],
        }
    }
}

/// Spreads the low 10 bits of `v` to every third bit.
pub fn expand_bits(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00FF;
    x = (x | (x << 8)) & 0x0300_F00F;
    x = (x | (x << 4)) & 0x030C_30C3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// Stage 2: a cluster's key.
pub fn morton_key(b: &GpuBox, grid: &KeyGrid) -> u32 {
    if box_is_empty(b) {
        return LBVH_EMPTY_KEY;
    }
    let max = (MORTON_CELLS - 1) as f32;
    let q: [u32; 3] = std::array::from_fn(|i| {
        let centre = (b[0][i] + b[1][i]) * 0.5;
        ((centre - grid.lo[i]) * grid.scale[i]).clamp(0.0, max) as u32
    });
    (expand_bits(q[0]) << 2) | (expand_bits(q[1]) << 1) | expand_bits(q[2])
}

/// Stage 2 over every cluster: `keys[c]` is [`morton_key`] of `boxes[c]`.
pub fn morton_keys(boxes: &[GpuBox], grid: &KeyGrid) -> Vec<u32> {
    boxes.iter().map(|b| morton_key(b, grid)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::lbvh::EMPTY_BOX;

    #[test]
    fn morton_keys_interleave_x_highest() {
        assert_eq!(expand_bits(0x3ff), 0x0924_9249);
        let b = |x: f32, y: f32, z: f32| [[x, y, z, 0.0], [x, y, z, 0.0]];
        let g = KeyGrid {
            lo: [0.0; 3],
            scale: [1.0; 3],
        };
        assert_eq!(morton_key(&b(1.0, 0.0, 0.0), &g), 0b100);
        assert_eq!(morton_key(&b(0.0, 1.0, 0.0), &g), 0b010);
        assert_eq!(morton_key(&b(0.0, 0.0, 1.0), &g), 0b001);
        assert_eq!(morton_key(&b(5000.0, -3.0, 2.0), &g) >> 2 & 1, 1);
        assert_eq!(morton_key(&EMPTY_BOX, &g), LBVH_EMPTY_KEY);
    }
}
