//! The kernel a particle spreads its value with (method.md §2, docs/formats.md): the paper's
//! unnormalised Gaussian RBF, or an SPH kernel normalised in 3D, as SPH codes, sarracen and
//! yt define them. One definition, in f64, for the CPU's reference and the grid scatter; the
//! GPUs' is `rbf_profile` in `shaders_glsl/shared/rbf.glsl` (its f32 twin:
//! `backend::shaders::cpu::rbf::profile`).
//!
//! A particle's radius r is where its kernel reaches 0 (or is truncated): for an SPH kernel
//! `r = support · h`. Every kernel is written as a *profile* of the squared distance over the
//! squared radius, `d² / r²` in [0, 1], so that the cut-off test `d² <= r²` and the radius rule
//! are the same for all of them:
//!
//! ```text
//! gaussian-rbf      exp(-4.5 d²/r²)                               (the paper's w exp(-0.5 (3d/r)²))
//! sph-cubic         (2-q)³/4 - (1-q)³           q = d/h, support 2h    σ = 1/π
//! sph-quintic       (3-q)⁵ - 6(2-q)⁵ + 15(1-q)⁵      support 3h        σ = 1/(120π)
//! sph-wendland-c2   (1-q/2)⁴ (1+2q)                   support 2h        σ = 21/(16π)
//! sph-wendland-c4   (1-q/2)⁶ (1+3q+35q²/12)           support 2h        σ = 495/(256π)
//! ```
//! with `(x)` standing for `max(x, 0)` in the splines. An SPH term is then `V σ/h³ f(q)` with
//! `V = m/ρ` the particle's volume, so `Σ V W` reproduces a uniform field's value: see
//! [`Kernel::weight_factor`].

use serde::{Deserialize, Serialize};

use super::shader_constants::{
    KERNEL_GAUSSIAN_RBF, KERNEL_SIGMA, KERNEL_SPH_CUBIC, KERNEL_SPH_QUINTIC,
    KERNEL_SPH_WENDLAND_C2, KERNEL_SPH_WENDLAND_C4, KERNEL_SUPPORT,
};

/// Which kernel the field is summed with.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
#[repr(u32)]
pub enum Kernel {
    /// The paper's Gaussian `w exp(-0.5 (3d/r)²)`, truncated at r, not normalised.
    #[default]
    GaussianRbf = KERNEL_GAUSSIAN_RBF,
    /// The M4 cubic spline, support 2h (Monaghan 1992; Phantom, sarracen).
    SphCubic = KERNEL_SPH_CUBIC,
    /// The M6 quintic spline, support 3h.
    SphQuintic = KERNEL_SPH_QUINTIC,
    /// Wendland C2, support 2h (Dehnen & Aly 2012, with H = 2h).
    SphWendlandC2 = KERNEL_SPH_WENDLAND_C2,
    /// Wendland C4, support 2h.
    SphWendlandC4 = KERNEL_SPH_WENDLAND_C4,
}

impl Kernel {
    /// Every kernel, in the order of their `KERNEL` values.
    pub const ALL: [Kernel; 5] = [
        Kernel::GaussianRbf,
        Kernel::SphCubic,
        Kernel::SphQuintic,
        Kernel::SphWendlandC2,
        Kernel::SphWendlandC4,
    ];

    /// The value of the `KERNEL` specialisation constant (the shaders' `KERNEL_*`, which the
    /// variants take as theirs), and the index of the kernel's support and σ.
    pub fn id(self) -> u32 {
        self as u32
    }

