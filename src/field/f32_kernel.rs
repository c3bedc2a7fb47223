//! The CPU's fast field kernel: a query point's RBF terms over a packed candidate list, eight
//! particles at a time in f32, with a polynomial exponential. Written once as plain lane
//! arithmetic over `[f32; 8]` and compiled twice: for the baseline x86-64 target (SSE2, and
//! any other architecture) and, chosen at run time when the CPU has them, with AVX2 and FMA
//! enabled, where the compiler turns each eight-lane step into one 256-bit instruction. The
//! point kernel's AVX2 twin (`sums_avx2`) is written in `core::arch` intrinsics instead, to
//! fuse its multiply-adds (Rust never contracts `a * b + c` on its own, and the vectoriser
//! packed `f32::mul_add` lanes four wide: docs/notes/2026-12-03-cpu-backend.md) and to pack
//! the candidates that reach into full lanes with a permutation before their exponentials,
//! where the baseline build branches per chunk (SSE2 has no lane permutation). Its results
//! therefore differ from the baseline build's by their roundings and order of summation
//! (1.5e-8 at most on a test image, tested to 1e-6). The packet kernel's narrowing is in
//! intrinsics too, for the same permutation, with the baseline build's operations: its two
//! builds stay equal bit for bit.
//! Where the CPU has AVX-512 (F and VL), the point kernel runs a third build of the same body
//! on the same eight lanes, packing with `vcompress` instead of the permutation: the same lanes
//! in the same order, so the AVX2 build's bits, and faster
//! (docs/notes/2026-12-04-cpu-point-kernel.md).
//!
//! Why this and not a SIMD crate: `wide` selects its instructions when the crate is compiled
//! (this project builds for baseline x86-64, where its `f32x8` is two SSE halves), `pulp` and
//! `multiversion` add dispatch machinery for one kernel; the kernel here is 40 lines of lane
//! arithmetic, and a `#[target_feature]` twin of it is the whole dispatch.
//! `benches/cpu_roofline.rs` measures every build against the machine's peak.

use std::sync::atomic::{AtomicBool, Ordering};

/// Particles evaluated together.
pub const LANES: usize = 8;

/// Terms a lane adds in f32 before its sum goes to f64: the kernel's sums are blocks of at most
/// this many f32 additions a lane, so their rounding does not grow with the number of terms
/// (`backend::precision` bounds it by this).
pub const LANE_TERMS: usize = 8;

/// The largest relative error of the kernel's exponential over its range `[-4.5, 0]`, per build
/// (measured by `exp_errors_are_as_stated` below): the baseline build ([`exp_neg`]) and the
/// fused multiply-add build (AVX2 and AVX-512).
pub const EXP_ERROR_BASELINE: f64 = 8.5e-8;
pub const EXP_ERROR_FMA: f64 = 8.5e-8;

/// [`EXP_ERROR_BASELINE`] or [`EXP_ERROR_FMA`], for the build field evaluation runs here.
pub fn exp_error_in_use() -> f64 {
    if simd_in_use() {
        EXP_ERROR_FMA
    } else {
        EXP_ERROR_BASELINE
    }
}

static SIMD_ALLOWED: AtomicBool = AtomicBool::new(true);

/// Allows or forbids the AVX2 build of the kernel (tests and benchmarks force the baseline
/// build with `false`; the results agree to the AVX2 point kernel's fused roundings, only
/// slower).
pub fn allow_simd(allowed: bool) {
    SIMD_ALLOWED.store(allowed, Ordering::Relaxed);
}

/// Whether field evaluation runs the AVX2 + FMA build of the kernel here.
pub fn simd_in_use() -> bool {
    SIMD_ALLOWED.load(Ordering::Relaxed) && avx2_available()
}

static AVX512_ALLOWED: AtomicBool = AtomicBool::new(true);

/// Allows or forbids the AVX-512 build of the point kernel and the dense loop (tests and
/// benchmarks force the AVX2 build with `false`; the point kernel's results are the same bits).
pub fn allow_avx512(allowed: bool) {
    AVX512_ALLOWED.store(allowed, Ordering::Relaxed);
}

/// Whether field evaluation runs the AVX-512 (F and VL) build of the point kernel and the
/// dense loop here: where [`simd_in_use`], AVX-512 is allowed, and the CPU has it.
pub fn avx512_in_use() -> bool {
    simd_in_use() && AVX512_ALLOWED.load(Ordering::Relaxed) && avx512_available()
}

