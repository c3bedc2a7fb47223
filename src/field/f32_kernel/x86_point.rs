//! The point and packet kernels' x86-64 builds (AVX2 + FMA, and AVX-512 F and VL): the
//! candidates' distance tests eight at a time, the reached ones packed to the front of full
//! lanes (a permutation per mask, or `vcompress`) before their exponentials.

use super::x86_lanes::*;
use super::*;

/// [`narrow_lanes`] with AVX2: the same operations in the same order (no fused multiply-adds),
/// so the same particles are kept in the same order; each chunk's kept lanes moved to the
/// front by one permutation ([`PACK`]) instead of eight scalar stores.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
pub(super) fn narrow_avx2(
    p: &Packed,
    runs: &[(u32, u32)],
    lo: [f32; 3],
    hi: [f32; 3],
    candidates: &mut [u32],
) -> usize {
    use core::arch::x86_64::*;
    let len = [&p.x, &p.y, &p.z, &p.r2]
        .into_iter()
        .map(Vec::len)
        .min()
        .unwrap_or(0);
    let (lo, hi) = (lo.map(|v| _mm256_set1_ps(v)), hi.map(|v| _mm256_set1_ps(v)));
    let zero = _mm256_setzero_ps();
    let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let mut n = 0;
    for &(a, b) in runs {
        let (mut at, end) = (a as usize, b as usize);
        assert!(end + LANES <= len, "runs within the padded particles");
        let mut index = _mm256_add_epi32(_mm256_set1_epi32(a as i32), iota);
        let end_v = _mm256_set1_epi32(b as i32);
        while at < end {
            // SAFETY: at < end and end + LANES <= len (asserted): eight floats from `at` are
            // in every array read.
            let (x, y, z, r2) = unsafe {
                (
                    lanes_at(&p.x, at),
                    lanes_at(&p.y, at),
                    lanes_at(&p.z, at),
                    lanes_at(&p.r2, at),
                )
            };
            // SAFETY: the CPU has AVX (this function's features).
            let (ex, ey, ez) = unsafe {
                (
                    box_gap(x, lo[0], hi[0], zero),
                    box_gap(y, lo[1], hi[1], zero),
                    box_gap(z, lo[2], hi[2], zero),
                )
            };
            let d2 = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(ex, ex), _mm256_mul_ps(ey, ey)),
                _mm256_mul_ps(ez, ez),
            );
            let live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(end_v, index));
            let keep = _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(d2, r2), live);
            let mask = _mm256_movemask_ps(keep) as usize;
            assert!(n + LANES <= candidates.len(), "room for a chunk's writes");
            // SAFETY: eight slots from n are in `candidates` (asserted); the table row holds
            // eight lanes.
            unsafe {
                let order = _mm256_loadu_si256(PACK[mask].as_ptr().cast());
                _mm256_storeu_si256(
                    candidates.as_mut_ptr().add(n).cast(),
                    _mm256_permutevar8x32_epi32(index, order),
                );
            }
            n += mask.count_ones() as usize;
            at += LANES;
            index = _mm256_add_epi32(index, _mm256_set1_epi32(LANES as i32));
        }
    }
    n
}

/// [`packet_terms_lanes`] compiled with AVX2 (the same operations: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) fn packet_terms_avx2<const C: usize>(
    p: &Packed,
    candidates: &[u32],
    q: &[[f32; 3]; LANES],
    live: [u32; LANES],
) -> [(f64, [f64; 3]); LANES] {
    packet_terms_lanes::<C>(p, candidates, q, live)
}

/// Reached candidates the AVX2 point kernel holds before computing their terms.
#[cfg(target_arch = "x86_64")]
pub(super) const HELD: usize = 64;

/// For each mask of reached lanes (bit l: lane l), the permutation that moves those lanes to
/// the front in order: the AVX2 point kernel's compaction.
#[cfg(target_arch = "x86_64")]
pub(super) static PACK: [[u32; LANES]; 256] = pack_table();

#[cfg(target_arch = "x86_64")]
pub(super) const fn pack_table() -> [[u32; LANES]; 256] {
    let mut table = [[0u32; LANES]; 256];
    let mut mask = 0;
    while mask < 256 {
        let (mut n, mut lane) = (0, 0);
        while lane < LANES {
            if (mask >> lane) & 1 == 1 {
                table[mask][n] = lane as u32;
                n += 1;
            }
            lane += 1;
        }
        mask += 1;
    }
    table
}

/// The point kernel with AVX2: the distance tests eight at a time with no branch on their
/// outcome, the reached candidates' indices and squared distances packed to the front of a
/// small buffer (a permutation per mask, [`PACK`]), then the terms eight reached candidates at
/// a time. Why: the cells hand the kernel six times the particles within reach, and a branch
/// per chunk on whether any lane reached mispredicted so often that it cost more than every
/// exponential would (measured by removing it: docs/notes/2026-12-04-cpu-point-kernel.md);
/// packing also runs the exponentials on full lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
pub(super) unsafe fn sums_avx2<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
    p: &Packed,
    runs: &[(u32, u32)],
    q: [f32; 3],
    one_radius: OneRadius,
    same_w: f32,
) -> (f64, [f64; 3]) {
    // SAFETY: the caller's CPU has AVX2 and FMA, which is all the body uses when its
    // compaction is the permutation table's.
    unsafe { point_sums::<C, ONE_RADIUS, SAME_W, false>(p, runs, q, one_radius, same_w) }
}

