//! How a blue-noise accumulation's frames combine into its image past the first mask cycle.
//!
//! A blue-noise sequence is stratified at the end of each cycle of the mask (every pixel has
//! then drawn one number from each `1/depth` of [0, 1)), and only there; each cycle reads the
//! mask at its own shift, so the cycles' means are independent. The frames of an incomplete
//! cycle are far noisier than their number suggests: on the dam break (marching) the first 8
//! frames of a cycle have about 120 times the variance of a whole cycle's mean, not the 8 an
//! independent sample would have, so the plain mean of 72 frames was noisier than that of 64
//! (docs/accuracy.md). The image of `c` whole cycles and `m` frames of the next is therefore
//! their inverse-variance combination, `M_c + w (P_m - M_c)` with `w = v_c / E|P_m - M_c|^2`
//! (`v_c` the variance of the whole cycles' mean): it is never noisier than the whole cycles
//! alone, and it is the plain mean (`w = m / (c d + m)`) where the frames are independent.
//!
//! `E|P_m - M_c|^2 = v(m) + v_c` is measured on the image itself. The variance `v_d` of one
//! cycle's mean is measured on the accumulation: from its third cycle on, as half the mean
//! square difference of its first two cycles' means (independent); during its second, a
//! quarter and half into it, from the first cycle's prefix of `q` frames `P1_q` (kept when it
//! was reached) and the second's `P2_q`, independent with equal variance, so that
//! `v_d = E|P2_q - M_1|^2 - E|P2_q - P1_q|^2 / 2`. That is a small difference of large numbers
//! where the cycles are strongly stratified, so its lower bound (two standard errors below)
//! is what is used: an underestimate only holds the image nearer the whole cycle's mean.
//! Until a quarter into the second cycle the image is the whole cycle's mean. The weight is
//! kept within `[0, m / (c d + m)]`: stratification makes a whole cycle better than its prefix,
//! never worse, so the partial cycle never deserves more than its share of the frames.
//!
//! Where the frames are not stratified (white noise, or delta tracking, which draws most of
//! its numbers from white noise: its first 8 frames have about 8 times a cycle's variance),
//! the image is the plain mean.

use super::settings::RenderSettings;
use crate::noise::BlueNoiseMask;
use crate::values::{Image, Integrator, NoiseKind};

/// The frames of one mask cycle where `settings` draw blue noise (every backend draws from the
/// built-in mask), `None` for white noise.
pub(crate) fn mask_cycle(settings: &RenderSettings) -> Option<u32> {
    mask_cycle_of(settings.noise)
}

fn mask_cycle_of(noise: NoiseKind) -> Option<u32> {
    match noise {
        NoiseKind::Stbn => Some(BlueNoiseMask::builtin().depth),
        NoiseKind::White => None,
    }
}

/// The frames of one mask cycle where `settings`' frames are stratified over it (blue noise,
/// and an integrator that draws its numbers from it: not delta tracking, which draws most of
/// its numbers from white noise); `None` where its frames are as good as independent.
pub(crate) fn stratified_cycle(settings: &RenderSettings) -> Option<u32> {
    stratified_cycle_of(settings.noise, settings.integrator)
}

fn stratified_cycle_of(noise: NoiseKind, integrator: Integrator) -> Option<u32> {
    let cycle = mask_cycle_of(noise)?;
    (integrator != Integrator::Delta && cycle >= 4 && cycle.is_multiple_of(4)).then_some(cycle)
}

/// The combination of one accumulation's whole mask cycles and its incomplete one (see the
/// module's text). It holds the means read back at the frames [`wants_mean_at`] names.
///
/// [`wants_mean_at`]: CycleWeights::wants_mean_at
pub(crate) struct CycleWeights {
    /// Frames of a mask cycle (a multiple of 4).
    cycle: u32,
    /// The mean of the whole cycles at the last cycle's end, and its frames.
    whole: Option<(Image, u32)>,
    /// The first cycle's mean at a quarter and at half of it, until the second cycle's
    /// prefixes of as many frames bound the cycle's variance with them.
    first_prefixes: Vec<(u32, Image)>,
    /// The variance (mean square over pixels and RGB) of one whole cycle's mean.
    cycle_variance: Option<f64>,
}

impl CycleWeights {
    /// The weights of an accumulation of `settings`: `None` where its frames are not
    /// stratified over a mask cycle and the plain mean is the image.
    pub(crate) fn of(settings: &RenderSettings) -> Option<CycleWeights> {
        CycleWeights::of_frames(settings.noise, settings.integrator)
    }

    /// The weights of an accumulation of frames drawn from `noise` by `integrator`.
    pub(crate) fn of_frames(noise: NoiseKind, integrator: Integrator) -> Option<CycleWeights> {
        let cycle = stratified_cycle_of(noise, integrator)?;
        Some(CycleWeights {
            cycle,
            whole: None,
            first_prefixes: Vec::new(),
            cycle_variance: None,
        })
    }

