//! The reference's point queries over cells: a point's candidates (the particles of the cells
//! around it, `accel::cells`) tested four at a time in f64, and the term of each one within
//! reach computed exactly as `Particles::accumulate` computes it (the same operations in the
//! same order: `w · exp(-4.5 d² / r²)` with the standard library's `exp`), so a term is that
//! function's value bit for bit and only the order of summation differs from a brute-force sum.
//! Nothing is approximated: this is the reference, made faster by visiting fewer particles and
//! testing their distances in vector lanes, not by cheaper arithmetic.
//!
//! The distance tests are lane arithmetic over `[f64; 4]`, compiled twice like the f32 kernel
//! (baseline x86-64, and AVX2 chosen at run time: [`super::f32_kernel::simd_in_use`]); without
//! contraction into fused multiply-adds both builds round alike, so they are equal bit for bit.

use glam::DVec3;
use rayon::prelude::*;

use super::f32_kernel::simd_in_use;
use super::{Kernel, Particles, Theta};

/// Candidates tested together.
pub(super) const LANES: usize = 4;

/// The particles in the order the caller chose (cell by cell), as f64 structure of arrays
/// followed by [`LANES`] that reach nothing, so four lanes can be read from any particle on.
#[derive(Clone, Debug, Default)]
pub(super) struct Packed64 {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    /// `r * r` as the reference computes it, or -1 (reaches no point) for the padding.
    r2: Vec<f64>,
    w: Vec<f64>,
    theta: [Vec<f64>; 3],
    channels: usize,
    kernel: Kernel,
}

impl Packed64 {
    /// Particles `order[0]`, `order[1]`, … of `p`.
    pub(super) fn gather(p: &Particles, order: &[u32]) -> Packed64 {
        let f64s = |f: &(dyn Fn(usize) -> f64 + Sync)| -> Vec<f64> {
            let mut v: Vec<f64> = order.par_iter().map(|&i| f(i as usize)).collect();
            v.extend([0.0; LANES]);
            v
        };
        let (theta, channels) = match &p.theta {
            Theta::None => ([Vec::new(), Vec::new(), Vec::new()], 0),
            Theta::Scalar(t) => ([f64s(&|i| t[i]), Vec::new(), Vec::new()], 1),
            Theta::Rgb(c) => ([0, 1, 2].map(|ch| f64s(&|i| c[i][ch])), 3),
        };
        let mut r2 = f64s(&|i| p.radii[i] * p.radii[i]);
        let n = r2.len() - LANES;
        r2[n..].fill(-1.0);
        Packed64 {
            x: f64s(&|i| p.centers[i].x),
            y: f64s(&|i| p.centers[i].y),
            z: f64s(&|i| p.centers[i].z),
            r2,
            w: f64s(&|i| p.weights[i]),
            theta,
            channels,
            kernel: p.kernel,
        }
    }

    /// Bytes of the arrays.
    pub(super) fn bytes(&self) -> usize {
        8 * (5 + self.channels) * self.x.len()
    }

    /// Σ phi_i and Σ theta_i phi_i at `q` (local coordinates) over the particles of `runs`
    /// (ranges of this order), in f64.
    #[inline]
    pub(super) fn sums(&self, runs: &[(u32, u32)], q: DVec3) -> (f64, [f64; 3]) {
        match self.channels {
            0 => sums::<0>(self, runs, q),
            1 => sums::<1>(self, runs, q),
            _ => sums::<3>(self, runs, q),
        }
    }
}

#[inline]
fn sums<const C: usize>(p: &Packed64, runs: &[(u32, u32)], q: DVec3) -> (f64, [f64; 3]) {
    #[cfg(target_arch = "x86_64")]
    if simd_in_use() {
        // SAFETY: the CPU has AVX2 and FMA (checked at run time by `simd_in_use`).
        return unsafe { sums_avx2::<C>(p, runs, q) };
    }
    sums_lanes::<C>(p, runs, q)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sums_avx2<const C: usize>(
    p: &Packed64,
    runs: &[(u32, u32)],
    q: DVec3,
) -> (f64, [f64; 3]) {
    sums_lanes::<C>(p, runs, q)
}

/// Reached candidates held before their terms are computed: a flush computes them in order.
const HELD: usize = 32;

/// The distance tests in lanes, the reached candidates compacted (branch-free) into a small
/// buffer, then their terms in the order of the runs. Two passes because the standard
/// library's `exp` is a call: computed inside the distance loop, every call spilled the loop's
/// state and the test of which lanes reached mispredicted (half the kernel's time in a
/// profile). A run's last chunk reads past its end and masks those lanes.
#[inline(always)]
fn sums_lanes<const C: usize>(p: &Packed64, runs: &[(u32, u32)], q: DVec3) -> (f64, [f64; 3]) {
    if p.kernel.is_sph() {
        sums_kernel::<C, true>(p, runs, q)
    } else {
        sums_kernel::<C, false>(p, runs, q)
    }
}

#[inline(always)]
fn sums_kernel<const C: usize, const SPH: bool>(
    p: &Packed64,
    runs: &[(u32, u32)],
    q: DVec3,
) -> (f64, [f64; 3]) {
    let mut phi = 0.0;
    let mut num = [0.0; 3];
    let mut held_index = [0u32; HELD];
    let mut held_d2 = [0f64; HELD];
    let mut n = 0;
    let mut flush = |held_index: &[u32], held_d2: &[f64]| {
        for (&j, &d2) in held_index.iter().zip(held_d2) {
            let j = j as usize;
            // The Gaussian written out (the reference's form, and the common case);
            // another kernel through its one definition.
            let term = if SPH {
                p.w[j] * p.kernel.profile(d2, p.r2[j])
            } else {
                p.w[j] * (-4.5 * d2 / p.r2[j]).exp()
            };
            phi += term;
            for (acc, t) in num.iter_mut().zip(&p.theta).take(C) {
                *acc += t[j] * term;
            }
        }
    };
    for &(a, b) in runs {
        let (mut at, b) = (a as usize, b as usize);
        while at < b {
            let lanes =
                |v: &[f64]| -> [f64; LANES] { v[at..at + LANES].try_into().expect("padded") };
            let (x, y, z, r2) = (lanes(&p.x), lanes(&p.y), lanes(&p.z), lanes(&p.r2));
            let mut d2 = [0.0; LANES];
            let mut reached = 0u32;
            for l in 0..LANES {
                // `(q - c).length_squared()`, as the reference computes it.
                let (dx, dy, dz) = (q.x - x[l], q.y - y[l], q.z - z[l]);
                d2[l] = dx * dx + dy * dy + dz * dz;
                reached |= u32::from(d2[l] <= r2[l]) << l;
            }
            reached &= (1u32 << (b - at).min(LANES)) - 1;
            // Apart from the lanes above (a loop that also advanced `n` was not vectorised):
            // every lane is written, the reached ones advance.
            for (l, &d2) in d2.iter().enumerate() {
                held_index[n] = (at + l) as u32;
                held_d2[n] = d2;
                n += ((reached >> l) & 1) as usize;
            }
            at += LANES;
            if n > HELD - LANES {
                flush(&held_index[..n], &held_d2[..n]);
                n = 0;
            }
        }
    }
    flush(&held_index[..n], &held_d2[..n]);
    (phi, num)
}
