//! The x86-64 builds' eight-lane pieces, in `core::arch` intrinsics: reach and distance tests,
//! the exponential, the packing of reached lanes, the sums held in f32 blocks and added in f64,
//! and the dense loop `benches/cpu_roofline.rs` takes as the machine's peak.

use super::*;

/// How far each of eight coordinates `v` lies outside `[lo, hi]` (0 inside): never more than
/// its distance to any point's coordinate in the interval, as rounded.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn box_gap(
    v: core::arch::x86_64::__m256,
    lo: core::arch::x86_64::__m256,
    hi: core::arch::x86_64::__m256,
    zero: core::arch::x86_64::__m256,
) -> core::arch::x86_64::__m256 {
    use core::arch::x86_64::*;
    // SAFETY: the caller vouches for the CPU.
    unsafe {
        let g = _mm256_max_ps(_mm256_sub_ps(lo, v), _mm256_sub_ps(v, hi));
        _mm256_max_ps(g, zero)
    }
}

/// The reach test of eight candidates (`index` below `end`, `d2 <= r2`) and their packing: the
/// reached lanes' squared distances written from `d2_at` (and their indices from `index_at`
/// where `gathers`: the terms gather by them), in lane order, by `vcompress` (`COMPRESS`) or by a
/// permutation from [`PACK`]: the same lanes either way. Returns how many. The point kernel's
/// and the group kernel's one definition.
///
/// # Safety
/// The CPU has AVX2 and POPCNT, and AVX-512 F and VL where `COMPRESS`; eight slots from
/// `d2_at` are writable, and from `index_at` where `gathers`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn pack_reached<const COMPRESS: bool>(
    d2: core::arch::x86_64::__m256,
    r2: core::arch::x86_64::__m256,
    index: core::arch::x86_64::__m256i,
    end: core::arch::x86_64::__m256i,
    gathers: bool,
    index_at: *mut core::arch::x86_64::__m256i,
    d2_at: *mut f32,
) -> u32 {
    use core::arch::x86_64::*;
    // SAFETY: the caller vouches for the CPU and the pointers; a table row holds eight lanes.
    unsafe {
        if COMPRESS {
            let live = _mm256_cmpgt_epi32_mask(end, index);
            let reached = _mm256_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, d2, r2);
            if gathers {
                _mm256_storeu_si256(index_at, _mm256_maskz_compress_epi32(reached, index));
            }
            _mm256_storeu_ps(d2_at, _mm256_maskz_compress_ps(reached, d2));
            reached.count_ones()
        } else {
            let live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(end, index));
            let reached = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(d2, r2), live);
            let mask = _mm256_movemask_ps(reached) as usize;
            let order = _mm256_loadu_si256(PACK[mask].as_ptr().cast());
            if gathers {
                _mm256_storeu_si256(index_at, _mm256_permutevar8x32_epi32(index, order));
            }
            _mm256_storeu_ps(d2_at, _mm256_permutevar8x32_ps(d2, order));
            mask.count_ones()
        }
    }
}

/// The point kernel's sums: Phi and the Theta numerator per channel, in eight f32 lanes for at
/// most [`LANE_TERMS`] terms a lane (a block), the blocks added in f64 (`flush`).
#[cfg(target_arch = "x86_64")]
pub(super) struct HeldSums {
    phi: core::arch::x86_64::__m256,
    num: [core::arch::x86_64::__m256; 3],
    /// Chunks of eight terms in the f32 lanes now.
    chunks: usize,
    total_phi: f64,
    total_num: [f64; 3],
}

#[cfg(target_arch = "x86_64")]
impl HeldSums {
    /// Nothing summed yet.
    #[inline(always)]
    pub(super) fn zero() -> HeldSums {
        // SAFETY: every caller enables AVX.
        let zero = unsafe { core::arch::x86_64::_mm256_setzero_ps() };
        HeldSums {
            phi: zero,
            num: [zero; 3],
            chunks: 0,
            total_phi: 0.0,
            total_num: [0.0; 3],
        }
    }

    /// Adds the f32 lanes to the f64 totals and empties them: a block ends.
    #[inline(always)]
    pub(super) fn flush<const C: usize>(&mut self) {
        // SAFETY: every caller enables AVX.
        let zero = unsafe { core::arch::x86_64::_mm256_setzero_ps() };
        self.total_phi += lane_total(self.phi);
        self.phi = zero;
        for ch in 0..C {
            self.total_num[ch] += lane_total(self.num[ch]);
            self.num[ch] = zero;
        }
        self.chunks = 0;
    }

