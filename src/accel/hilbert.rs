//! 3D Hilbert keys (Skilling, "Programming the Hilbert curve", AIP Conf. Proc. 707, 2004).
//!
//! Positions are quantised to 21 bits per axis over the series' bounds (so the order of a step
//! does not depend on which other particles it holds), giving 63-bit keys.

use glam::DVec3;
use rayon::prelude::*;

use crate::values::Bounds;

/// Bits per axis of the keys we sort by.
pub const HILBERT_BITS: u32 = 21;

/// The Hilbert curve as a state machine over the 24 orientations a sub-cube's curve can
/// have: `HILBERT_STEP[8 s + o]` for orientation `s` and octant `o` (x·4 + y·2 + z, one bit of
/// each coordinate) is `digit | next << 3`, the octant's 3-bit place along the curve and the
/// orientation of the curve inside it. It is Skilling's curve exactly (the tests derive this
/// table from his transform and compare keys at every depth): one lookup per level replaces his
/// twenty-odd exchanges.
pub const HILBERT_STEP: [u8; 192] = [
    8, 17, 27, 2, 39, 46, 52, 5, 56, 71, 73, 86, 91, 20, 10, 13, 48, 1, 103, 110, 115, 18, 12, 21,
    126, 129, 29, 26, 79, 80, 140, 3, 148, 43, 37, 34, 127, 128, 78, 81, 156, 45, 35, 42, 31, 6,
    160, 105, 72, 87, 139, 4, 57, 70, 50, 53, 0, 171, 111, 76, 49, 58, 102, 61, 180, 143, 83, 184,
    69, 54, 66, 97, 16, 123, 9, 74, 47, 60, 38, 77, 132, 95, 85, 14, 67, 144, 82, 33, 142, 55, 185,
    96, 93, 116, 90, 11, 188, 107, 175, 176, 101, 98, 62, 65, 164, 109, 119, 22, 99, 106, 152, 41,
    174, 177, 63, 64, 117, 114, 92, 19, 30, 125, 161, 122, 7, 172, 104, 75, 130, 25, 133, 166, 179,
    136, 84, 191, 94, 15, 141, 28, 145, 32, 138, 51, 146, 155, 149, 36, 137, 24, 190, 167, 154,
    157, 147, 44, 169, 182, 120, 135, 162, 165, 121, 134, 187, 108, 168, 183, 118, 173, 23, 124,
    153, 170, 40, 59, 178, 113, 131, 88, 181, 158, 68, 151, 186, 163, 89, 112, 189, 100, 150, 159,
];

/// Two levels per lookup: `HILBERT_STEP2[64 s + 8 o_hi + o_lo]` is `digits | next << 6`.
const HILBERT_STEP2: [u16; 1536] = two_levels();

const fn two_levels() -> [u16; 1536] {
    let mut out = [0u16; 1536];
    let mut i = 0;
    while i < 1536 {
        let (s, hi, lo) = (i / 64, (i / 8) % 8, i % 8);
        let first = HILBERT_STEP[s * 8 + hi];
        let second = HILBERT_STEP[(first >> 3) as usize * 8 + lo];
        out[i] = ((first & 7) as u16) << 3 | (second & 7) as u16 | ((second >> 3) as u16) << 6;
        i += 1;
    }
    out
}