/// [`sums_avx2`] with AVX-512 (F and VL) on the same eight lanes: the reach test writes a
/// mask register, and the reached lanes are packed by `vcompress` instead of the mask moved to
/// a general register, a permutation loaded from [`PACK`] and applied: the same lanes in the
/// same order, so the same bits. Why: on a Zen 4 core that chain was most of the test's time,
/// and the queries ran faster without it (docs/notes/2026-12-04-cpu-point-kernel.md, "The
/// machine's peak measured in AVX-512"). Sixteen lanes ran slower: a query's nine runs of
/// about 21 candidates fill sixteen lanes worse than eight.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma,popcnt")]
pub(super) unsafe fn sums_avx512<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
    p: &Packed,
    runs: &[(u32, u32)],
    q: [f32; 3],
    one_radius: OneRadius,
    same_w: f32,
) -> (f64, [f64; 3]) {
    // SAFETY: the caller's CPU has AVX-512 F and VL, AVX2 and FMA.
    unsafe { point_sums::<C, ONE_RADIUS, SAME_W, true>(p, runs, q, one_radius, same_w) }
}

/// The body of [`sums_avx2`] (`COMPRESS` false) and [`sums_avx512`] (true), inlined into
/// each so that its intrinsics take their features. The held indices are written only where
/// the terms gather something by them (a radius or weight of each particle's own, or theta):
/// a scene of one radius with no density map and no attribute keeps only the distances.
///
/// # Safety
/// The CPU has AVX2, FMA and POPCNT, and AVX-512 F and VL where `COMPRESS`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn point_sums<
    const C: usize,
    const ONE_RADIUS: bool,
    const SAME_W: bool,
    const COMPRESS: bool,
>(
    p: &Packed,
    runs: &[(u32, u32)],
    q: [f32; 3],
    one_radius: OneRadius,
    same_w: f32,
) -> (f64, [f64; 3]) {
    use core::arch::x86_64::*;
    // SAFETY: the caller vouches for the CPU's features (the intrinsics need nothing else);
    // each pointer's bounds are argued where it is made.
    unsafe {
        let gathers = C > 0 || !ONE_RADIUS || !SAME_W;
        let (qx, qy, qz) = (
            _mm256_set1_ps(q[0]),
            _mm256_set1_ps(q[1]),
            _mm256_set1_ps(q[2]),
        );
        let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let one_r2 = ONE_RADIUS.then(|| _mm256_set1_ps(one_radius.r2));
        let mut sums = HeldSums::zero();
        // The loads below read eight floats from every array the kernel uses: all of them must
        // hold each run and its padding (checked once, on the shortest).
        let len = [&p.x, &p.y, &p.z, &p.r2, &p.k, &p.w]
            .into_iter()
            .chain(&p.theta[..C])
            .map(Vec::len)
            .min()
            .unwrap_or(0);
        // A chunk's store writes eight slots from `n`, so the buffer holds HELD + LANES.
        let mut held_index = [0i32; HELD + LANES];
        let mut held_d2 = [0f32; HELD + LANES];
        let mut n = 0usize;
        for &(a, b) in runs {
            let (mut at, end) = (a as usize, b as usize);
            assert!(end + LANES <= len, "runs within the padded particles");
            // The lanes' particle indices, and the run's end to mask them by.
            let mut index = _mm256_add_epi32(_mm256_set1_epi32(a as i32), iota);
            let end_v = _mm256_set1_epi32(b as i32);
            while at < end {
                // Bounds: at < end and end + LANES <= len (asserted): eight floats from `at`
                // are in every array read; n <= HELD (flushed below otherwise): eight slots
                // from n are in the buffers; a table row holds eight lanes.
                let (d2, r2) = distance2_avx2(p, at, [qx, qy, qz], one_r2);
                let count = pack_reached::<COMPRESS>(
                    d2,
                    r2,
                    index,
                    end_v,
                    gathers,
                    held_index.as_mut_ptr().add(n).cast(),
                    held_d2.as_mut_ptr().add(n),
                );
                n += count as usize;
                at += LANES;
                index = _mm256_add_epi32(index, _mm256_set1_epi32(LANES as i32));
                if n > HELD - LANES {
                    // Whole chunks now; the rest moves to the front.
                    let whole = n / LANES * LANES;
                    // Bounds: whole <= HELD; held indices are particles' (below `len`) or 0.
                    sums.add::<C, ONE_RADIUS, SAME_W>(
                        p,
                        &held_index,
                        &held_d2,
                        whole,
                        one_radius,
                        same_w,
                    );
                    if gathers {
                        held_index.copy_within(whole..n, 0);
                    }
                    held_d2.copy_within(whole..n, 0);
                    n -= whole;
                }
            }
        }
        sums.add::<C, ONE_RADIUS, SAME_W>(p, &held_index, &held_d2, n, one_radius, same_w);
        sums.totals::<C>()
    }
}
