//! The march's step bias in a targeted render (`render::target`): how far the converged
//! image at a march step lies from the converged reference, calibrated from images at a few
//! steps, with no reference.

use crate::values::Image;

/// The march's bias (RMSE over linear RGB) as a function of the step, calibrated from
/// images at `dt0`, `2 dt0` and `4 dt0`.
///
/// The two coarser steps' bias is measured directly (their difference from the image at `dt0`,
/// noise subtracted in quadrature, plus the bias at `dt0`); the bias at `dt0` and finer comes
/// from the order `p` (Richardson). The bias is rarely a clean power law (it stays within the
/// noise while the step resolves the kernel, then grows fast), so the coarser steps are never
/// extrapolated from finer ones, and four times `dt0` is only chosen when its bias *bound* (the
/// estimate plus what the noise could hide) fits the target.
///
/// Below the finest step measured, a bias that stood clear of the noise is extrapolated at
/// most linearly ([`Self::MAX_ORDER`]): the RMSE of a bias that sits at sharp features (opaque
/// surfaces, kernels thinner than the step) falls at orders 0.3-0.9 there while the coarser
/// pair can show 2-3 (the step outgrowing the kernel at `4 dt0`), and an order from those two
/// differences put the bias at `dt0` at 0.44 of the truth on the sharp-gradient scene
/// (docs/notes/2026-12-06-target-error.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepBias {
    /// The finest step calibrated, data units.
    pub dt0: f64,
    /// The estimated bias at `dt0`, `2 dt0`, `4 dt0`.
    pub levels: [f64; 3],
    /// What the calibration images' noise could hide at each of them.
    pub hidden: [f64; 3],
    /// `p` in bias ∝ dt^p, at `dt0` and finer.
    pub order: f64,
    /// Whether the step's effect at `2 dt0` stood clear of the calibration images' noise.
    pub resolved: bool,
    /// The differences the levels rest on ([`Difference`]): from `dt0` to `2 dt0` and from
    /// `dt0` to `4 dt0` (the coarse calibration's one difference, from `2 dt0` to `4 dt0`,
    /// twice).
    pub differences: [Difference; 2],
    /// The bias at `dt0`, `2 dt0`, `4 dt0` were it to fall at the slowest order the
    /// calibration assumes ([`Self::MIN_ORDER`]) below `2 dt0`.
    pub slow: [f64; 3],
    /// The same plus what the calibration's noise could hide, at that order: the most the bias
    /// may be.
    pub slow_bound: [f64; 3],
}

/// One difference between two calibration images: its size with the noise subtracted in
/// quadrature, the noise of the difference, and whether it stood clear of that noise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Difference {
    pub size: f64,
    pub noise: f64,
    pub resolved: bool,
}

impl StepBias {
    /// The order assumed where the calibration cannot tell: the jittered march's error on a
    /// smooth field (the images bound it anyway: below the noise, it cannot matter).
    pub const DEFAULT_ORDER: f64 = 2.0;
    /// The fastest fall below the finest measured step assumed for a bias the calibration
    /// resolved.
    pub const MAX_ORDER: f64 = 1.0;
    /// The order taken where the difference to twice the step stood clear of the noise and the
    /// one to four times did not: the middle of the orders a resolved bias is assumed to fall
    /// at below `dt0` ([`Self::MIN_ORDER`] to [`Self::MAX_ORDER`]), so the bias at `dt0`
    /// (1.47 times the difference) is within 1.64x of either end. Order 1 (the difference
    /// itself) put it at 0.64 of the truth on the sharp-gradient scene and 0.63 on the PySPH
    /// step, whose bias falls at 0.6-0.9 there (docs/notes/2026-12-07-target-error.md).
    pub const UNKNOWN_ORDER: f64 = 0.75;
    /// The slowest fall the calibration assumes: that of a bias at step-like features (an
    /// error of fixed size over a band of pixels as wide as the step: RMSE ∝ dt^0.5).
    pub const MIN_ORDER: f64 = 0.5;
    /// The share of its own noise above which an unresolved difference is a bias half seen
    /// ([`Self::settled`]).
    pub const HALF_SEEN: f64 = 0.5;
    /// The share of the target below which an image's whole error bound is negligible
    /// ([`Self::settled`]): the dam break demo's first step (512x512, emission–absorption) met
    /// E = 0.02 at 2 spp with an estimate of 4.5e-5, and refining that estimate cost 8.7 times
    /// the render.
    pub const NEGLIGIBLE: f64 = 0.1;

    /// The estimated bias at step `dt`.
    pub fn at(&self, dt: f64) -> f64 {
        self.interpolate(dt, self.levels)
    }

