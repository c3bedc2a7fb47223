//! The CPU twin of `shaders_glsl/shared/rbf.glsl`: the particle radius rule (the shaders'
//! [`RadiusRule`], which the ash backend bounds its CPU-built LBVH's boxes by), the sums and the
//! SPH kernels' profiles in f32.

pub use crate::backend::shaders::RadiusRule;
use crate::values::Kernel;

/// A point's sum as `rbf.glsl`'s `sum_add` keeps it: plainly (`compensated` false) or with
/// Kahan's compensation, in f32, one cluster's sum at a time.
#[derive(Clone, Copy, Debug, Default)]
pub struct PointSum {
    /// The running sums: Phi and the Theta numerator.
    pub sum: [f32; 4],
    /// Kahan's compensation of each sum (0 when summed plainly).
    pub comp: [f32; 4],
}

impl PointSum {
    /// `sum_add(acc, comp, v)`.
    pub fn add(&mut self, v: [f32; 4], compensated: bool) {
        for ((sum, comp), v) in self.sum.iter_mut().zip(&mut self.comp).zip(v) {
            if compensated {
                let y = v - *comp;
                let t = *sum + y;
                *comp = (t - *sum) - y;
                *sum = t;
            } else {
                *sum += v;
            }
        }
    }
}

/// `rbf.glsl`'s `rbf_profile` for an SPH kernel, in f32: its profile at squared distance `d2`
/// within radius `r`, `q` computed as the shader computes it and `f(q)` by the one definition
/// ([`Kernel::of_q`]) in f32.
pub fn sph_profile(kernel: Kernel, d2: f32, r: f32) -> f32 {
    if kernel == Kernel::GaussianRbf {
        return (-4.5 * d2 / (r * r)).exp();
    }
    kernel.of_q(kernel.support() as f32 * (d2 / (r * r)).sqrt())
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::backend::precision::{SPH_TERM_FLOOR, U, sph_kernel_error};

    /// The f32 profile of every SPH kernel, on fresh random distances and radii, errs from the
    /// f64 definition (`values::Kernel::profile`, at the same f32 inputs) by at most the error
    /// model's kernel part (`backend::precision`) wherever the term is above the floor that
    /// part covers, with the argument `d²/r²` rounded twice (r² and the division, IEEE); and
    /// the model is not vacuous: the worst error is within 30x of it.
    #[test]
    fn the_f32_sph_profiles_keep_the_error_models_kernel_bound() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for kernel in Kernel::ALL.into_iter().filter(|k| k.is_sph()) {
            let bound = sph_kernel_error(kernel, 2.0 * U, false);
            let floor = SPH_TERM_FLOOR * kernel.of_q(0.0);
            let mut worst = 0.0f64;
            for _ in 0..200_000 {
                let r: f32 = 10f32.powf(rng.random_range(-4.0..3.0));
                let d: f32 = r * rng.random::<f32>();
                let d2 = d * d;
                let want = kernel.profile(f64::from(d2), f64::from(r) * f64::from(r));
                if want < floor {
                    continue;
                }
                let got = f64::from(sph_profile(kernel, d2, r));
                worst = worst.max((got / want - 1.0).abs());
            }
            assert!(worst <= bound, "{kernel}: {worst:e} > bound {bound:e}");
            assert!(
                worst * 30.0 >= bound,
                "{kernel}: {worst:e} far below {bound:e}"
            );
        }
    }

    /// Over many positive terms of a wide dynamic range, the plain f32 sum stays within its
    /// bound ((n - 1) u) and the compensated one within 2u (plus n u², nothing here), far below
    /// the plain one's error: what `backend::precision` counts on.
    #[test]
    fn compensated_sums_keep_their_bound_whatever_the_count() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        for n in [1usize, 7, 100, 2000, 30_000] {
            let terms: Vec<f32> = (0..n)
                .map(|_| (rng.random::<f32>() * -4.5).exp() * 10f32.powi(rng.random_range(-3..3)))
                .collect();
            let exact: f64 = terms.iter().map(|&t| f64::from(t)).sum();
            let (mut plain, mut comp) = (PointSum::default(), PointSum::default());
            for &t in &terms {
                plain.add([t; 4], false);
                comp.add([t; 4], true);
            }
            let plain_err = (f64::from(plain.sum[0]) / exact - 1.0).abs();
            let comp_err = (f64::from(comp.sum[0]) / exact - 1.0).abs();
            let n_u = (n.saturating_sub(1)) as f64 * U;
            assert!(
                plain_err <= n_u / (1.0 - n_u) + 1e-300,
                "n {n}: plain {plain_err:e}"
            );
            assert!(
                comp_err <= 2.0 * U + 4.0 * n as f64 * U * U,
                "n {n}: compensated {comp_err:e}"
            );
            if n >= 2000 {
                assert!(
                    comp_err * 10.0 < plain_err,
                    "n {n}: {comp_err:e} vs {plain_err:e}"
                );
            }
        }
    }
}