    /// Phi and the first `C` channels' Theta numerators.
    #[inline(always)]
    pub(super) fn totals<const C: usize>(&mut self) -> (f64, [f64; 3]) {
        self.flush::<C>();
        (self.total_phi, self.total_num)
    }

    /// Adds the terms of held candidates `0..count`, eight at a time, the lanes past `count`
    /// masked (their indices read as 0: the slots may hold another call's). The indices are
    /// read only where the terms gather by them (see [`point_sums`]).
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; `count + LANES` is within `held_d2` (and `held_index` where
    /// it is read); every held index below `count` is below the length of every array
    /// gathered from.
    #[inline(always)]
    pub(super) unsafe fn add<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
        &mut self,
        p: &Packed,
        held_index: &[i32],
        held_d2: &[f32],
        count: usize,
        one_radius: OneRadius,
        same_w: f32,
    ) {
        use core::arch::x86_64::*;
        // SAFETY: the caller vouches for the CPU's features.
        let iota = unsafe { _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7) };
        let mut i = 0;
        while i < count {
            // SAFETY: i < count, so i + LANES is within the buffers; the caller vouches for
            // the indices and the CPU.
            unsafe {
                let live = _mm256_cmpgt_epi32(_mm256_set1_epi32((count - i) as i32), iota);
                let d2 = _mm256_loadu_ps(held_d2.as_ptr().add(i));
                // Read only where something is gathered (the held indices are not written
                // otherwise).
                let gather = |v: &Vec<f32>| {
                    let index = _mm256_loadu_si256(held_index.as_ptr().add(i).cast());
                    _mm256_i32gather_ps::<4>(v.as_ptr(), _mm256_and_si256(index, live))
                };
                // The same values either way: broadcast where every particle's are the same.
                let k = if ONE_RADIUS {
                    _mm256_set1_ps(one_radius.k)
                } else {
                    gather(&p.k)
                };
                let w = if SAME_W {
                    _mm256_set1_ps(same_w)
                } else {
                    gather(&p.w)
                };
                let x = _mm256_mul_ps(_mm256_sub_ps(_mm256_setzero_ps(), k), d2);
                let term =
                    _mm256_and_ps(_mm256_mul_ps(w, exp_neg_avx2(x)), _mm256_castsi256_ps(live));
                self.phi = _mm256_add_ps(self.phi, term);
                for (ch, acc) in self.num.iter_mut().enumerate().take(C) {
                    *acc = _mm256_fmadd_ps(gather(&p.theta[ch]), term, *acc);
                }
            }
            self.chunks += 1;
            if self.chunks == LANE_TERMS {
                self.flush::<C>();
            }
            i += LANES;
        }
    }
}

/// The sum of eight f32 lanes in f64, as [`lanes_total`] adds them: how every AVX2 kernel
/// ends. In pairs rather than lane after lane: three dependent additions instead of seven
/// (the one-by-one sum held a tenth of the group kernel's samples).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn lane_total(v: core::arch::x86_64::__m256) -> f64 {
    use core::arch::x86_64::*;
    // SAFETY: every caller enables AVX.
    unsafe {
        let halves = _mm256_add_pd(
            _mm256_cvtps_pd(_mm256_castps256_ps128(v)),
            _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)),
        );
        let pairs = _mm_add_pd(
            _mm256_castpd256_pd128(halves),
            _mm256_extractf128_pd::<1>(halves),
        );
        _mm_cvtsd_f64(_mm_add_sd(pairs, _mm_unpackhi_pd(pairs, pairs)))
    }
}

/// Eight floats of `v` from `at`, at any alignment.
///
/// # Safety
/// `at + LANES <= v.len()`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn lanes_at(v: &[f32], at: usize) -> core::arch::x86_64::__m256 {
    // A read through a packed (align 1) struct is an unaligned load with no check in builds
    // with debug assertions (`_mm256_loadu_ps` is a `copy_nonoverlapping`, which checks its
    // arguments there: the kernel ran at half speed in `checked`).
    // SAFETY: the caller keeps the eight floats within `v`.
    unsafe { (*(v.as_ptr().add(at) as *const Unaligned)).0 }
}

