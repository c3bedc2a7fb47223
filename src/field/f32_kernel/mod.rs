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

#[cfg(test)]
mod tests;
#[cfg(target_arch = "x86_64")]
mod x86_group;
#[cfg(target_arch = "x86_64")]
mod x86_lanes;
#[cfg(target_arch = "x86_64")]
mod x86_point;

#[cfg(target_arch = "x86_64")]
use x86_group::*;
#[cfg(target_arch = "x86_64")]
use x86_lanes::*;
#[cfg(target_arch = "x86_64")]
use x86_point::*;

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
/// The fused multiply-add build's bound (AVX2 and AVX-512); see [`EXP_ERROR_BASELINE`].
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
    /// Particle centres' x in f32 local coordinates (relative to the field's origin).
    pub x: Vec<f32>,
    /// Particle centres' y in f32 local coordinates.
    pub y: Vec<f32>,
    /// Particle centres' z in f32 local coordinates.
    pub z: Vec<f32>,
    /// r², or -1 (reaches no point) for the padding.
    pub r2: Vec<f32>,
    /// 4.5 / r² (the kernel's exponent is `-k d²`).
    pub k: Vec<f32>,
    /// The density map's weight w(t).
    pub w: Vec<f32>,
    /// theta per channel (the normalised attribute, or linear RGB); `channels` of them.
    pub theta: [Vec<f32>; 3],
    /// Theta channels per particle: 0 (density only), 1 (post-classification: t) or 3
    /// (pre-classification: linear RGB).
    pub channels: usize,
    /// `k` and `r2` where every particle has the same (one radius: no radius map, no
    /// smoothing lengths), and `w` likewise (no density map); set by [`Packed::pad`]. The
    /// SIMD point kernels then broadcast them instead of gathering `k` for each term and
    /// loading `r2` for each test: a scene that models neither pays for neither (measured in
    /// docs/notes/2026-12-04-cpu-point-kernel.md, "What a term gathers" and "One radius
    /// broadcasts r² too").
    pub one_radius: Option<OneRadius>,
    /// The weight `w` when every particle has the same (bit for bit), else `None`; set by
    /// [`Packed::pad`].
    pub same_w: Option<f32>,
}

/// The kernel's constants of one radius r: `k` = 4.5 / r² and `r2` = r², as every particle's
/// arrays hold them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OneRadius {
    /// 4.5 / r², the exponent factor (the kernel is `exp(-k d²)`).
    pub k: f32,
    /// r², the squared radius a distance is tested against.
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