    /// Whether the accumulation's mean at `frames` frames is needed (read it back and give it
    /// to [`took_mean`](Self::took_mean) before rendering the next frame).
    pub(crate) fn wants_mean_at(&self, frames: u32) -> bool {
        // Of the counts that may be wanted, the second cycle's prefixes only while the first
        // cycle's prefix of as many frames waits for its twin.
        let in_cycle = frames % self.cycle;
        self.may_want_mean_at(frames)
            && (in_cycle == 0 || frames < self.cycle || self.cycle_variance_pending(in_cycle))
    }

    /// Whether the mean at `frames` frames may be wanted, whatever was measured before: every
    /// frame count [`wants_mean_at`](Self::wants_mean_at) can name, for a renderer that keeps
    /// the means before it can ask (the distributed one keeps them in its tiles' owners).
    pub(crate) fn may_want_mean_at(&self, frames: u32) -> bool {
        let d = self.cycle;
        let in_cycle = frames % d;
        frames > 0
            && (in_cycle == 0 || ((in_cycle == d / 4 || in_cycle == d / 2) && frames < 2 * d))
    }

    fn cycle_variance_pending(&self, prefix: u32) -> bool {
        self.first_prefixes.iter().any(|(q, _)| *q == prefix)
    }

    /// The accumulation's mean at `frames` frames, as [`wants_mean_at`](Self::wants_mean_at)
    /// asked.
    pub(crate) fn took_mean(&mut self, frames: u32, mean: Image) {
        let d = self.cycle;
        let in_cycle = frames % d;
        if in_cycle != 0 && frames < d {
            self.first_prefixes.push((in_cycle, mean));
            return;
        }
        if in_cycle != 0
            && let (Some((m1, d1)), Some(at)) = (
                &self.whole,
                self.first_prefixes.iter().position(|(q, _)| *q == in_cycle),
            )
            && *d1 == d
        {
            let (q, p1) = self.first_prefixes.remove(at);
            // P2_q = M_1 + (n / q)(mean_n - M_1): the second cycle's own mean of q frames.
            let p2 = m1.offset_by(&mean, m1, f64::from(frames) / f64::from(q));
            let bound = cycle_variance_bound(m1, &p1, &p2);
            self.cycle_variance = Some(self.cycle_variance.map_or(bound, |v| v.max(bound)));
            tracing::debug!(
                "blue-noise cycles: one cycle's variance at least {bound:.3e}, measured {q} frames into the second"
            );
        } else if let Some((m1, d1)) = &self.whole
            && *d1 == d
            && frames == 2 * d
        {
            // Two whole cycles, independent: half their mean square difference is one's
            // variance, measured directly (the prefixes' bound is a small difference of large
            // numbers where the cycles are strongly stratified).
            let c2 = m1.offset_by(&mean, m1, 2.0);
            let variance = 0.5 * c2.rmse(m1).powi(2);
            self.cycle_variance = Some(variance);
            tracing::debug!("blue-noise cycles: one cycle's variance {variance:.3e}, from two");
        }
        if in_cycle == 0 {
            self.whole = Some((mean, frames));
        }
    }

    /// The image of the accumulation whose mean at `frames` frames is `mean`.
    pub(crate) fn image(&self, frames: u32, mean: Image) -> Image {
        let d = self.cycle;
        let Some((whole, whole_frames)) = &self.whole else {
            return mean;
        };
        // Only an accumulation whose last whole cycle was read at its end (a mean of other
        // frames is not this one's).
        if frames.is_multiple_of(d) || *whole_frames != frames - frames % d {
            return mean;
        }
        let partial = frames - whole_frames;
        let cycles = f64::from(whole_frames / d);
        // P_m - M_c = (n / m)(mean_n - M_c).
        let stretch = f64::from(frames) / f64::from(partial);
        let spread = (stretch * mean.rmse(whole)).powi(2);
        let plain = f64::from(partial) / f64::from(frames);
        let w = match self.cycle_variance {
            None => 0.0,
            Some(_) if spread <= 0.0 => plain,
            Some(v) => (v / cycles / spread).clamp(0.0, plain),
        };
        whole.offset_by(&mean, whole, w * stretch)
    }
}

