//! The group kernel's x86-64 builds: a group of close query points' shared candidates
//! narrowed to those within reach of the group's box, then each point's point kernel over them.

use super::x86_lanes::*;
use super::x86_point::*;
use super::*;

/// [`Packed::group_sums`] with AVX2 (its packing by a permutation, as [`sums_avx2`]).
///
/// # Safety
/// The CPU has AVX2, FMA and POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
pub(super) unsafe fn group_sums_avx2<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
    p: &Packed,
    runs: &[(u32, u32)],
    qs: &[[f32; 3]],
    scratch: &mut GroupScratch,
    out: &mut [(f64, [f64; 3])],
) {
    // SAFETY: the caller's CPU has AVX2, FMA and POPCNT.
    unsafe { group_sums_body::<C, ONE_RADIUS, SAME_W, false>(p, runs, qs, scratch, out) }
}

/// [`Packed::group_sums`] with AVX-512 F and VL (its packing by `vcompress`, as
/// [`sums_avx512`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx2,fma,popcnt")]
pub(super) unsafe fn group_sums_avx512<
    const C: usize,
    const ONE_RADIUS: bool,
    const SAME_W: bool,
>(
    p: &Packed,
    runs: &[(u32, u32)],
    qs: &[[f32; 3]],
    scratch: &mut GroupScratch,
    out: &mut [(f64, [f64; 3])],
) {
    // SAFETY: the caller's CPU has AVX-512 F and VL, AVX2 and FMA.
    unsafe { group_sums_body::<C, ONE_RADIUS, SAME_W, true>(p, runs, qs, scratch, out) }
}

/// The body of [`group_sums_avx2`] (`COMPRESS` false) and [`group_sums_avx512`] (true),
/// inlined into each.
///
/// # Safety
/// The CPU has AVX2, FMA and POPCNT, and AVX-512 F and VL where `COMPRESS`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn group_sums_body<
    const C: usize,
    const ONE_RADIUS: bool,
    const SAME_W: bool,
    const COMPRESS: bool,
