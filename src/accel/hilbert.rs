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
///
/// Skilling's transform, written without branches (each conditional exchange is a mask) and
/// with the bits interleaved by magic-number spreading: this runs once per particle per step,
/// and is most of the CPU's work on a step change.
#[inline]
pub fn hilbert_key(q: [u32; 3], bits: u32) -> u64 {
    debug_assert!((1..=21).contains(&bits));
    let [mut x0, mut x1, mut x2] = q;
    // Inverse undo of the rotations, from the top bit down.
    let mut level = bits - 1;
    while level > 0 {
        let p = (1u32 << level) - 1;
        // i = 0: x0's own bit set inverts its low bits; clear, it exchanges with itself.
        x0 ^= p & ((x0 >> level) & 1).wrapping_neg();
        for xi in [&mut x1, &mut x2] {
            let set = ((*xi >> level) & 1).wrapping_neg();
            let t = (x0 ^ *xi) & p & !set;
            x0 ^= (p & set) | t;
            *xi ^= t;
        }
        level -= 1;
    }
    // Gray encode.
    x1 ^= x0;
    x2 ^= x1;
    let mut t = 0u32;
    let mut level = bits - 1;
    while level > 0 {
        t ^= ((1u32 << level) - 1) & ((x2 >> level) & 1).wrapping_neg();
        level -= 1;
    }
    x0 ^= t;
    x1 ^= t;
    x2 ^= t;
    // Interleave, most significant first: bit b of x0 goes to 3b + 2, of x1 to 3b + 1, of x2
    // to 3b.
    (spread_by_3(x0) << 2) | (spread_by_3(x1) << 1) | spread_by_3(x2)
}

/// Moves bit b of the low 21 bits of `v` to bit 3b.
#[inline]
fn spread_by_3(v: u32) -> u64 {
    let mut x = u64::from(v) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
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
    // Sorting (key, index) pairs keeps each comparison in cache (sorting indices by a key
    // looked up through them does not); the pairs are unique, so an unstable sort gives the
    // stable order.
    let mut pairs: Vec<(u64, u32)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, &p)| (quantizer.key(p), i as u32))
        .collect();
    pairs.par_sort_unstable();
    pairs.into_par_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Skilling's transform as he wrote it (branches, a bit-by-bit interleave): the oracle
    /// of the branchless [`hilbert_key`].
    fn skilling_key(q: [u32; 3], bits: u32) -> u64 {
        let mut x = q;
        let m = 1u32 << (bits - 1);
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
        let mut key = 0u64;
        for bit in (0..bits).rev() {
            for v in x {
                key = (key << 1) | u64::from((v >> bit) & 1);
            }
        }
        key
    }

    #[test]
    fn the_branchless_key_equals_skillings_on_random_cells_of_every_depth() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for bits in 1..=21u32 {
            for _ in 0..20_000 {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let mask = (1u32 << bits) - 1;
                let q = [
                    s as u32 & mask,
                    (s >> 21) as u32 & mask,
                    (s >> 42) as u32 & mask,
                ];
                assert_eq!(
                    hilbert_key(q, bits),
                    skilling_key(q, bits),
                    "{q:?} at {bits} bits"
                );
            }
            let top = [(1u32 << bits) - 1; 3];
            assert_eq!(hilbert_key(top, bits), skilling_key(top, bits));
        }
    }

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
