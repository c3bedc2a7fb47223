//! 3D Hilbert keys (Skilling, "Programming the Hilbert curve", AIP Conf. Proc. 707, 2004).
//!
//! Positions are quantised to 21 bits per axis over the series' bounds (so the order of a step
//! does not depend on which other particles it holds), giving 63-bit keys. The quantiser works
//! on f32 local coordinates ([`HilbertQuantizer`]), so a GPU that holds only those computes
//! the same keys and order bit for bit (`shaders_wgsl/hilbert_keys.wgsl`).

use glam::DVec3;
use rayon::prelude::*;

use crate::values::Bounds;

pub use crate::values::shader_constants::{HILBERT_BITS, HILBERT_STEP};

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

/// Maps positions in a box to integer cells of the Hilbert grid, through f32 local
/// coordinates: a position is made relative to the box's centre in f64 and rounded to f32
/// (exactly what the GPU backends upload, `backend::gpu_data`), and the cell is
/// `(local - lo) · scale` in f32 arithmetic, clamped and truncated. Two correctly rounded f32
/// operations are what every GPU computes bit for bit (WGSL and Vulkan require subtraction and
/// multiplication to be correctly rounded), so a device that holds only the f32 local
/// coordinates computes the same keys as the CPU (`shaders_wgsl/hilbert_keys.wgsl`). The f32
/// rounding moves a coordinate by at most 1/16 of a cell (2^-24 of the half extent against
/// 2^-21 of the extent), which only decides ties between neighbouring cells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HilbertQuantizer {
    origin: DVec3,
    lo: [f32; 3],
    scale: [f32; 3],
}

impl HilbertQuantizer {
    /// The quantiser over `bounds` (the series' bounds, so keys do not depend on which particles a
    /// step holds): local coordinates relative to its centre, 2^[`HILBERT_BITS`] cells per axis
    /// across its extent.
    pub fn new(bounds: Bounds) -> HilbertQuantizer {
        let cells = f64::from(1u32 << HILBERT_BITS);
        let extent = bounds.extent();
        let origin = bounds.center();
        let lo = if bounds.is_empty() {
            DVec3::ZERO
        } else {
            bounds.min - origin
        };
        let scale = |e: f64| if e > 0.0 { (cells / e) as f32 } else { 0.0 };
        HilbertQuantizer {
            origin,
            lo: [lo.x as f32, lo.y as f32, lo.z as f32],
            scale: [scale(extent.x), scale(extent.y), scale(extent.z)],
        }
    }

    /// The origin of local coordinates: the box's centre (0 for an empty box).
    pub fn origin(&self) -> DVec3 {
        self.origin
    }

    /// The grid's lower corner in local coordinates, and its cells per unit length (0 on an
    /// axis of zero extent): what the key kernel is given.
    pub fn lo(&self) -> [f32; 3] {
        self.lo
    }

    /// Cells per unit length on each axis, in f32 (0 on an axis of zero extent).
    pub fn scale(&self) -> [f32; 3] {
        self.scale
    }

    /// `p`'s local coordinates: `p - origin` in f64, rounded to f32.
    #[inline]
    pub fn local(&self, p: DVec3) -> [f32; 3] {
        let l = p - self.origin;
        [l.x as f32, l.y as f32, l.z as f32]
    }

    /// The cell of a point with local coordinates `l`.
    #[inline]
    pub fn cell_of_local(&self, l: [f32; 3]) -> [u32; 3] {
        let max = ((1u32 << HILBERT_BITS) - 1) as f32;
        // Per component (glam's vector clamp checks its bounds on every call in checked
        // builds, which cost as much as the key).
        std::array::from_fn(|i| ((l[i] - self.lo[i]) * self.scale[i]).clamp(0.0, max) as u32)
    }

    /// The Hilbert grid cell of position `p` (world coordinates), each axis in `0..2^HILBERT_BITS`.
    #[inline]
    pub fn cell(&self, p: DVec3) -> [u32; 3] {
        self.cell_of_local(self.local(p))
    }

    /// The 63-bit Hilbert key of position `p` (world coordinates).
    #[inline]
    pub fn key(&self, p: DVec3) -> u64 {
        hilbert_key(self.cell(p), HILBERT_BITS)
    }

    /// The key of a point with local coordinates `l`.
    #[inline]
    pub fn key_of_local(&self, l: [f32; 3]) -> u64 {
        hilbert_key(self.cell_of_local(l), HILBERT_BITS)
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