>(
    p: &Packed,
    runs: &[(u32, u32)],
    qs: &[[f32; 3]],
    scratch: &mut GroupScratch,
    out: &mut [(f64, [f64; 3])],
) {
    use core::arch::x86_64::*;
    let gathers = C > 0 || !ONE_RADIUS || !SAME_W;
    let one_radius = p.one_radius.unwrap_or_default();
    let same_w = p.same_w.unwrap_or(0.0);
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for q in qs {
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    // SAFETY: the caller vouches for the CPU's features; each pointer's bounds are argued
    // where it is made.
    unsafe {
        let count =
            narrow_copy::<C, ONE_RADIUS, SAME_W, COMPRESS>(p, runs, lo, hi, &mut scratch.narrowed);
        let n = &scratch.narrowed;
        // Each point's reached candidates start on a whole chunk (their lanes are then the
        // ones `point_sums` gives them), and a chunk's store writes eight slots past them.
        let need = qs.len() * (count + LANES) + LANES;
        if scratch.held_d2.len() < need {
            scratch.held_d2.resize(need, 0.0);
            scratch.held_index.resize(need, 0);
        }
        // Pointers held in registers: stores through the buffers' would otherwise make the
        // compiler load every array's address again each chunk.
        let (held_index, held_d2) = (
            scratch.held_index.as_mut_ptr(),
            scratch.held_d2.as_mut_ptr(),
        );
        let (x, y, z, r2s) = (n.x.as_ptr(), n.y.as_ptr(), n.z.as_ptr(), n.r2.as_ptr());
        let one_r2 = if ONE_RADIUS {
            Some(_mm256_set1_ps(one_radius.r2))
        } else {
            None
        };
        let iota = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let end_v = _mm256_set1_epi32(count as i32);
        // First pass: every point's tests.
        let mut spans = [(0usize, 0usize); 64];
        assert!(qs.len() <= spans.len(), "at most 64 points a group");
        let mut base = 0;
        for (qf, span) in qs.iter().zip(&mut spans) {
            let q = [
                _mm256_set1_ps(qf[0]),
                _mm256_set1_ps(qf[1]),
                _mm256_set1_ps(qf[2]),
            ];
            let mut m = base;
            let mut index = iota;
            let mut at = 0;
            while at < count {
                // Bounds: at < count, and the copy holds LANES more: eight floats from `at`
                // in every array read; m + LANES <= base + count + LANES <= need.
                let d2 = distance2_from(
                    [
                        _mm256_loadu_ps(x.add(at)),
                        _mm256_loadu_ps(y.add(at)),
                        _mm256_loadu_ps(z.add(at)),
                    ],
                    q,
                );
                let r2 = match one_r2 {
                    Some(r2) => r2,
                    None => _mm256_loadu_ps(r2s.add(at)),
                };
                m += pack_reached::<COMPRESS>(
                    d2,
                    r2,
                    index,
                    end_v,
                    gathers,
                    held_index.add(m).cast(),
                    held_d2.add(m),
                ) as usize;
                at += LANES;
                index = _mm256_add_epi32(index, _mm256_set1_epi32(LANES as i32));
            }
            *span = (base, m - base);
            base += (m - base).div_ceil(LANES) * LANES;
        }
        // Second pass: every point's terms.
        for (&(from, reached), o) in spans.iter().zip(out.iter_mut()) {
            let mut sums = HeldSums::zero();
            // Bounds: from + reached + LANES <= need; the held indices are the copy's.
            sums.add::<C, ONE_RADIUS, SAME_W>(
                n,
                core::slice::from_raw_parts(held_index.add(from), need - from),
                core::slice::from_raw_parts(held_d2.add(from), need - from),
                reached,
                one_radius,
                same_w,
            );
            *o = sums.totals::<C>();
        }
    }
}

/// Copies into `out` the particles of `runs` within their radius of the box `[lo, hi]`, in
/// order, with the arrays the point kernel reads of them (positions; r² and k where radii
/// differ; w where weights do; theta), padded by [`LANES`]; returns how many. The arrays may
/// hold more past the padding. The box test is the point test's
/// arithmetic (the fused squared distance) on each axis's gap to the box, which is never
/// larger than the distance to a point in it, so no particle a point of the box reaches is left
/// out.
///
/// # Safety
/// The CPU has AVX2 and FMA, and AVX-512 F and VL where `COMPRESS`.
// Whole on purpose: hot SIMD, its pointer tables and masks kept in registers through both loops.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn narrow_copy<
    const C: usize,
    const ONE_RADIUS: bool,
    const SAME_W: bool,
    const COMPRESS: bool,
>(
    p: &Packed,
    runs: &[(u32, u32)],
    lo_f: [f32; 3],
    hi_f: [f32; 3],
    out: &mut Packed,
) -> usize {
    use core::arch::x86_64::*;
    // The arrays the point kernel reads: positions always, r² and k where radii differ, w
    // where weights do, theta per channel; the padding reaches nothing (r² = -1).
    let used = [
        true,
        true,
        true,
        !ONE_RADIUS,
        !ONE_RADIUS,
        !SAME_W,
        C > 0,
        C > 1,
        C > 1,
    ];
    let padding = [0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let from: [&Vec<f32>; 9] = [
        &p.x,
        &p.y,
        &p.z,
        &p.r2,
        &p.k,
        &p.w,
        &p.theta[0],
        &p.theta[1],
        &p.theta[2],
    ];
    let Packed {
        x,
        y,
        z,
        r2,
        k,
        w,
        theta: [t0, t1, t2],
        ..
    } = out;
    let to: [&mut Vec<f32>; 9] = [x, y, z, r2, k, w, t0, t1, t2];
    // The box test reads every position and r² (each particle's: the same floats as one
    // radius broadcast); eight floats from each run's end must be there too.
    let mut len = p.r2.len();
    for (a, v) in from.iter().enumerate() {
        if used[a] {
            len = len.min(v.len());
        }
    }
    let total: usize = runs.iter().map(|&(a, b)| (b - a) as usize).sum();
    // Room for every candidate, and a chunk's sixteen writes past the last (grown, never
    // cleared: what is there is overwritten, and the count is returned).
    let mut dst = [core::ptr::null_mut::<f32>(); 9];
    let mut src = [core::ptr::null::<f32>(); 9];
    for a in 0..9 {
        if used[a] {
            if to[a].len() < total + 2 * LANES {
                to[a].resize(total + 2 * LANES, 0.0);
            }
            dst[a] = to[a].as_mut_ptr();
            src[a] = from[a].as_ptr();
        } else {
            to[a].clear();
        }
    }
    // No closures below: they would not take the caller's target features.
    let mut n = 0;
    if COMPRESS {
        // Sixteen lanes a chunk (AVX-512 F): half the instructions a candidate.
        // SAFETY: the caller's CPU has AVX-512 F and VL where COMPRESS; bounds as below.
        unsafe {
            let (lo, hi) = (
                [
                    _mm512_set1_ps(lo_f[0]),
                    _mm512_set1_ps(lo_f[1]),
                    _mm512_set1_ps(lo_f[2]),
                ],
                [
                    _mm512_set1_ps(hi_f[0]),
                    _mm512_set1_ps(hi_f[1]),
                    _mm512_set1_ps(hi_f[2]),
                ],
            );
            let zero = _mm512_setzero_ps();
            let one_r2 = _mm512_set1_ps(p.one_radius.unwrap_or_default().r2);
            for &(a, b) in runs {
                let (mut at, end) = (a as usize, b as usize);
                assert!(end + LANES <= len, "runs within the padded particles");
                while at < end {
                    let live: __mmask16 = if end - at >= 16 {
                        u16::MAX
                    } else {
                        (1u16 << (end - at)) - 1
                    };
                    let mut e = [zero; 3];
                    let mut xyz = [zero; 3];
                    for (axis, e) in e.iter_mut().enumerate() {
                        let v = _mm512_maskz_loadu_ps(live, src[axis].add(at));
                        xyz[axis] = v;
                        let g =
                            _mm512_max_ps(_mm512_sub_ps(lo[axis], v), _mm512_sub_ps(v, hi[axis]));
                        *e = _mm512_max_ps(g, zero);
                    }
                    let [ex, ey, ez] = e;
                    let d2 =
                        _mm512_fmadd_ps(ez, ez, _mm512_fmadd_ps(ey, ey, _mm512_mul_ps(ex, ex)));
                    let r2 = if ONE_RADIUS {
                        one_r2
                    } else {
                        _mm512_maskz_loadu_ps(live, p.r2.as_ptr().add(at))
                    };
                    let keep = _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(live, d2, r2);
                    for a in 0..9 {
                        if used[a] {
                            // The positions as loaded for the test.
                            let v = if a < 3 {
                                xyz[a]
                            } else {
                                _mm512_maskz_loadu_ps(live, src[a].add(at))
                            };
                            _mm512_storeu_ps(dst[a].add(n), _mm512_maskz_compress_ps(keep, v));
                        }
                    }
                    n += keep.count_ones() as usize;
                    at += 16;
                }
            }
        }
    } else {
        // SAFETY: the caller vouches for the CPU.
        let (lo, hi, zero, iota) = unsafe {
            (
                [
                    _mm256_set1_ps(lo_f[0]),
                    _mm256_set1_ps(lo_f[1]),
                    _mm256_set1_ps(lo_f[2]),
                ],
                [
                    _mm256_set1_ps(hi_f[0]),
                    _mm256_set1_ps(hi_f[1]),
                    _mm256_set1_ps(hi_f[2]),
                ],
                _mm256_setzero_ps(),
                _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            )
        };
        for &(a, b) in runs {
            let (mut at, end) = (a as usize, b as usize);
            assert!(end + LANES <= len, "runs within the padded particles");
            // SAFETY: the caller vouches for the CPU.
            let (mut index, end_v) = unsafe {
                (
                    _mm256_add_epi32(_mm256_set1_epi32(a as i32), iota),
                    _mm256_set1_epi32(b as i32),
                )
            };
            while at < end {
                // SAFETY: at < end and end + LANES <= len (asserted): eight floats from `at` are
                // in every array read; n + LANES <= total + LANES: eight slots from n in every
                // array written; a table row holds eight lanes.
                unsafe {
                    let (ex, ey, ez) = (
                        box_gap(lanes_at(&p.x, at), lo[0], hi[0], zero),
                        box_gap(lanes_at(&p.y, at), lo[1], hi[1], zero),
                        box_gap(lanes_at(&p.z, at), lo[2], hi[2], zero),
                    );
                    let d2 =
                        _mm256_fmadd_ps(ez, ez, _mm256_fmadd_ps(ey, ey, _mm256_mul_ps(ex, ex)));
                    let live = _mm256_castsi256_ps(_mm256_cmpgt_epi32(end_v, index));
                    let keep =
                        _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(d2, lanes_at(&p.r2, at)), live);
                    let mask = _mm256_movemask_ps(keep) as usize;
                    let order = _mm256_loadu_si256(PACK[mask].as_ptr().cast());
                    for a in 0..9 {
                        if used[a] {
                            let v = _mm256_loadu_ps(src[a].add(at));
                            _mm256_storeu_ps(dst[a].add(n), _mm256_permutevar8x32_ps(v, order));
                        }
                    }
                    n += mask.count_ones() as usize;
                    index = _mm256_add_epi32(index, _mm256_set1_epi32(LANES as i32));
                }
                at += LANES;
            }
        }
    }
    for a in 0..9 {
        if used[a] {
            to[a][n..n + LANES].fill(padding[a]);
        }
    }
    n
}