/// Particles `at..at + 8`: their squared distances from `q` (fused), and which of the `live`
/// lanes lie within their radius (`one_r2`, or each one's). The one reach test of the AVX2
/// point kernel and the dense loop (the AVX-512 point kernel compares [`distance2_avx2`]'s
/// pair into a mask register).
///
/// # Safety
/// Eight floats from `at` are in `p.x`, `p.y`, `p.z` and (without `one_r2`) `p.r2`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn reach_avx2(
    p: &Packed,
    at: usize,
    q: [core::arch::x86_64::__m256; 3],
    live: core::arch::x86_64::__m256,
    one_r2: Option<core::arch::x86_64::__m256>,
) -> (core::arch::x86_64::__m256, core::arch::x86_64::__m256) {
    use core::arch::x86_64::*;
    // SAFETY: the caller keeps eight floats from `at` within each array.
    let (d2, r2) = unsafe { distance2_avx2(p, at, q, one_r2) };
    let reached = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(d2, r2), live);
    (d2, reached)
}

/// Particles `at..at + 8`: their squared distances from `q` (fused), and their r²: `one_r2`
/// where every particle has it (one radius: its array is not read), or loaded.
///
/// # Safety
/// Eight floats from `at` are in `p.x`, `p.y`, `p.z` and (without `one_r2`) `p.r2`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn distance2_avx2(
    p: &Packed,
    at: usize,
    q: [core::arch::x86_64::__m256; 3],
    one_r2: Option<core::arch::x86_64::__m256>,
) -> (core::arch::x86_64::__m256, core::arch::x86_64::__m256) {
    // SAFETY: the caller keeps eight floats from `at` within each array.
    let (x, y, z, r2) = unsafe {
        (
            lanes_at(&p.x, at),
            lanes_at(&p.y, at),
            lanes_at(&p.z, at),
            one_r2.unwrap_or_else(|| lanes_at(&p.r2, at)),
        )
    };
    (distance2_from([x, y, z], q), r2)
}

/// The squared distances of eight particles at `xyz` from `q`, fused: the point test's one
/// definition (the point kernel's and the group kernel's).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) fn distance2_from(
    xyz: [core::arch::x86_64::__m256; 3],
    q: [core::arch::x86_64::__m256; 3],
) -> core::arch::x86_64::__m256 {
    use core::arch::x86_64::*;
    let (dx, dy, dz) = (
        _mm256_sub_ps(xyz[0], q[0]),
        _mm256_sub_ps(xyz[1], q[1]),
        _mm256_sub_ps(xyz[2], q[2]),
    );
    _mm256_fmadd_ps(dz, dz, _mm256_fmadd_ps(dy, dy, _mm256_mul_ps(dx, dx)))
}

/// Eight floats at any address.
#[cfg(target_arch = "x86_64")]
#[repr(C, packed)]
pub(super) struct Unaligned(core::arch::x86_64::__m256);

/// [`exp_neg`] on eight lanes with fused multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) fn exp_neg_avx2(x: core::arch::x86_64::__m256) -> core::arch::x86_64::__m256 {
    use core::arch::x86_64::*;
    let c = _mm256_set1_ps;
    let x = _mm256_max_ps(x, c(EXP_MIN));
    let round = c(EXP_ROUND);
    let shifted = _mm256_fmadd_ps(x, c(std::f32::consts::LOG2_E), round);
    let n = _mm256_sub_ps(shifted, round);
    let r = _mm256_fnmadd_ps(n, c(LN2_HI), x);
    let r = _mm256_fnmadd_ps(n, c(LN2_LO), r);
    let mut p = c(EXP_POLY[0]);
    for &k in &EXP_POLY[1..] {
        p = _mm256_fmadd_ps(p, r, c(k));
    }
    let e = _mm256_add_ps(_mm256_fmadd_ps(p, _mm256_mul_ps(r, r), r), c(1.0));
    let n_int = _mm256_sub_epi32(_mm256_castps_si256(shifted), _mm256_castps_si256(round));
    let scale = _mm256_slli_epi32::<23>(_mm256_add_epi32(n_int, _mm256_set1_epi32(127)));
    _mm256_mul_ps(e, _mm256_castsi256_ps(scale))
}