    /// The most the bias at `dt` may be: the estimate and what the noise could hide.
    pub fn bound(&self, dt: f64) -> f64 {
        let sum = std::array::from_fn(|i| self.levels[i] + self.hidden[i]);
        self.interpolate(dt, sum)
    }

    fn interpolate(&self, dt: f64, at: [f64; 3]) -> f64 {
        let x = (dt / self.dt0).log2();
        if x <= 0.0 {
            return at[0] * (dt / self.dt0).powf(self.order);
        }
        if x >= 2.0 {
            return at[2] * (dt / (4.0 * self.dt0)).powf(self.order);
        }
        // Linear between the measured steps (in log2 of the step).
        let i = (x.floor() as usize).min(1);
        let f = x - i as f64;
        at[i] * (1.0 - f) + at[i + 1] * f
    }

    /// The calibration difference that fixes the bias at `dt`: from `dt0` to `4 dt0` for
    /// steps coarser than `2 dt0`, from `dt0` to `2 dt0` otherwise (below `dt0` by the order).
    pub fn difference_at(&self, dt: f64) -> Difference {
        if dt > 2.0 * self.dt0 {
            self.differences[1]
        } else {
            self.differences[0]
        }
    }

    /// Whether the estimated bias at `dt` can stand in the error estimate of an image at `dt`
    /// whose noise is `noise`, rendered to the target error `target`. It can where
    /// - the difference it rests on stood clear of the calibration's noise (its size is known;
    ///   the order below `dt0` is taken from the second difference, or as
    ///   [`Self::UNKNOWN_ORDER`]);
    /// - nothing is half seen: the difference, its noise subtracted, is at most
    ///   [`Self::HALF_SEEN`] of that noise;
    /// - the bias it allows at the slowest order (2.41 times the difference at `dt0`) is at
    ///   most sqrt 3 times the image's noise, where an estimate of the noise alone is still
    ///   within 2x of the truth;
    /// - or the whole error, the bias at its most (slowest order, noise and all) and the
    ///   image's noise, is under [`Self::NEGLIGIBLE`] of the target: such an image's estimate
    ///   is not refined further.
    ///
    /// An unresolved difference hides a bias as large as its noise: at two calibration frames
    /// on an opaque PySPH step the bias at `dt0` (1.6e-3) rested on a difference of 8.7e-4
    /// within its noise (8.5e-4), taken at order 2 (2.9e-4): the estimate was 0.38 of the
    /// truth (docs/notes/2026-12-07-target-error.md).
    pub fn settled(&self, dt: f64, noise: f64, target: f64) -> bool {
        let d = self.difference_at(dt);
        let slowest = StepBias {
            order: Self::MIN_ORDER,
            ..*self
        };
        let slow = slowest.interpolate(dt, self.slow);
        let most = slowest.interpolate(dt, self.slow_bound);
        d.resolved
            || d.size <= Self::HALF_SEEN * d.noise
            || slow <= 3f64.sqrt() * noise
            || most.hypot(noise) <= Self::NEGLIGIBLE * target
    }

    /// The bias from images at `dt0`, `2 dt0` and `4 dt0` and their noise (RMSE).
    pub fn calibrate(dt0: f64, images: [&Image; 3], noise: [f64; 3]) -> StepBias {
        // The difference of level i's expectation from dt0's, its noise subtracted in
        // quadrature; the noise of that difference (what it could hide, at one standard
        // deviation); whether it stands clear of it (two).
        let diff = |i: usize| {
            let d = images[i].rmse(images[0]);
            let n = noise[i].hypot(noise[0]);
            ((d * d - n * n).max(0.0).sqrt(), n, d > 2.0 * n)
        };
        let (d1, h1, r1) = diff(1);
        let (d2, h2, r2) = diff(2);
        // M(2dt) - M(dt) = (2^p - 1) b(dt0), M(4dt) - M(dt) = (4^p - 1) b(dt0): the ratio is
        // 2^p + 1.
        // A resolved bias is extrapolated below dt0 at most linearly (see the type's text).
        let order = match (r1, r2) {
            (true, true) => (d2 / d1 - 1.0)
                .max(Self::MIN_ORDER.exp2())
                .log2()
                .clamp(Self::MIN_ORDER, Self::MAX_ORDER),
            (true, false) => Self::UNKNOWN_ORDER,
            _ => Self::DEFAULT_ORDER,
        };
        let b0 = d1 / (order.exp2() - 1.0);
        let h0 = h1 / (order.exp2() - 1.0);
        let slow = 1.0 / (Self::MIN_ORDER.exp2() - 1.0);
        StepBias {
            dt0,
            levels: [b0, b0 + d1, b0 + d2],
            hidden: [h0, h0 + h1, h0 + h2],
            order,
            resolved: r1,
            differences: [
                Difference {
                    size: d1,
                    noise: h1,
                    resolved: r1,
                },
                Difference {
                    size: d2,
                    noise: h2,
                    resolved: r2,
                },
            ],
            slow: [slow * d1, (slow + 1.0) * d1, slow * d1 + d2],
            slow_bound: [
                slow * (d1 + h1),
                (slow + 1.0) * (d1 + h1),
                slow * (d1 + h1) + d2 + h2,
            ],
        }
    }