#[cfg(target_arch = "x86_64")]
fn avx512_available() -> bool {
    std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx512_available() -> bool {
    false
}

#[cfg(target_arch = "x86_64")]
fn avx2_available() -> bool {
    std::is_x86_feature_detected!("avx2")
        && std::is_x86_feature_detected!("fma")
        && std::is_x86_feature_detected!("popcnt")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_available() -> bool {
    false
}

/// The exponential's constants, one definition for its two builds ([`exp_neg`] and the AVX2
/// point kernel's): the least input, 1.5 · 2^23 (adding it rounds to an integer, to nearest,
/// ties to even, in the low bits), ln 2 in two parts (Cody–Waite) and Cephes' `expf`
/// polynomial, highest degree first.
const EXP_MIN: f32 = -87.0;
const EXP_ROUND: f32 = 12_582_912.0;
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;
const EXP_POLY: [f32; 6] = [
    1.987_569_1e-4,
    1.398_199_9e-3,
    8.333_452e-3,
    4.166_579_6e-2,
    1.666_666_5e-1,
    0.5,
];

/// `exp(x)` for `x <= 0` in f32, as a polynomial: Cody–Waite reduction to `r` in
/// `[-ln 2 / 2, ln 2 / 2]` and Cephes' `expf` minimax polynomial, scaled by `2^n` built in the
/// exponent bits. Relative error below 2.5e-7 (2 ulp) over the kernel's range `[-4.5, 0]` and
/// down to -87 (tested against f64); inputs below -87 give `exp(-87)` (the kernel masks them:
/// they lie outside every particle's radius).
#[inline(always)]
pub fn exp_neg(x: f32) -> f32 {
    let x = if x > EXP_MIN { x } else { EXP_MIN };
    let shifted = x * std::f32::consts::LOG2_E + EXP_ROUND;
    let n = shifted - EXP_ROUND;
    let r = x - n * LN2_HI - n * LN2_LO;
    let mut p = EXP_POLY[0];
    for c in &EXP_POLY[1..] {
        p = p * r + c;
    }
    let e = p * (r * r) + r + 1.0;
    // n in [-126, 0]: 2^n is a normal f32 with biased exponent n + 127.
    let n_int = shifted.to_bits().wrapping_sub(EXP_ROUND.to_bits()) as i32;
    // Wrapping: an overflow check would stop the compiler vectorising the lanes (n + 127 is
    // in [1, 127] anyway).
    e * f32::from_bits((n_int.wrapping_add(127) as u32).wrapping_shl(23))
}

/// Particles for the kernel: structure of arrays in the order the caller chose, followed by
/// [`LANES`] particles that reach nothing, so the kernel can read eight lanes from any particle
/// on.
#[derive(Clone, Debug, Default)]
pub struct Packed {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
    /// r², or -1 (reaches no point) for the padding.
    pub r2: Vec<f32>,
    /// 4.5 / r² (the kernel's exponent is `-k d²`).
    pub k: Vec<f32>,
    /// The density map's weight w(t).
    pub w: Vec<f32>,
    /// theta per channel (the normalised attribute, or linear RGB); `channels` of them.
    pub theta: [Vec<f32>; 3],
    pub channels: usize,
    /// `k` and `r2` where every particle has the same (one radius: no radius map, no
    /// smoothing lengths), and `w` likewise (no density map); set by [`Packed::pad`]. The
    /// SIMD point kernels then broadcast them instead of gathering `k` for each term and
    /// loading `r2` for each test: a scene that models neither pays for neither (measured in
    /// docs/notes/2026-12-04-cpu-point-kernel.md, "What a term gathers" and "One radius
    /// broadcasts r² too").
    pub one_radius: Option<OneRadius>,
    pub same_w: Option<f32>,
}

/// The kernel's constants of one radius r: `k` = 4.5 / r² and `r2` = r², as every particle's
/// arrays hold them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OneRadius {
    pub k: f32,
    pub r2: f32,
}

impl Packed {
    /// Appends the padding (call once, after the last particle), noting first whether every
    /// particle has the same `k` and `r2`, and the same `w` ([`Packed::one_radius`]; bit for bit).
    pub fn pad(&mut self) {
        let same = |v: &[f32]| -> Option<f32> {
            let first = *v.first()?;
            v.iter()
                .all(|x| x.to_bits() == first.to_bits())
                .then_some(first)
        };
        self.one_radius = same(&self.k)
            .zip(same(&self.r2))
            .map(|(k, r2)| OneRadius { k, r2 });
        self.same_w = same(&self.w);
        for _ in 0..LANES {
            self.x.push(0.0);
            self.y.push(0.0);
            self.z.push(0.0);
            self.r2.push(-1.0);
            self.k.push(0.0);
            self.w.push(0.0);
            for v in &mut self.theta[..self.channels] {
                v.push(0.0);
            }
        }
    }

    /// Bytes of the arrays.
    pub fn bytes(&self) -> usize {
        4 * (6 + self.channels) * self.x.len()
    }

    /// Σ phi_i and Σ theta_i phi_i at `q` over the particles of `runs` (ranges of particle
    /// indices), in f32 lanes summed into f64 at the end. Runs the AVX2 build where
    /// [`simd_in_use`].
    #[inline]
    pub fn sums(&self, runs: &[(u32, u32)], q: [f32; 3]) -> (f64, [f64; 3]) {
        match self.channels {
            0 => sums::<0>(self, runs, q),
            1 => sums::<1>(self, runs, q),
            _ => sums::<3>(self, runs, q),
        }
    }

    /// [`Packed::sums`] at up to [`LANES`] points at once (`q[l]` where `live[l]` is all ones,
    /// a point per lane), over the particles of `runs`: those within their radius of the
    /// points' bounding box are gathered into `candidates` first (the points lie close
    /// together: a packet of neighbouring rays' samples), then each is evaluated at every
    /// point. A term is the same f32 value [`Packed::sums`] computes for its point and
    /// particle (the box test never leaves out a particle that reaches a point: its distance
    /// rounds no larger); only the order of summation differs.
    pub fn packet_sums(
        &self,
        runs: &[(u32, u32)],
        q: &[[f32; 3]; LANES],
        live: [u32; LANES],
        candidates: &mut Vec<u32>,
    ) -> [(f64, [f64; 3]); LANES] {
        match self.channels {
            0 => packet_sums::<0>(self, runs, q, live, candidates),
            1 => packet_sums::<1>(self, runs, q, live, candidates),
            _ => packet_sums::<3>(self, runs, q, live, candidates),
        }
    }
}

#[inline]
fn packet_sums<const C: usize>(
    p: &Packed,
    runs: &[(u32, u32)],
    q: &[[f32; 3]; LANES],
    live: [u32; LANES],
    candidates: &mut Vec<u32>,
) -> [(f64, [f64; 3]); LANES] {
    let (lo, hi) = bounding_box(q, live);
    let total: usize = runs.iter().map(|&(a, b)| (b - a) as usize).sum();
    // Room for every candidate and a chunk's stray writes; what is there is overwritten
    // (filling it anew each packet would be a second pass over it).
    if candidates.len() < total + LANES {
        candidates.resize(total + LANES, 0);
    }
    #[cfg(target_arch = "x86_64")]
    if simd_in_use() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time by `simd_in_use`).
        return unsafe {
            let n = narrow_avx2(p, runs, lo, hi, candidates);
            packet_terms_avx2::<C>(p, &candidates[..n], q, live)
        };
    }
    let n = narrow_lanes(p, runs, lo, hi, candidates);
    packet_terms_lanes::<C>(p, &candidates[..n], q, live)
}

/// The bounding box of the live points.
fn bounding_box(q: &[[f32; 3]; LANES], live: [u32; LANES]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for (point, &m) in q.iter().zip(&live) {
        if m != 0 {
            for a in 0..3 {
                lo[a] = lo[a].min(point[a]);
                hi[a] = hi[a].max(point[a]);
            }
        }
    }
    (lo, hi)
}

/// The particles of `runs` within their radius of the box `[lo, hi]`, written to the front of
/// `candidates` (which holds every run's particles and [`LANES`] more); returns how many. In
/// lanes: the baseline build.
#[inline(always)]
fn narrow_lanes(
    p: &Packed,
    runs: &[(u32, u32)],
    lo: [f32; 3],
    hi: [f32; 3],
    candidates: &mut [u32],
) -> usize {
    let mut n = 0;
    // How far `v` lies outside [lo, hi] (plain compares: `f32::max` would add NaN handling;
    // they are also what `_mm256_max_ps` computes, so [`narrow_avx2`] keeps the same ones).
    let gap = |v: f32, lo: f32, hi: f32| -> f32 {
        let (below, above) = (lo - v, v - hi);
        let g = if below > above { below } else { above };
        if g > 0.0 { g } else { 0.0 }
    };
    for &(a, b) in runs {
        let (mut at, b) = (a as usize, b as usize);
        while at < b {
            let valid = (b - at).min(LANES);
            let lanes =
                |v: &[f32]| -> [f32; LANES] { v[at..at + LANES].try_into().expect("padded") };
            let (x, y, z, r2) = (lanes(&p.x), lanes(&p.y), lanes(&p.z), lanes(&p.r2));
            let mut keep = [0u32; LANES];
            for l in 0..LANES {
                let (ex, ey, ez) = (
                    gap(x[l], lo[0], hi[0]),
                    gap(y[l], lo[1], hi[1]),
                    gap(z[l], lo[2], hi[2]),
                );
                let d2 = ex * ex + ey * ey + ez * ez;
                keep[l] = u32::from(d2 <= r2[l] && l < valid);
            }
            // Branch-free compaction: every lane is written, the kept ones advance.
            for (l, &k) in keep.iter().enumerate() {
                candidates[n] = (at + l) as u32;
                n += k as usize;
            }
            at += LANES;
        }
    }
    n
}