/// A lower bound (two standard errors below the estimate, at least 0) on the variance of one
/// whole cycle's mean, from the first cycle's mean `m1`, its prefix `p1` of q frames and the
/// second cycle's prefix `p2` of as many: per pixel, `|p2 - m1|^2 - |p2 - p1|^2 / 2` has
/// expectation `v_d`. Where the cycles are strongly stratified it is a small difference of large
/// numbers, dominated by a few pixels' noise; the bound then says "about none", and the image
/// keeps the whole cycles.
fn cycle_variance_bound(m1: &Image, p1: &Image, p2: &Image) -> f64 {
    let terms: Vec<f64> = m1
        .pixels
        .iter()
        .zip(p1.pixels.iter().zip(&p2.pixels))
        .map(|(m, (a, b))| {
            (0..3)
                .map(|c| {
                    let (m, a, b) = (f64::from(m[c]), f64::from(a[c]), f64::from(b[c]));
                    (b - m).powi(2) - 0.5 * (b - a).powi(2)
                })
                .sum::<f64>()
                / 3.0
        })
        .collect();
    let n = terms.len().max(2) as f64;
    let mean = terms.iter().sum::<f64>() / n;
    let spread = terms.iter().map(|t| (t - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean - 2.0 * (spread / n).sqrt()).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn constant(value: f32) -> Image {
        Image::flat(2, 1, value)
    }

    #[test]
    fn the_means_are_asked_for_at_the_cycle_ends_and_the_first_two_cycles_prefixes() {
        let settings = RenderSettings::default();
        let mut w = CycleWeights::of(&settings).expect("blue noise, emission-absorption");
        let d = w.cycle;
        let asked: Vec<u32> = (0..=3 * d)
            .filter(|&n| {
                let wanted = w.wants_mean_at(n);
                if wanted {
                    w.took_mean(n, constant(1.0));
                }
                wanted
            })
            .collect();
        assert_eq!(
            asked,
            [d / 4, d / 2, d, d + d / 4, d + d / 2, 2 * d, 3 * d],
            "cycle {d}"
        );
        // Identical frames: no variance, and the image is the plain mean.
        assert_eq!(w.cycle_variance, Some(0.0));
    }

    #[test]
    fn the_cycle_variance_bound_is_below_the_variance_and_near_it() {
        use rand::{Rng, SeedableRng};
        // Per pixel and channel: the first cycle's mean M1 = s + m (variance v_d), its prefix
        // P1 = M1 + e (correlated with M1, as a prefix is), the second cycle's prefix P2 =
        // s + m' + e', independent of both, with P1's variance.
        let bound_with = |prefix_noise: f64| {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
            let mut u = |a: f64| rng.random_range(-a..a);
            let mut images = [(); 3].map(|_| Image::flat(200, 200, 0.0));
            for i in 0..images[0].pixels.len() {
                for c in 0..3 {
                    let m = 0.5 + u(0.01);
                    images[0].pixels[i][c] = m as f32;
                    images[1].pixels[i][c] = (m + u(prefix_noise)) as f32;
                    images[2].pixels[i][c] = (0.5 + u(0.01) + u(prefix_noise)) as f32;
                }
            }
            let [m1, p1, p2] = &images;
            cycle_variance_bound(m1, p1, p2)
        };
        let v_d = 0.01f64 * 0.01 / 3.0;
        // A prefix with 10 times the cycle's variance: the bound is close below it.
        let bound = bound_with(0.03);
        assert!(
            bound <= v_d && bound > 0.6 * v_d,
            "bound {bound:.3e}, variance {v_d:.3e}"
        );
        // With 10,000 times: the bound says "about none" rather than a variance it cannot
        // resolve (the image then keeps the whole cycles).
        let bound = bound_with(1.0);
        assert!(bound < 0.5 * v_d, "bound {bound:.3e}, variance {v_d:.3e}");
    }

    #[test]
    fn white_noise_and_delta_tracking_keep_the_plain_mean() {
        let white = RenderSettings {
            noise: NoiseKind::White,
            ..RenderSettings::default()
        };
        let delta = RenderSettings {
            integrator: Integrator::Delta,
            ..RenderSettings::default()
        };
        assert!(CycleWeights::of(&white).is_none());
        assert!(CycleWeights::of(&delta).is_none());
        let marching = RenderSettings {
            integrator: Integrator::Marching,
            ..RenderSettings::default()
        };
        assert!(CycleWeights::of(&marching).is_some());
    }

    #[test]
    fn the_incomplete_cycle_is_weighted_by_the_measured_variances() {
        let settings = RenderSettings::default();
        let mut w = CycleWeights::of(&settings).unwrap();
        let d = w.cycle;
        // Before any measurement the image past the first cycle is the whole cycle's mean.
        w.took_mean(d, constant(1.0));
        assert_eq!(w.image(d + 4, constant(2.0)).pixels[0][0], 1.0);
        // Within the first cycle and at cycle ends it is the plain mean.
        assert_eq!(w.image(d / 2, constant(3.0)).pixels[0][0], 3.0);
        assert_eq!(w.image(2 * d, constant(3.0)).pixels[0][0], 3.0);
        // One cycle's variance v = 0.01, and the partial cycle of m frames differs from the
        // whole by 0.5: w = v / 0.25 = 0.04 (under the plain share m / n).
        w.cycle_variance = Some(0.01);
        let (n, m) = (d + d / 2, d / 2);
        let stretch = f64::from(n) / f64::from(m);
        let mean = constant((1.0 + 0.5 / stretch) as f32);
        let image = w.image(n, mean);
        let expected = 1.0 + 0.04 * 0.5;
        assert!(
            (f64::from(image.pixels[0][0]) - expected).abs() < 1e-6,
            "{:?}",
            image.pixels[0]
        );
        // A variance so large the plain share is less: the plain mean.
        w.cycle_variance = Some(100.0);
        let mean = constant((1.0 + 0.5 / stretch) as f32);
        let image = w.image(n, mean.clone());
        assert!((image.pixels[0][0] - mean.pixels[0][0]).abs() < 1e-6);
    }
}