/// [`dense_sums`] with AVX-512 in sixteen lanes (a run's last lanes masked): on CPUs that
/// split 512-bit work in two 256-bit halves (Zen 4) it still computes more terms a second than
/// the eight-lane loop (half the instructions for the same arithmetic), so it, not the AVX2
/// loop, is their peak (docs/benchmarks.md, "The CPU backend"). The exponential is
/// [`exp_neg`]'s, in sixteen lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn dense_sums_avx512(p: &Packed, from: usize, to: usize, q: [f32; 3]) -> f64 {
    use core::arch::x86_64::*;
    const WIDE: usize = 16;
    let c = _mm512_set1_ps;
    let (qx, qy, qz) = (c(q[0]), c(q[1]), c(q[2]));
    let mut phi = _mm512_setzero_ps();
    let mut at = from;
    while at < to {
        let live: __mmask16 = if to - at >= WIDE {
            u16::MAX
        } else {
            (1u16 << (to - at)) - 1
        };
        // SAFETY: the lanes past `to` are masked off in every load (not read).
        let lanes = |v: &Vec<f32>| unsafe { _mm512_maskz_loadu_ps(live, v.as_ptr().add(at)) };
        let (dx, dy, dz) = (
            _mm512_sub_ps(lanes(&p.x), qx),
            _mm512_sub_ps(lanes(&p.y), qy),
            _mm512_sub_ps(lanes(&p.z), qz),
        );
        let d2 = _mm512_fmadd_ps(dz, dz, _mm512_fmadd_ps(dy, dy, _mm512_mul_ps(dx, dx)));
        let reached = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, d2, lanes(&p.r2));
        // The exponential as `exp_neg_avx2` computes it.
        let x = _mm512_max_ps(
            _mm512_mul_ps(_mm512_sub_ps(_mm512_setzero_ps(), lanes(&p.k)), d2),
            c(EXP_MIN),
        );
        let round = c(EXP_ROUND);
        let shifted = _mm512_fmadd_ps(x, c(std::f32::consts::LOG2_E), round);
        let n = _mm512_sub_ps(shifted, round);
        let r = _mm512_fnmadd_ps(n, c(LN2_LO), _mm512_fnmadd_ps(n, c(LN2_HI), x));
        let mut poly = c(EXP_POLY[0]);
        for &k in &EXP_POLY[1..] {
            poly = _mm512_fmadd_ps(poly, r, c(k));
        }
        let e = _mm512_add_ps(_mm512_fmadd_ps(poly, _mm512_mul_ps(r, r), r), c(1.0));
        let n_int = _mm512_sub_epi32(_mm512_castps_si512(shifted), _mm512_castps_si512(round));
        let scale = _mm512_slli_epi32::<23>(_mm512_add_epi32(n_int, _mm512_set1_epi32(127)));
        let term = _mm512_mul_ps(lanes(&p.w), _mm512_mul_ps(e, _mm512_castsi512_ps(scale)));
        phi = _mm512_mask_add_ps(phi, reached, phi, term);
        at += WIDE;
    }
    let mut lanes = [0f32; WIDE];
    // SAFETY: sixteen floats.
    unsafe { _mm512_storeu_ps(lanes.as_mut_ptr(), phi) };
    lanes.iter().map(|&x| f64::from(x)).sum()
}

/// [`dense_sums`] with AVX2 and fused multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn dense_sums_avx2(p: &Packed, from: usize, to: usize, q: [f32; 3]) -> f64 {
    use core::arch::x86_64::*;
    let (qx, qy, qz) = (
        _mm256_set1_ps(q[0]),
        _mm256_set1_ps(q[1]),
        _mm256_set1_ps(q[2]),
    );
    let end = _mm256_set1_epi32(to as i32);
    let mut index = _mm256_add_epi32(
        _mm256_set1_epi32(from as i32),
        _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
    );
    let mut phi = _mm256_setzero_ps();
    let mut at = from;
    while at < to {
        let live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(end, index));
        // SAFETY: at < to, and to + LANES is within every array read (asserted by the caller).
        let (d2, reached, k, w) = unsafe {
            let (d2, reached) = reach_avx2(p, at, [qx, qy, qz], live, None);
            (d2, reached, lanes_at(&p.k, at), lanes_at(&p.w, at))
        };
        let x = _mm256_mul_ps(_mm256_sub_ps(_mm256_setzero_ps(), k), d2);
        let term = _mm256_and_ps(_mm256_mul_ps(w, exp_neg_avx2(x)), reached);
        phi = _mm256_add_ps(phi, term);
        at += LANES;
        index = _mm256_add_epi32(index, _mm256_set1_epi32(LANES as i32));
    }
    lane_total(phi)
}