/// [`narrow_lanes`] with AVX2: the same operations in the same order (no fused multiply-adds),
/// so the same particles are kept in the same order; each chunk's kept lanes moved to the
/// front by one permutation ([`PACK`]) instead of eight scalar stores.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
fn narrow_avx2(
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
fn packet_terms_avx2<const C: usize>(
    p: &Packed,
    candidates: &[u32],
    q: &[[f32; 3]; LANES],
    live: [u32; LANES],
) -> [(f64, [f64; 3]); LANES] {
    packet_terms_lanes::<C>(p, candidates, q, live)
}

/// The packet kernel's terms: each candidate evaluated at every point, a point per lane.
#[inline(always)]
fn packet_terms_lanes<const C: usize>(
    p: &Packed,
    candidates: &[u32],
    q: &[[f32; 3]; LANES],
    live: [u32; LANES],
) -> [(f64, [f64; 3]); LANES] {
    let (qx, qy, qz): ([f32; LANES], [f32; LANES], [f32; LANES]) = (
        std::array::from_fn(|l| q[l][0]),
        std::array::from_fn(|l| q[l][1]),
        std::array::from_fn(|l| q[l][2]),
    );
    // Each point's terms in f32 over eight candidates at a time, those sums added in f64: a
    // point's sum rounds no worse than in [`Packed::sums`] (whose lanes hold an eighth of it).
    let mut phi = [0f64; LANES];
    let mut num = [[0f64; LANES]; 3];
    for block in candidates.chunks(LANES) {
        let mut block_phi = [0f32; LANES];
        let mut block_num = [[0f32; LANES]; 3];
        for &j in block {
            let j = j as usize;
            let (x, y, z, r2, k, w) = (p.x[j], p.y[j], p.z[j], p.r2[j], p.k[j], p.w[j]);
            let mut term = [0f32; LANES];
            for l in 0..LANES {
                let (dx, dy, dz) = (x - qx[l], y - qy[l], z - qz[l]);
                let d2 = dx * dx + dy * dy + dz * dz;
                let reached = if d2 <= r2 { live[l] } else { 0 };
                let e = w * exp_neg(-k * d2);
                term[l] = f32::from_bits(e.to_bits() & reached);
                block_phi[l] += term[l];
            }
            for (ch, acc) in block_num.iter_mut().enumerate().take(C) {
                let t = p.theta[ch][j];
                for l in 0..LANES {
                    acc[l] += t * term[l];
                }
            }
        }
        for l in 0..LANES {
            phi[l] += f64::from(block_phi[l]);
        }
        for ch in 0..C {
            for l in 0..LANES {
                num[ch][l] += f64::from(block_num[ch][l]);
            }
        }
    }
    std::array::from_fn(|l| (phi[l], [0, 1, 2].map(|ch| num[ch][l])))
}

#[inline]
fn sums<const C: usize>(p: &Packed, runs: &[(u32, u32)], q: [f32; 3]) -> (f64, [f64; 3]) {
    #[cfg(target_arch = "x86_64")]
    if simd_in_use() {
        // One build of the point kernel per common radius and weight (broadcast) or not.
        macro_rules! by_broadcast {
            ($build:ident) => {
                match (p.one_radius, p.same_w) {
                    (Some(k), Some(w)) => $build::<C, true, true>(p, runs, q, k, w),
                    (Some(k), None) => $build::<C, true, false>(p, runs, q, k, 0.0),
                    (None, Some(w)) => {
                        $build::<C, false, true>(p, runs, q, OneRadius::default(), w)
                    }
                    (None, None) => {
                        $build::<C, false, false>(p, runs, q, OneRadius::default(), 0.0)
                    }
                }
            };
        }
        // SAFETY: the CPU has AVX2 and FMA (checked at run time by `simd_in_use`), and AVX-512
        // F and VL where `avx512_in_use`.
        return unsafe {
            if avx512_in_use() {
                by_broadcast!(sums_avx512)
            } else {
                by_broadcast!(sums_avx2)
            }
        };
    }
    sums_lanes::<C>(p, runs, q)
}

/// Reached candidates the AVX2 point kernel holds before computing their terms.
#[cfg(target_arch = "x86_64")]
const HELD: usize = 64;

/// For each mask of reached lanes (bit l: lane l), the permutation that moves those lanes to
/// the front in order: the AVX2 point kernel's compaction.
#[cfg(target_arch = "x86_64")]
static PACK: [[u32; LANES]; 256] = pack_table();

#[cfg(target_arch = "x86_64")]
const fn pack_table() -> [[u32; LANES]; 256] {
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
unsafe fn sums_avx2<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
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
unsafe fn sums_avx512<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
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
unsafe fn point_sums<
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

/// A group of points' shared candidates and their reached candidates between the two passes of
/// [`Packed::group_sums`]. Made once per thread and reused.
#[derive(Debug, Default)]
pub struct GroupScratch {
    /// The candidates within reach of the group's bounding box, with the arrays the point
    /// kernel reads of them.
    narrowed: Packed,
    held_index: Vec<i32>,
    held_d2: Vec<f32>,
}

impl Packed {
    /// [`Packed::sums`] at each of `qs` (points close together: consecutive queries in Hilbert
    /// order) into `out`, over the particles of `runs`, which hold each point's candidates in
    /// the order the point's own runs list them (the runs around the block of cells the points
    /// fall in, level by level). Those within their radius of the points' bounding box
    /// are copied out contiguous once; then every point's reach tests run over that copy, and
    /// every point's terms after all the tests. Why: a point's terms wait on its tests' packed
    /// stores and on the exponential's chain, and one point after another left that wait
    /// exposed; the copy also turns nine short runs into one and leaves out the candidates far
    /// from every point. Each point's sums are the bits [`Packed::sums`] gives it alone: the
    /// same reached particles (the box test never leaves out one a point's test keeps: it
    /// computes the same fused distance of gaps no larger) in the same order. Where the AVX2
    /// build is not in use ([`simd_in_use`]), each point is evaluated alone.
    pub fn group_sums(
        &self,
        runs: &[(u32, u32)],
        qs: &[[f32; 3]],
        scratch: &mut GroupScratch,
        out: &mut [(f64, [f64; 3])],
    ) {
        assert_eq!(qs.len(), out.len(), "a result per point");
        #[cfg(target_arch = "x86_64")]
        if simd_in_use() {
            macro_rules! by_broadcast {
                ($build:ident, $c:literal) => {
                    match (self.one_radius.is_some(), self.same_w.is_some()) {
                        (true, true) => $build::<$c, true, true>,
                        (true, false) => $build::<$c, true, false>,
                        (false, true) => $build::<$c, false, true>,
                        (false, false) => $build::<$c, false, false>,
                    }
                };
            }
            let build = match (self.channels, avx512_in_use()) {
                (0, false) => by_broadcast!(group_sums_avx2, 0),
                (1, false) => by_broadcast!(group_sums_avx2, 1),
                (_, false) => by_broadcast!(group_sums_avx2, 3),
                (0, true) => by_broadcast!(group_sums_avx512, 0),
                (1, true) => by_broadcast!(group_sums_avx512, 1),
                (_, true) => by_broadcast!(group_sums_avx512, 3),
            };
            // SAFETY: the CPU has AVX2 and FMA (`simd_in_use`), and AVX-512 F and VL where the
            // build compresses (`avx512_in_use`).
            unsafe { build(self, runs, qs, scratch, out) };
            return;
        }
        for (q, o) in qs.iter().zip(out) {
            *o = self.sums(runs, *q);
        }
    }
}

/// [`Packed::group_sums`] with AVX2 (its packing by a permutation, as [`sums_avx2`]).
///
/// # Safety
/// The CPU has AVX2, FMA and POPCNT.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,popcnt")]
unsafe fn group_sums_avx2<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
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
unsafe fn group_sums_avx512<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
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
unsafe fn group_sums_body<
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
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn narrow_copy<
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

/// How far each of eight coordinates `v` lies outside `[lo, hi]` (0 inside): never more than
/// its distance to any point's coordinate in the interval, as rounded.
///
/// # Safety
/// The CPU has AVX.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn box_gap(
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
unsafe fn pack_reached<const COMPRESS: bool>(
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
struct HeldSums {
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
    fn zero() -> HeldSums {
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
    fn flush<const C: usize>(&mut self) {
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
    fn totals<const C: usize>(&mut self) -> (f64, [f64; 3]) {
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
    unsafe fn add<const C: usize, const ONE_RADIUS: bool, const SAME_W: bool>(
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
fn lane_total(v: core::arch::x86_64::__m256) -> f64 {
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
unsafe fn lanes_at(v: &[f32], at: usize) -> core::arch::x86_64::__m256 {
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
unsafe fn reach_avx2(
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
unsafe fn distance2_avx2(
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
fn distance2_from(
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
struct Unaligned(core::arch::x86_64::__m256);

/// [`exp_neg`] on eight lanes with fused multiply-adds.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn exp_neg_avx2(x: core::arch::x86_64::__m256) -> core::arch::x86_64::__m256 {
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

/// The point kernel in lanes: the baseline build (the AVX2 one is `sums_avx2`), in one pass
/// that skips the exponentials of a chunk reaching nothing. It does not compact like the AVX2
/// build: without a lane permutation (SSE2 has none) the compaction is eight scalar stores a
/// chunk, and the queries ran slower with it than with this branch
/// (docs/notes/2026-12-04-cpu-point-kernel.md, "Not for the baseline build").
/// A run's last chunk reads past its end (into the next particles, or the padding) and masks
/// those lanes.
/// Masks are all-ones or zero lanes of `u32`, as vector compares make them, so the compiler
/// keeps them in vector registers (a `[bool; 8]` became shuffles and scalar bit tests, and
/// slower queries: docs/notes/2026-12-03-cpu-backend.md).
#[inline(always)]
fn sums_lanes<const C: usize>(p: &Packed, runs: &[(u32, u32)], q: [f32; 3]) -> (f64, [f64; 3]) {
    let mut phi = [0f32; LANES];
    let mut num = [[0f32; LANES]; 3];
    let mut total_phi = 0.0;
    let mut total_num = [0.0; 3];
    let mut chunks = 0;
    // A block of at most LANE_TERMS terms a lane ends: its lanes go to the f64 totals.
    let mut flush = |phi: &mut [f32; LANES], num: &mut [[f32; LANES]; 3]| {
        total_phi += lanes_total(phi);
        *phi = [0.0; LANES];
        for ch in 0..C {
            total_num[ch] += lanes_total(&num[ch]);
            num[ch] = [0.0; LANES];
        }
    };
    for &(a, b) in runs {
        let (a, b) = (a as usize, b as usize);
        let mut at = a;
        // Whole chunks, then the run's tail with the lanes past its end masked off.
        while at < b {
            let valid = (b - at).min(LANES) as u32;
            let live: [u32; LANES] =
                std::array::from_fn(|l| if (l as u32) < valid { u32::MAX } else { 0 });
            if chunk::<C>(p, at, q, live, &mut phi, &mut num) {
                chunks += 1;
                if chunks == LANE_TERMS {
                    flush(&mut phi, &mut num);
                    chunks = 0;
                }
            }
            at += LANES;
        }
    }
    flush(&mut phi, &mut num);
    (total_phi, total_num)
}

/// The sum of eight f32 lanes in f64: lane i and lane i + 4 added, then those pairs two
/// apart, then the last two (the order [`lane_total`] adds a vector's lanes in).
fn lanes_total(v: &[f32; LANES]) -> f64 {
    let l = v.map(f64::from);
    ((l[0] + l[4]) + (l[2] + l[6])) + ((l[1] + l[5]) + (l[3] + l[7]))
}

/// Eight particles from `from` on, the lanes outside `live` left out.
#[inline(always)]
fn chunk<const C: usize>(
    p: &Packed,
    from: usize,
    q: [f32; 3],
    live: [u32; LANES],
    phi: &mut [f32; LANES],
    num: &mut [[f32; LANES]; 3],
) -> bool {
    let lanes = |v: &[f32]| -> [f32; LANES] { v[from..from + LANES].try_into().expect("padded") };
    let (x, y, z, r2) = (lanes(&p.x), lanes(&p.y), lanes(&p.z), lanes(&p.r2));
    let mut d2 = [0f32; LANES];
    let mut reached = [0u32; LANES];
    for l in 0..LANES {
        let (dx, dy, dz) = (x[l] - q[0], y[l] - q[1], z[l] - q[2]);
        d2[l] = dx * dx + dy * dy + dz * dz;
        reached[l] = if d2[l] <= r2[l] { live[l] } else { 0 };
    }
    // Most candidates lie beyond their radius (the cells overfetch): a chunk that reaches
    // nothing skips the exponentials.
    if reached.iter().fold(0, |any, &m| any | m) == 0 {
        return false;
    }
    let (k, w) = (lanes(&p.k), lanes(&p.w));
    let mut term = [0f32; LANES];
    for l in 0..LANES {
        let e = w[l] * exp_neg(-k[l] * d2[l]);
        term[l] = f32::from_bits(e.to_bits() & reached[l]);
        phi[l] += term[l];
    }
    for (ch, acc) in num.iter_mut().enumerate().take(C) {
        let t = lanes(&p.theta[ch]);
        for l in 0..LANES {
            acc[l] += t[l] * term[l];
        }
    }
    true
}

/// Every particle of `from..to`'s term at `q` in eight lanes, with no compaction: the tight
/// loop `benches/cpu_roofline.rs` takes as this machine's peak rate of terms, over particles
/// that all reach. No field query runs it: the AVX2 point kernel's compaction pays only where
/// most candidates lie out of reach (the baseline build is its point kernel, whose branch on a
/// chunk reaching nothing is always taken the same way here).
pub fn dense_sums(p: &Packed, from: usize, to: usize, q: [f32; 3]) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if simd_in_use() {
        assert!(to + LANES <= p.x.len().min(p.r2.len()).min(p.k.len()).min(p.w.len()));
        // SAFETY: the CPU has AVX2 and FMA (checked at run time by `simd_in_use`); every
        // array read holds eight floats from any particle below `to` (asserted).
        if avx512_in_use() {
            // SAFETY: and AVX-512 F (`avx512_in_use`).
            return unsafe { dense_sums_avx512(p, from, to, q) };
        }
        return unsafe { dense_sums_avx2(p, from, to, q) };
    }
    sums_lanes::<0>(p, &[(from as u32, to as u32)], q).0
}

/// [`dense_sums`] with AVX-512 in sixteen lanes (a run's last lanes masked): on CPUs that
/// split 512-bit work in two 256-bit halves (Zen 4) it still computes more terms a second than
/// the eight-lane loop (half the instructions for the same arithmetic), so it, not the AVX2
/// loop, is their peak (docs/benchmarks.md, "The CPU backend"). The exponential is
/// [`exp_neg`]'s, in sixteen lanes.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn dense_sums_avx512(p: &Packed, from: usize, to: usize, q: [f32; 3]) -> f64 {
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
unsafe fn dense_sums_avx2(p: &Packed, from: usize, to: usize, q: [f32; 3]) -> f64 {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A reproducible stream of floats in [0, 1) (a linear congruential generator).
    fn uniform(seed: u32) -> impl FnMut() -> f32 {
        let mut state = seed;
        move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        }
    }

    /// Points evaluated together ([`Packed::group_sums`]) get the bits each gets alone
    /// ([`Packed::sums`] over the same runs), in both SIMD builds, for every combination of a
    /// common or own radius and weight and every number of channels, with particles placed on
    /// the points' spheres to the last few floats (where a box test that rounded past the
    /// point test would leave one out); groups of one to eight points, close or spread.
    #[test]
    fn a_group_gives_each_point_the_bits_it_has_alone() {
        let mut next = uniform(777);
        let mut scratch = GroupScratch::default();
        let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
        let mut compared = 0;
        for round in 0..96 {
            let channels = [0, 1, 3][round % 3];
            let (own_radius, own_w) = ((round / 3) % 2 == 1, (round / 6) % 2 == 1);
            let r0 = 0.05f64 as f32;
            let spread = [0.002, 0.03, 0.2, 0.0][(round / 12) % 4];
            let centre = [next(), next(), next()].map(|v| 0.3 * (v - 0.5));
            let points = 1 + round % 8;
            let qs: Vec<[f32; 3]> = (0..points)
                .map(|_| [0, 1, 2].map(|a| centre[a] + spread * (next() - 0.5)))
                .collect();
            let mut p = Packed {
                channels,
                ..Packed::default()
            };
            for i in 0..257 + round {
                let r = if own_radius { r0 * (0.5 + next()) } else { r0 };
                let c = if i % 3 == 0 {
                    // On a point's sphere, to a few floats: the particle's own radius along a
                    // random direction, that distance stepped by -3..3 ulps.
                    let q = qs[i % points];
                    let u = [next() - 0.5, next() - 0.5, next() - 0.5];
                    let norm = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt().max(1e-3);
                    let step = (i / 3 % 7) as i32 - 3;
                    let d = f32::from_bits((r.to_bits() as i32 + step) as u32);
                    [0, 1, 2].map(|a| q[a] + u[a] / norm * d)
                } else {
                    [0, 1, 2].map(|a| centre[a] + 0.4 * (next() - 0.5))
                };
                let w = if own_w { 0.5 + next() } else { 1.0 };
                let theta = [next(), next() - 0.5, next()];
                push(&mut p, c, r, w, &theta[..channels]);
            }
            p.pad();
            let n = p.x.len() as u32 - LANES as u32;
            let runs = [(0u32, 7u32), (9, n / 2), (n / 2, n), (7, 9)];
            let alone: Vec<_> = qs.iter().map(|&q| bits(p.sums(&runs, q))).collect();
            assert!(alone.iter().any(|a| f64::from_bits(a.0) > 0.0));
            let mut out = vec![(f64::NAN, [f64::NAN; 3]); points];
            p.group_sums(&runs, &qs, &mut scratch, &mut out);
            let together: Vec<_> = out.iter().map(|&s| bits(s)).collect();
            assert_eq!(together, alone, "round {round}");
            // The AVX2 build where the dispatch chose AVX-512.
            #[cfg(target_arch = "x86_64")]
            if avx512_in_use() {
                macro_rules! avx2 {
                    ($c:literal) => {
                        match (p.one_radius.is_some(), p.same_w.is_some()) {
                            (true, true) => group_sums_avx2::<$c, true, true>,
                            (true, false) => group_sums_avx2::<$c, true, false>,
                            (false, true) => group_sums_avx2::<$c, false, true>,
                            (false, false) => group_sums_avx2::<$c, false, false>,
                        }
                    };
                }
                let build = match channels {
                    0 => avx2!(0),
                    1 => avx2!(1),
                    _ => avx2!(3),
                };
                let mut out = vec![(f64::NAN, [f64::NAN; 3]); points];
                // SAFETY: `avx512_in_use` implies AVX2, FMA and POPCNT.
                unsafe { build(&p, &runs, &qs, &mut scratch, &mut out) };
                let narrow: Vec<_> = out.iter().map(|&s| bits(s)).collect();
                assert_eq!(narrow, alone, "round {round}, AVX2 build");
            }
            compared += points;
        }
        assert!(compared > 300);
    }

    /// Appends a particle at `c` of radius `r`, weight `w` and theta per channel.
    fn push(p: &mut Packed, c: [f32; 3], r: f32, w: f32, theta: &[f32]) {
        p.x.push(c[0]);
        p.y.push(c[1]);
        p.z.push(c[2]);
        p.r2.push(r * r);
        p.k.push(4.5 / (r * r));
        p.w.push(w);
        for (ch, &t) in theta.iter().enumerate() {
            p.theta[ch].push(t);
        }
    }

    /// A scene of one radius and no density map (every k and every w the same, as a global
    /// radius writes them): `pad` notes each, and the AVX2 point kernel's broadcasts give the
    /// bits its gathers give; one particle of another radius or weight ends each.
    #[test]
    fn a_common_radius_and_weight_are_broadcast_to_the_same_bits() {
        let mut p = Packed {
            channels: 3,
            ..Packed::default()
        };
        let mut next = uniform(4242);
        // 0.1 as a data file gives it (the f64 value rounded once), 301 particles.
        let r = 0.1f64 as f32;
        for _ in 0..301 {
            let c = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.4 * v);
            push(&mut p, c, r, 1.0, &[next(), next() - 0.5, next()]);
        }
        p.pad();
        assert_eq!(
            (p.one_radius, p.same_w),
            (
                Some(OneRadius {
                    k: 4.5 / (r * r),
                    r2: r * r
                }),
                Some(1.0)
            )
        );
        if simd_in_use() {
            let runs = [(0u32, 7u32), (7, 150), (150, 301), (3, 4)];
            for _ in 0..40 {
                let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.3 * v);
                let (k, w) = (p.one_radius.unwrap(), p.same_w.unwrap());
                // SAFETY: `simd_in_use` checked the CPU's features.
                let gathered = unsafe {
                    sums_avx2::<3, false, false>(&p, &runs, q, OneRadius::default(), 0.0)
                };
                let each = unsafe {
                    [
                        sums_avx2::<3, true, true>(&p, &runs, q, k, w),
                        sums_avx2::<3, true, false>(&p, &runs, q, k, 0.0),
                        sums_avx2::<3, false, true>(&p, &runs, q, OneRadius::default(), w),
                    ]
                };
                assert!(gathered.0 > 0.0);
                let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
                for broadcast in each {
                    assert_eq!(bits(broadcast), bits(gathered), "at {q:?}");
                }
                assert_eq!(bits(p.sums(&runs, q)), bits(gathered));
            }
        }
        // One particle of its own radius, then one of its own weight.
        let mut p2 = Packed {
            channels: 0,
            ..Packed::default()
        };
        push(&mut p2, [0.0; 3], r, 1.0, &[]);
        push(&mut p2, [0.01; 3], 0.2, 1.0, &[]);
        p2.pad();
        assert_eq!((p2.one_radius, p2.same_w), (None, Some(1.0)));
        let mut p3 = Packed::default();
        push(&mut p3, [0.0; 3], r, 1.0, &[]);
        push(&mut p3, [0.01; 3], r, 0.5, &[]);
        p3.pad();
        assert_eq!(
            (p3.one_radius, p3.same_w),
            (
                Some(OneRadius {
                    k: 4.5 / (r * r),
                    r2: r * r
                }),
                None
            )
        );
    }

    /// One radius broadcast, not loaded, decides reach as the loaded radii do at the radius
    /// itself: particles within 2% of r of a point, and on an axis at r and its neighbouring
    /// floats (where `d² <= r²` is decided by the last bit), give the loaded build's bits in
    /// both SIMD builds of the point kernel.
    #[test]
    fn one_radius_decides_reach_at_the_radius_as_the_loaded_radii_do() {
        if !simd_in_use() {
            // The dispatch test (tests/cpu_f32.rs) holds `simd_in_use` to the CPU's features.
            return;
        }
        let r = 0.1f64 as f32;
        let mut p = Packed::default();
        // On the x axis from the origin: d² is x² rounded once, against r² rounded once.
        let mut axis_reached = [0, 0];
        for ulps in -40i32..40 {
            let x = f32::from_bits((r.to_bits() as i32 + ulps) as u32);
            axis_reached[usize::from(x * x <= r * r)] += 1;
            push(&mut p, [x, 0.0, 0.0], r, 1.0, &[]);
        }
        assert!(
            axis_reached[0] > 0 && axis_reached[1] > 0,
            "{axis_reached:?}"
        );
        let mut next = uniform(2718);
        for _ in 0..301 {
            let u = [next() - 0.5, next() - 0.5, next() - 0.5];
            let norm = u.iter().map(|v| v * v).sum::<f32>().sqrt().max(1e-3);
            let s = r * (0.98 + 0.04 * next()) / norm;
            push(&mut p, u.map(|v| v * s), r, 1.0, &[]);
        }
        p.pad();
        let radius = p.one_radius.expect("one radius");
        let runs = [(0u32, 80u32), (80, 381), (5, 6), (90, 97)];
        let q = [0.0f32; 3];
        let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
        // SAFETY: `simd_in_use` checked AVX2 and FMA above, `avx512_in_use` AVX-512 below.
        let loaded =
            unsafe { sums_avx2::<0, false, true>(&p, &runs, q, OneRadius::default(), 1.0) };
        assert!(loaded.0 > 0.0);
        let broadcast = unsafe { sums_avx2::<0, true, true>(&p, &runs, q, radius, 1.0) };
        assert_eq!(bits(broadcast), bits(loaded));
        if avx512_in_use() {
            let wide = unsafe { sums_avx512::<0, true, true>(&p, &runs, q, radius, 1.0) };
            assert_eq!(bits(wide), bits(loaded));
        }
        assert_eq!(bits(p.sums(&runs, q)), bits(loaded));
    }

    #[test]
    fn the_avx2_point_kernel_agrees_with_the_lanes_to_their_roundings() {
        if !simd_in_use() {
            // The dispatch test (tests/cpu_f32.rs) holds `simd_in_use` to the CPU's features.
            return;
        }
        // Particles around the origin, some out of reach; runs of awkward lengths.
        let mut p = Packed {
            channels: 3,
            ..Packed::default()
        };
        let mut next = uniform(12345);
        for _ in 0..203 {
            let r: f32 = 0.2 + 0.3 * next();
            let c = [next() - 0.5, next() - 0.5, next() - 0.5];
            push(&mut p, c, r, 0.5 + next(), &[next(), next(), next()]);
        }
        p.pad();
        let runs = [(0u32, 13u32), (20, 21), (40, 203), (100, 108)];
        for _ in 0..50 {
            let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.6 * v);
            // SAFETY: `simd_in_use` checked the CPU's features above.
            let fast =
                unsafe { sums_avx2::<3, false, false>(&p, &runs, q, OneRadius::default(), 0.0) };
            let lanes = sums_lanes::<3>(&p, &runs, q);
            assert!(lanes.0 > 0.0);
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1e-3);
            assert!(close(fast.0, lanes.0), "phi {} vs {}", fast.0, lanes.0);
            for ch in 0..3 {
                assert!(
                    close(fast.1[ch], lanes.1[ch]),
                    "{ch}: {:?} vs {:?}",
                    fast,
                    lanes
                );
            }
        }
    }

    /// The AVX-512 build of the point kernel packs the same lanes in the same order as the
    /// AVX2 build, so it gives the same bits: for every channel count and every broadcast, over
    /// runs of awkward lengths, runs that reach nothing and runs that fill the held candidates
    /// several times over (flushes), in a scene of one radius and weight (where the broadcasts
    /// apply) and one of each particle's own.
    #[test]
    fn the_avx512_point_kernel_gives_the_avx2_bits() {
        if !avx512_in_use() {
            // The dispatch test (tests/cpu_f32.rs) holds `avx512_in_use` to the CPU's features.
            return;
        }
        let mut next = uniform(9001);
        let scene = |common: bool, next: &mut dyn FnMut() -> f32| {
            let mut p = Packed {
                channels: 3,
                ..Packed::default()
            };
            // 0..700 a clump about the origin, 700..1301 far away.
            for i in 0..1301 {
                let (spread, shift) = if i < 700 { (0.3, 0.0) } else { (1.0, 10.0) };
                let (r, w) = if common {
                    (0.4, 1.0)
                } else {
                    (0.3 + 0.2 * next(), 0.25 + next())
                };
                let c = [
                    shift + spread * (next() - 0.5),
                    spread * (next() - 0.5),
                    spread * (next() - 0.5),
                ];
                push(&mut p, c, r, w, &[next(), next() - 0.5, next()]);
            }
            p.pad();
            p
        };
        let runs = [
            (0u32, 7u32),
            (7, 150),
            (150, 613),
            (3, 4),
            (700, 1301),
            (613, 700),
            (17, 17),
        ];
        let bits = |s: (f64, [f64; 3])| (s.0.to_bits(), s.1.map(f64::to_bits));
        // SAFETY (each call below): `avx512_in_use` checked the CPU's features.
        macro_rules! both {
            ($c:literal, $one_radius:literal, $same_w:literal, $p:expr, $q:expr, $k:expr, $w:expr) => {{
                let wide =
                    unsafe { sums_avx512::<$c, $one_radius, $same_w>($p, &runs, $q, $k, $w) };
                let narrow =
                    unsafe { sums_avx2::<$c, $one_radius, $same_w>($p, &runs, $q, $k, $w) };
                assert_eq!(
                    bits(wide),
                    bits(narrow),
                    "C {}, same k {}, same w {}, at {:?}",
                    $c,
                    $one_radius,
                    $same_w,
                    $q
                );
                wide.0
            }};
        }
        let mut reached = 0;
        for common in [true, false] {
            let p = scene(common, &mut next);
            assert_eq!(p.one_radius.is_some(), common);
            let (k, w) = (p.one_radius.unwrap_or_default(), p.same_w.unwrap_or(0.0));
            for i in 0..30 {
                let q = if i % 3 == 2 {
                    [10.0 + next() - 0.5, next() - 0.5, next() - 0.5]
                } else {
                    [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.5 * v)
                };
                let phi = both!(0, false, false, &p, q, OneRadius::default(), 0.0);
                both!(1, false, false, &p, q, OneRadius::default(), 0.0);
                both!(3, false, false, &p, q, OneRadius::default(), 0.0);
                if common {
                    both!(0, true, true, &p, q, k, w);
                    both!(0, true, false, &p, q, k, 0.0);
                    both!(0, false, true, &p, q, OneRadius::default(), w);
                    both!(1, true, true, &p, q, k, w);
                    both!(3, true, true, &p, q, k, w);
                    both!(3, true, false, &p, q, k, 0.0);
                    both!(3, false, true, &p, q, OneRadius::default(), w);
                }
                reached += usize::from(phi > 100.0);
            }
        }
        assert!(reached > 10, "the clump reaches most queries ({reached})");
    }

    /// The AVX-512 dense loop (the peak on a CPU that has it) sums the terms the AVX2 loop and
    /// the f64 sum do, to their roundings (sixteen lanes add in another order than eight), over
    /// ranges whose ends are not multiples of sixteen, shorter than sixteen, and empty.
    #[test]
    fn the_avx512_dense_loop_sums_the_avx2_terms() {
        if !avx512_in_use() {
            return;
        }
        let mut p = Packed::default();
        let mut next = uniform(31337);
        for _ in 0..1000 {
            let r: f32 = 0.2 + 0.4 * next();
            push(
                &mut p,
                [next(), next(), next()].map(|v| v - 0.5),
                r,
                0.5 + next(),
                &[],
            );
        }
        p.pad();
        for (from, to) in [
            (0, 1000),
            (3, 613),
            (5, 16),
            (100, 101),
            (40, 40),
            (999, 1000),
        ] {
            for _ in 0..10 {
                let q = [next() - 0.5, next() - 0.5, next() - 0.5].map(|v| 0.5 * v);
                // SAFETY: `avx512_in_use` checked the CPU's features; the padding holds
                // eight (AVX2) floats past `to`, and the AVX-512 loop masks its last lanes.
                let (wide, narrow) = unsafe {
                    (
                        dense_sums_avx512(&p, from, to, q),
                        dense_sums_avx2(&p, from, to, q),
                    )
                };
                let exact: f64 = (from..to)
                    .map(|j| {
                        let d2: f64 = [p.x[j] - q[0], p.y[j] - q[1], p.z[j] - q[2]]
                            .map(|d| f64::from(d) * f64::from(d))
                            .iter()
                            .sum();
                        if d2 <= f64::from(p.r2[j]) {
                            f64::from(p.w[j]) * (-f64::from(p.k[j]) * d2).exp()
                        } else {
                            0.0
                        }
                    })
                    .sum();
                let tolerance = 1e-5 * exact.max(1e-30);
                assert!(
                    (wide - exact).abs() <= tolerance && (narrow - exact).abs() <= tolerance,
                    "{from}..{to} at {q:?}: AVX-512 {wide}, AVX2 {narrow}, f64 {exact}"
                );
                if to == from {
                    assert_eq!(wide, 0.0);
                }
            }
        }
    }

    /// Every build of the point kernel against the sum as written in f64, over runs where far
    /// more candidates reach than the kernel holds before computing (its flushes), runs that
    /// reach nothing, runs of one particle, a particle in two runs (counted twice), and the
    /// dense loop over one run.
    #[test]
    fn the_point_kernel_sums_every_reached_term_once() {
        let mut p = Packed {
            channels: 1,
            ..Packed::default()
        };
        let mut next = uniform(777);
        // 0..700: a clump within reach of the origin (radius 0.3..0.5, centres within 0.15);
        // 700..1301: far away.
        for i in 0..1301 {
            let (spread, shift) = if i < 700 { (0.3, 0.0) } else { (1.0, 10.0) };
            let r: f32 = 0.3 + 0.2 * next();
            let c = [
                shift + spread * (next() - 0.5),
                spread * (next() - 0.5),
                spread * (next() - 0.5),
            ];
            push(&mut p, c, r, 0.25 + next(), &[next() - 0.5]);
        }
        p.pad();
        let runs = [(0u32, 613u32), (700, 1301), (613, 614), (614, 700), (5, 17)];
        let brute = |q: [f32; 3]| -> (f64, f64) {
            let (mut phi, mut num) = (0.0, 0.0);
            for &(a, b) in &runs {
                for j in a as usize..b as usize {
                    let d2 = [p.x[j] - q[0], p.y[j] - q[1], p.z[j] - q[2]]
                        .map(|d| f64::from(d) * f64::from(d))
                        .iter()
                        .sum::<f64>();
                    if d2 <= f64::from(p.r2[j]) {
                        let term = f64::from(p.w[j]) * (-f64::from(p.k[j]) * d2).exp();
                        phi += term;
                        num += f64::from(p.theta[0][j]) * term;
                    }
                }
            }
            (phi, num)
        };
        // The baseline build, then AVX2, then AVX-512, as far as the CPU has them.
        let builds = [true, simd_in_use(), avx512_in_use()]
            .iter()
            .filter(|&&available| available)
            .count();
        for q in [
            [0.0, 0.0, 0.0],
            [0.05, -0.1, 0.02],
            [10.2, 0.1, -0.3],
            [3.0, 3.0, 3.0],
        ] {
            let (phi, num) = brute(q);
            for simd in 0..builds {
                allow_simd(simd >= 1);
                allow_avx512(simd == 2);
                let (got_phi, got_num) = p.sums(&runs, q);
                allow_simd(true);
                allow_avx512(true);
                let scale = phi.max(1e-30);
                assert!(
                    (got_phi - phi).abs() <= 1e-5 * scale,
                    "{q:?}, build {simd}: phi {got_phi} vs {phi}"
                );
                assert!(
                    (got_num[0] - num).abs() <= 1e-5 * scale,
                    "{q:?}, build {simd}: theta {} vs {num}",
                    got_num[0]
                );
            }
            match q[0] {
                // Hundreds of terms: the kernel flushes its held candidates several times.
                x if x < 1.0 => assert!(phi > 100.0, "the clump reaches {q:?}: {phi}"),
                x if x > 9.0 => assert!(phi > 1.0, "the far particles reach {q:?}: {phi}"),
                _ => assert_eq!(phi, 0.0, "nothing reaches {q:?}"),
            }
        }
        // The dense loop over one run equals the kernel over it.
        let q = [0.02, 0.01, -0.03];
        let dense = dense_sums(&p, 0, 613, q);
        let kernel = p.sums(&[(0, 613)], q).0;
        assert!(
            (dense - kernel).abs() <= 1e-5 * kernel,
            "{dense} vs {kernel}"
        );
    }

    /// The packet kernel's narrowing with AVX2 keeps exactly the particles, in the order, that
    /// the lanes keep (the same operations), into poisoned candidate slots, over boxes from a
    /// point to wider than the particles, and runs of awkward lengths.
    #[test]
    fn the_avx2_narrowing_keeps_what_the_lanes_keep() {
        if !simd_in_use() {
            return;
        }
        let mut p = Packed::default();
        let mut next = uniform(4242);
        for _ in 0..517 {
            let r: f32 = 0.01 + 0.1 * next();
            push(&mut p, [next(), next(), next()], r, 1.0, &[]);
        }
        p.pad();
        let runs = [(0u32, 1u32), (3, 200), (200, 209), (300, 517), (17, 17)];
        let total: usize = runs.iter().map(|&(a, b)| (b - a) as usize).sum();
        let mut kept_any = false;
        for size in [0.0, 0.01, 0.1, 0.3, 2.0] {
            for _ in 0..20 {
                let lo = [next(), next(), next()];
                let hi = lo.map(|v| v + size * next());
                let mut fast = vec![u32::MAX; total + LANES];
                let mut lanes = vec![u32::MAX - 1; total + LANES];
                // SAFETY: `simd_in_use` checked the CPU's features above.
                let n_fast = unsafe { narrow_avx2(&p, &runs, lo, hi, &mut fast) };
                let n_lanes = narrow_lanes(&p, &runs, lo, hi, &mut lanes);
                assert_eq!(&fast[..n_fast], &lanes[..n_lanes], "box {lo:?} {hi:?}");
                kept_any |= n_fast > 0;
            }
        }
        assert!(kept_any, "some box keeps particles");
    }

    /// The worst relative error of `exp` over the kernel's range `[-4.5, 0]`, every f32 step
    /// of the way (about 4e7 inputs, a stride of them).
    fn worst_exp_error(exp: impl Fn(f32) -> f32) -> f64 {
        let mut worst = 0.0f64;
        let mut x = 0.0f32;
        while x >= -4.5 {
            let got = f64::from(exp(x));
            worst = worst.max((got / f64::from(x).exp() - 1.0).abs());
            x = f32::from_bits(x.to_bits() + 37).min(-f32::MIN_POSITIVE);
        }
        worst
    }

    /// The per-build constants the error bound uses are the exponentials' measured errors
    /// (not below them, and not more than 1.5 times above).
    #[test]
    fn exp_errors_are_as_stated() {
        let baseline = worst_exp_error(exp_neg);
        assert!(
            baseline <= EXP_ERROR_BASELINE && EXP_ERROR_BASELINE <= 1.5 * baseline,
            "baseline build: measured {baseline:e}, stated {EXP_ERROR_BASELINE:e}"
        );
        #[cfg(target_arch = "x86_64")]
        if avx2_available() {
            let fma = worst_exp_error(|x| {
                use core::arch::x86_64::*;
                // SAFETY: AVX2 and FMA are present (checked above).
                unsafe {
                    let v = exp_neg_avx2(_mm256_set1_ps(x));
                    _mm256_cvtss_f32(v)
                }
            });
            assert!(
                fma <= EXP_ERROR_FMA && EXP_ERROR_FMA <= 1.5 * fma,
                "FMA build: measured {fma:e}, stated {EXP_ERROR_FMA:e}"
            );
        }
    }

    #[test]
    fn exp_neg_is_within_its_stated_error() {
        let mut worst = 0.0f64;
        for i in 0..=1_000_000 {
            let x = -87.0 * f64::from(i) / 1e6;
            let x32 = x as f32;
            let got = f64::from(exp_neg(x32));
            let want = f64::from(x32).exp();
            worst = worst.max((got / want - 1.0).abs());
        }
        assert!(worst < 2.5e-7, "largest relative error {worst:e}");
        assert_eq!(exp_neg(0.0), 1.0);
        assert_eq!(exp_neg(-1e30), exp_neg(-87.0));
    }
}