    /// The CLI's spelling.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::GaussianRbf => "gaussian-rbf",
            Kernel::SphCubic => "sph-cubic",
            Kernel::SphQuintic => "sph-quintic",
            Kernel::SphWendlandC2 => "sph-wendland-c2",
            Kernel::SphWendlandC4 => "sph-wendland-c4",
        }
    }

    /// Whether this is an SPH kernel: normalised, each term weighted by the particle's volume.
    pub fn is_sph(self) -> bool {
        self != Kernel::GaussianRbf
    }

    /// The support in units of h (1 for the Gaussian, whose radius is its own unit).
    pub fn support(self) -> f64 {
        KERNEL_SUPPORT[self as usize]
    }

    /// The 3D normalisation σ (1 for the Gaussian).
    pub fn sigma(self) -> f64 {
        KERNEL_SIGMA[self as usize]
    }

    /// What multiplies the profile of a particle of radius `r` and volume `volume` (`m/ρ`):
    /// `V σ / h³` with `h = r / support` for an SPH kernel; 1 for the Gaussian, whose weight is
    /// the density map's alone. The density map's `w(t)` multiplies either.
    #[inline]
    pub fn weight_factor(self, r: f64, volume: f64) -> f64 {
        if self.is_sph() {
            let s = self.support();
            volume * self.sigma() * (s * s * s) / (r * r * r)
        } else {
            1.0
        }
    }

    /// The profile at squared distance `d2` from a particle of squared radius `r2`, for
    /// `d2 <= r2` (beyond, the caller adds nothing). The Gaussian's is computed as the
    /// reference always has, `exp(-4.5 d² / r²)`.
    #[inline(always)]
    pub fn profile(self, d2: f64, r2: f64) -> f64 {
        match self {
            Kernel::GaussianRbf => (-4.5 * d2 / r2).exp(),
            _ => self.of_q(self.support() * (d2 / r2).sqrt()),
        }
    }

    /// An SPH kernel's unnormalised `f(q)`, `q = d / h` (0 beyond the support; the Gaussian's
    /// is `exp(-4.5 q²)` in units of its radius), in f64 or, as the shaders compute it, in f32
    /// (`backend::shaders::cpu::rbf::sph_profile`, the twin of `rbf.glsl`'s `rbf_profile`).
    #[inline(always)]
    pub fn of_q<F: num_traits::Float>(self, q: F) -> F {
        let c = |v: f64| F::from(v).expect("a kernel constant");
        let zero = F::zero();
        let plus = |x: F| x.max(zero);
        match self {
            Kernel::GaussianRbf => {
                if q <= F::one() {
                    (c(-4.5) * q * q).exp()
                } else {
                    zero
                }
            }
            Kernel::SphCubic => {
                let (a, b) = (plus(c(2.0) - q), plus(F::one() - q));
                c(0.25) * (a * a * a) - b * b * b
            }
            Kernel::SphQuintic => {
                let fifth = |x: F| {
                    let x = plus(x);
                    let x2 = x * x;
                    x2 * x2 * x
                };
                fifth(c(3.0) - q) - c(6.0) * fifth(c(2.0) - q) + c(15.0) * fifth(F::one() - q)
            }
            Kernel::SphWendlandC2 => {
                let a = plus(F::one() - c(0.5) * q);
                let a2 = a * a;
                a2 * a2 * (F::one() + c(2.0) * q)
            }
            Kernel::SphWendlandC4 => {
                let a = plus(F::one() - c(0.5) * q);
                let a2 = a * a;
                a2 * a2 * a2 * (F::one() + c(3.0) * q + c(35.0 / 12.0) * q * q)
            }
        }
    }
}

impl std::fmt::Display for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each SPH kernel integrates to 1 over its support (σ is right for f as written), in
    /// shells of q, by Simpson's rule on 20,000 intervals.
    #[test]
    fn sph_kernels_are_normalised_in_3d() {
        for k in Kernel::ALL.into_iter().filter(|k| k.is_sph()) {
            let s = k.support();
            let n = 20_000;
            let dq = s / n as f64;
            let g = |q: f64| 4.0 * std::f64::consts::PI * q * q * k.sigma() * k.of_q(q);
            let mut sum = g(0.0) + g(s);
            for i in 1..n {
                sum += if i % 2 == 1 { 4.0 } else { 2.0 } * g(i as f64 * dq);
            }
            let integral = sum * dq / 3.0;
            assert!((integral - 1.0).abs() < 1e-9, "{k}: integral {integral}");
        }
    }

    /// Hand-derived values: each kernel at its centre, at h, and at its support's edge, and
    /// continuous there.
    #[test]
    fn sph_kernels_match_their_hand_derived_values() {
        use std::f64::consts::PI;
        let cases = [
            // kernel, W(0) h³, W(h) h³
            (Kernel::SphCubic, 1.0 / PI, 0.25 / PI),
            (
                Kernel::SphQuintic,
                66.0 / (120.0 * PI),
                (32.0 - 6.0) / (120.0 * PI),
            ),
            (
                Kernel::SphWendlandC2,
                21.0 / (16.0 * PI),
                21.0 / (16.0 * PI) * 3.0 / 16.0,
            ),
            (
                Kernel::SphWendlandC4,
                495.0 / (256.0 * PI),
                495.0 / (256.0 * PI) * (1.0 + 3.0 + 35.0 / 12.0) / 64.0,
            ),
        ];
        for (k, at_0, at_h) in cases {
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs().max(1e-300);
            assert!(close(k.sigma() * k.of_q(0.0), at_0), "{k} at 0");
            assert!(close(k.sigma() * k.of_q(1.0), at_h), "{k} at h");
            assert_eq!(k.of_q(k.support()), 0.0, "{k} at its support");
            assert!(
                k.of_q(k.support() * (1.0 - 1e-6)) < 1e-12,
                "{k} near its support"
            );
            // The profile over d²/r² is the same function.
            let r = 0.37 * k.support();
            let d = 0.37;
            assert!(
                close(k.profile(d * d, r * r), k.of_q(1.0)),
                "{k}: profile at h"
            );
        }
    }

    /// A particle's total weight over all space is its volume: Σ V W reproduces a uniform
    /// field (what `weight_factor` is for).
    #[test]
    fn a_particle_carries_its_volume() {
        for k in Kernel::ALL.into_iter().filter(|k| k.is_sph()) {
            let (r, volume) = (0.8, 0.003);
            let n = 4000;
            let dd = r / n as f64;
            let total: f64 = (0..n)
                .map(|i| {
                    let d = (i as f64 + 0.5) * dd;
                    4.0 * std::f64::consts::PI
                        * d
                        * d
                        * k.weight_factor(r, volume)
                        * k.profile(d * d, r * r)
                        * dd
                })
                .sum();
            assert!((total / volume - 1.0).abs() < 1e-6, "{k}: {total}");
        }
    }
}
