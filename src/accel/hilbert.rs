//! 3D Hilbert keys (Skilling, "Programming the Hilbert curve", AIP Conf. Proc. 707, 2004).
//!
//! Positions are quantised to 21 bits per axis over the series' bounds (so the order of a step
//! does not depend on which other particles it holds), giving 63-bit keys.

use glam::DVec3;
use rayon::prelude::*;

use crate::values::Bounds;

/// Bits per axis of the keys we sort by.
pub const HILBERT_BITS: u32 = 21;

/// The Hilbert index of integer coordinates `q` (each below 2^bits) on a curve of `bits` bits
/// per axis; consecutive indices are face-adjacent cells.
pub fn hilbert_key(q: [u32; 3], bits: u32) -> u64 {
    debug_assert!((1..=21).contains(&bits));
    let mut x = q;
    let m = 1u32 << (bits - 1);
    // Inverse undo of the rotations, from the top bit down.
    let mut b = m;
    while b > 1 {
        let p = b - 1;
        for i in 0..3 {
            if x[i] & b != 0 {
                x[0] ^= p;
            } else {
                let t = (x[0] ^ x[i]) & p;
                x[0] ^= t;
                x[i] ^= t;
            }
        }
        b >>= 1;
    }
    // Gray encode.
    x[1] ^= x[0];
    x[2] ^= x[1];
    let mut t = 0;
    let mut b = m;
    while b > 1 {
        if x[2] & b != 0 {
            t ^= b - 1;
        }
        b >>= 1;
    }
    for v in &mut x {
        *v ^= t;
    }
    // Interleave the transposed bits, most significant first.
    let mut key = 0u64;
    for bit in (0..bits).rev() {
        for v in x {
            key = (key << 1) | u64::from((v >> bit) & 1);
        }
    }
    key
}

/// Maps positions in a box to integer cells of the Hilbert grid.
#[derive(Clone, Copy, Debug)]
pub struct HilbertQuantizer {
    min: DVec3,
    scale: DVec3,
}

impl HilbertQuantizer {
    pub fn new(bounds: Bounds) -> HilbertQuantizer {
        let cells = f64::from(1u32 << HILBERT_BITS);
        let extent = bounds.extent();
        let scale = DVec3::select(extent.cmpgt(DVec3::ZERO), cells / extent, DVec3::ZERO);
        HilbertQuantizer {
            min: if bounds.is_empty() {
                DVec3::ZERO
            } else {
                bounds.min
            },
            scale,
        }
    }

    pub fn cell(&self, p: DVec3) -> [u32; 3] {
        let max = f64::from((1u32 << HILBERT_BITS) - 1);
        let q = ((p - self.min) * self.scale).clamp(DVec3::ZERO, DVec3::splat(max));
        [q.x as u32, q.y as u32, q.z as u32]
    }

    pub fn key(&self, p: DVec3) -> u64 {
        hilbert_key(self.cell(p), HILBERT_BITS)
    }
}

/// The stable order of `positions` along the Hilbert curve over `bounds`: `order[k]` is the
/// index of the k-th particle on the curve. Ties keep their input order.
pub fn hilbert_order(positions: &[DVec3], bounds: Bounds) -> Vec<u32> {
    let quantizer = HilbertQuantizer::new(bounds);
    let keys: Vec<u64> = positions.par_iter().map(|&p| quantizer.key(p)).collect();
    let mut order: Vec<u32> = (0..positions.len() as u32).collect();
    order.par_sort_by_key(|&i| keys[i as usize]);
    order
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curve_visits_every_cell_once_moving_to_a_neighbour_each_step() {
        for bits in 1..=4u32 {
            let side = 1u32 << bits;
            let mut cells = vec![[0u32; 3]; (side * side * side) as usize];
            for x in 0..side {
                for y in 0..side {
                    for z in 0..side {
                        let k = hilbert_key([x, y, z], bits) as usize;
                        assert!(k < cells.len());
                        cells[k] = [x + 1, y + 1, z + 1]; // +1 marks it visited
                    }
                }
            }
            assert!(
                cells.iter().all(|c| c[0] > 0),
                "every key used once (bits {bits})"
            );
            for w in cells.windows(2) {
                let d: u32 = (0..3).map(|i| w[0][i].abs_diff(w[1][i])).sum();
                assert_eq!(d, 1, "consecutive keys are neighbours (bits {bits})");
            }
        }
    }

    #[test]
    fn order_is_stable_and_a_permutation() {
        let p = vec![
            DVec3::ONE,
            DVec3::ZERO,
            DVec3::ONE,
            DVec3::ZERO,
            DVec3::splat(0.5),
        ];
        let b = Bounds::of_points(&p);
        let order = hilbert_order(&p, b);
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(sorted, vec![0, 1, 2, 3, 4]);
        let pos = |i: u32| order.iter().position(|&o| o == i).unwrap();
        assert!(
            pos(1) < pos(3) && pos(0) < pos(2),
            "equal keys keep input order"
        );
    }
}