/// The Hilbert index of integer coordinates `q` (each below 2^bits) on a curve of `bits` bits
/// per axis; consecutive indices are face-adjacent cells.
///
/// The coordinates' bits are interleaved by magic-number spreading (a Morton code), then the
/// Morton digits are walked two levels at a time through [`HILBERT_STEP`]'s state machine:
/// this runs once per particle per step, and was most of the CPU's work on a step change.
#[inline]
pub fn hilbert_key(q: [u32; 3], bits: u32) -> u64 {
    debug_assert!((1..=21).contains(&bits));
    let morton = (spread_by_3(q[0]) << 2) | (spread_by_3(q[1]) << 1) | spread_by_3(q[2]);
    let mut level = bits;
    let (mut key, mut state) = (0u64, 0usize);
    if level % 2 == 1 {
        level -= 1;
        let e = HILBERT_STEP[((morton >> (3 * level)) & 7) as usize];
        key = u64::from(e & 7);
        state = usize::from(e >> 3);
    }
    while level >= 2 {
        level -= 2;
        let e = HILBERT_STEP2[state * 64 + ((morton >> (3 * level)) & 63) as usize];
        key = (key << 6) | u64::from(e & 63);
        state = usize::from(e >> 6);
    }
    key
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

    #[inline]
    pub fn cell(&self, p: DVec3) -> [u32; 3] {
        let max = f64::from((1u32 << HILBERT_BITS) - 1);
        let q = (p - self.min) * self.scale;
        // Per component (glam's vector clamp checks its bounds on every call in checked
        // builds, which cost as much as the key).
        [q.x, q.y, q.z].map(|v| v.clamp(0.0, max) as u32)
    }

    #[inline]
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
    /// of the table-driven [`hilbert_key`].
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

    /// A signed permutation of the axes acting on cells of side 2^level: axis i of the result
    /// is axis `perm[i]` of the input, mirrored where `flip[i]`.
    #[derive(Clone, Copy, PartialEq, Debug)]
    struct Orientation {
        perm: [usize; 3],
        flip: [bool; 3],
    }

    impl Orientation {
        const IDENTITY: Orientation = Orientation {
            perm: [0, 1, 2],
            flip: [false; 3],
        };

        fn all() -> Vec<Orientation> {
            let perms = [
                [0, 1, 2],
                [0, 2, 1],
                [1, 0, 2],
                [1, 2, 0],
                [2, 0, 1],
                [2, 1, 0],
            ];
            perms
                .iter()
                .flat_map(|&perm| {
                    (0..8).map(move |f| Orientation {
                        perm,
                        flip: [f & 4 != 0, f & 2 != 0, f & 1 != 0],
                    })
                })
                .collect()
        }

        fn apply(self, q: [u32; 3], level: u32) -> [u32; 3] {
            let mask = (1u32 << level) - 1;
            [0, 1, 2].map(|i| q[self.perm[i]] ^ if self.flip[i] { mask } else { 0 })
        }

        /// `self` after `inner`: q ↦ self(inner(q)).
        fn after(self, inner: Orientation) -> Orientation {
            Orientation {
                perm: [0, 1, 2].map(|i| inner.perm[self.perm[i]]),
                flip: [0, 1, 2].map(|i| inner.flip[self.perm[i]] ^ self.flip[i]),
            }
        }
    }

    fn octant_cell(o: usize) -> [u32; 3] {
        [(o >> 2) as u32 & 1, (o >> 1) as u32 & 1, o as u32 & 1]
    }

    /// Derives the state machine from Skilling's transform alone: the curve inside each octant
    /// of a 3-level curve is the 2-level curve in some orientation (found by trying all 48),
    /// and walking orientations from the identity gives the states. The table the code uses
    /// must be exactly this.
    #[test]
    fn the_state_table_is_derived_from_skillings_curve() {
        let children: Vec<(u64, Orientation)> = (0..8)
            .map(|o| {
                let hi = octant_cell(o).map(|b| b << 2);
                let cells: Vec<[u32; 3]> =
                    (0..64u32).map(|c| [c >> 4, (c >> 2) & 3, c & 3]).collect();
                let child = Orientation::all()
                    .into_iter()
                    .find(|t| {
                        cells.iter().all(|&c| {
                            let q = [0, 1, 2].map(|i| hi[i] | c[i]);
                            skilling_key(q, 3) & 63 == skilling_key(t.apply(c, 2), 2)
                        })
                    })
                    .expect("each octant holds an oriented copy of the curve");
                (skilling_key(hi, 3) >> 6, child)
            })
            .collect();
        let mut states = vec![Orientation::IDENTITY];
        let mut table = Vec::new();
        let mut s = 0;
        while s < states.len() {
            let state = states[s];
            for o in 0..8 {
                let turned = state.apply(octant_cell(o), 1);
                let (digit, child) =
                    children[((turned[0] << 2) | (turned[1] << 1) | turned[2]) as usize];
                let next = child.after(state);
                let index = states.iter().position(|&t| t == next).unwrap_or_else(|| {
                    states.push(next);
                    states.len() - 1
                });
                table.push(digit as u8 | (index as u8) << 3);
            }
            s += 1;
        }
        assert_eq!(states.len(), 24);
        assert_eq!(table, HILBERT_STEP);
    }

    #[test]
    fn the_table_key_equals_skillings_on_random_cells_of_every_depth() {
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