    /// The bias from images at `2 dt0` and `4 dt0` alone (a loose target's calibration, which
    /// skips the default step): their difference `D`, its noise subtracted in quadrature, is
    /// `(2^p - 1) b(2 dt0)` for a bias of order `p`, and with one difference the order is
    /// unknown, so the slowest the calibration assumes is taken ([`Self::MIN_ORDER`]:
    /// `b(2 dt0) = 2.41 D`). Order 1 (`b = D`), assumed before, put the bias at 0.45 of the
    /// truth on an opaque PySPH step, whose bias fell at order 0.6-0.8; for a smooth field's
    /// faster fall this overstates it, which only sends more targets to the full calibration.
    pub fn calibrate_coarse(dt0: f64, images: [&Image; 2], noise: [f64; 2]) -> StepBias {
        let d = images[1].rmse(images[0]);
        let n = noise[1].hypot(noise[0]);
        let p = Self::MIN_ORDER;
        let tail = 1.0 / (p.exp2() - 1.0);
        let b1 = (d * d - n * n).max(0.0).sqrt() * tail;
        let h1 = n * tail;
        let down = (-p).exp2();
        let difference = Difference {
            size: b1 / tail,
            noise: n,
            resolved: d > 2.0 * n,
        };
        StepBias {
            dt0,
            levels: [b1 * down, b1, b1 + b1 / tail],
            hidden: [h1 * down, h1, h1 + n],
            order: p,
            resolved: difference.resolved,
            differences: [difference; 2],
            slow: [b1 * down, b1, b1 + b1 / tail],
            slow_bound: [(b1 + h1) * down, b1 + h1, b1 + h1 + b1 / tail + n],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(value: f32) -> Image {
        Image::flat(4, 3, value)
    }

    #[test]
    fn a_slow_bias_is_found_from_three_steps() {
        // bias(dt) = 0.01 (dt / dt0)^0.5 over a flat reference of 0.5: the RMSE of an error at
        // step-like features.
        let images = [1.0, 2f64.sqrt(), 2.0].map(|f| flat(0.5 + (0.01 * f) as f32));
        let bias = StepBias::calibrate(2.0, [&images[0], &images[1], &images[2]], [0.0; 3]);
        assert!(bias.resolved);
        assert!((bias.order - 0.5).abs() < 1e-3, "{bias:?}");
        for (dt, want) in [(2.0, 0.01), (4.0, 0.01414), (8.0, 0.02), (1.0, 0.00707)] {
            assert!(
                (bias.at(dt) / want - 1.0).abs() < 1e-3,
                "{dt}: {}",
                bias.at(dt)
            );
        }
        assert_eq!(bias.bound(4.0), bias.at(4.0), "no noise, nothing hidden");
    }

    #[test]
    fn a_resolved_bias_falls_at_most_linearly_below_the_finest_step() {
        // bias(dt) = 0.01 (dt / dt0)^2: the differences say order 2, but two differences
        // cannot tell whether the finest pair is still in that regime (on the sharp-gradient
        // scene they said 2.8 where the bias fell at 0.3-0.9 below dt0): order 1 below dt0,
        // an overestimate of a smooth field's bias (0.03 at dt0 where it is 0.01).
        let images = [0.01, 0.04, 0.16].map(|b| flat(0.5 + b));
        let bias = StepBias::calibrate(2.0, [&images[0], &images[1], &images[2]], [0.0; 3]);
        assert!(bias.resolved);
        assert_eq!(bias.order, StepBias::MAX_ORDER);
        for (dt, want) in [(2.0, 0.03), (4.0, 0.06), (8.0, 0.18), (1.0, 0.015)] {
            assert!((bias.at(dt) - want).abs() < 1e-6, "{dt}: {}", bias.at(dt));
        }
        for dt in [1.0, 2.0, 4.0, 8.0] {
            assert!(bias.at(dt) >= 0.01 * (dt / 2.0) * (dt / 2.0) - 1e-9);
        }
    }

    #[test]
    fn a_bias_within_the_noise_is_bounded_not_assumed() {
        // The coarser images differ from the finest by less than their noise.
        let images = [flat(0.5), flat(0.5005), flat(0.501)];
        let bias = StepBias::calibrate(1.0, [&images[0], &images[1], &images[2]], [0.01; 3]);
        assert!(!bias.resolved);
        assert_eq!(bias.order, StepBias::DEFAULT_ORDER);
        assert_eq!(bias.at(4.0), 0.0, "the noise explains the whole difference");
        assert!(
            bias.bound(4.0) >= 0.01,
            "but could hide {}",
            bias.bound(4.0)
        );
    }

    #[test]
    fn the_coarser_steps_alone_bound_the_bias_at_the_slowest_order() {
        // bias(dt) = 0.01 (dt / dt0)^0.5: 0.01414 at 2 dt0, 0.02 at 4 dt0; their difference,
        // 0.00586, is 0.414 of the bias at 2 dt0 (with order 1 it was taken as all of it).
        let images = [flat(0.51414), flat(0.52)];
        let bias = StepBias::calibrate_coarse(1.0, [&images[0], &images[1]], [0.0; 2]);
        assert!(bias.resolved);
        assert!((bias.at(2.0) / 0.01414 - 1.0).abs() < 2e-3, "{bias:?}");
        assert!((bias.at(4.0) / 0.02 - 1.0).abs() < 2e-3, "{bias:?}");
        assert!((bias.at(1.0) / 0.01 - 1.0).abs() < 2e-3, "{}", bias.at(1.0));
        // A bias growing faster (order 2: 0.04 at 2 dt0, 0.16 at 4 dt0) is overstated.
        let bias = StepBias::calibrate_coarse(1.0, [&flat(0.54), &flat(0.66)], [0.0; 2]);
        assert!(bias.at(2.0) >= 0.04 && bias.at(4.0) >= 0.16, "{bias:?}");
        // Within the noise: no bias estimated, the noise's share bounded.
        let bias = StepBias::calibrate_coarse(1.0, [&flat(0.5), &flat(0.501)], [0.01; 2]);
        assert!(!bias.resolved);
        assert_eq!(bias.at(2.0), 0.0);
        assert!(bias.bound(2.0) >= 0.01, "{}", bias.bound(2.0));
    }

    #[test]
    fn a_bias_half_seen_in_the_noise_is_not_settled() {
        // The difference to twice the step is 0.001 against a calibration noise of 0.0008 a
        // level (0.00113 for the difference): within its noise, but most of it.
        let images = [flat(0.5), flat(0.5015), flat(0.503)];
        let bias = StepBias::calibrate(1.0, [&images[0], &images[1], &images[2]], [8e-4; 3]);
        assert!(!bias.resolved, "{bias:?}");
        let d = bias.difference_at(1.0);
        assert!(d.size > StepBias::HALF_SEEN * d.noise, "{d:?}");
        // Beside an image noise of 5e-4 the bias it may hide (2.41 times the difference at
        // the slowest order) matters: not settled. Beside 2e-3 it does not.
        assert!(!bias.settled(1.0, 5e-4, 0.01));
        assert!(bias.settled(1.0, 2e-3, 0.01));
        // With quieter images the same difference stands clear: settled, at an order between
        // the slowest and the linear one, as four times the step is not resolved.
        let noisy_coarse = [1e-4, 1e-4, 0.05];
        let bias = StepBias::calibrate(1.0, [&images[0], &images[1], &images[2]], noisy_coarse);
        assert!(bias.resolved && !bias.differences[1].resolved, "{bias:?}");
        assert_eq!(bias.order, StepBias::UNKNOWN_ORDER);
        assert!(bias.settled(1.0, 5e-4, 1.0));
        assert!((bias.at(1.0) / (bias.differences[0].size * 1.47) - 1.0).abs() < 0.01);
        // A difference well within its noise is settled: nothing is half seen.
        let quiet = [flat(0.5), flat(0.5001), flat(0.5002)];
        let bias = StepBias::calibrate(1.0, [&quiet[0], &quiet[1], &quiet[2]], [8e-4; 3]);
        assert!(bias.settled(1.0, 5e-4, 1.0), "{bias:?}");
        // Beside a target that dwarfs its bound, any bias is settled.
        let bias = StepBias::calibrate(1.0, [&images[0], &images[1], &images[2]], [8e-4; 3]);
        assert!(!bias.settled(1.0, 5e-4, 0.03));
        assert!(bias.settled(1.0, 5e-4, 0.1));
    }
}
