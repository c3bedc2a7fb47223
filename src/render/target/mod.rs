//! How wrong an image is, estimated without the answer, and rendering to an error or within a
//! time (`aarbf render --target-error E`, `--time-budget S`, the scene file's `target_error`
//! and `time_budget`).
//!
//! A targeted render's error against the converged reference has two parts whose squares add
//! (the noise has zero mean, so it is uncorrelated with the bias):
//!
//! - **Noise**, measured on the render itself by a second, independent sequence of frames (the
//!   same settings under another seed), in one of two ways (`Companion`):
//!   - where the frames are stratified over the blue-noise mask's cycle (blue noise, any
//!     integrator but delta tracking) and the metric is RMSE, the image is one sequence, A,
//!     and the second, B, is rendered on its half-resolution lattice (the rays of A's even
//!     pixels, a quarter of the work): the noise is `rmse(A on the lattice, B) / sqrt 2`, exact
//!     in expectation because A and B are independent. Two independent sequences of N frames
//!     each lose the stratification one sequence of 2N has within a cycle (a target the
//!     defaults reach at 32 spp took two sequences of 24 frames), and splitting one sequence
//!     into halves overstates its noise (its frames are anti-correlated within a cycle: up to
//!     2.3x in the tests). Once A is two or more whole cycles, the spread of the cycles' means
//!     (independent: each reads the mask at its own shift) measures its noise and the lattice
//!     stops; a sequence predicted to need more than one cycle is measured by a pair instead,
//!     where the lattice would only add its first cycle's cost;
//!   - otherwise (white noise, delta tracking, FLIP targets, which need a full-resolution
//!     realisation of the noise) the image is the mean of A and B, both whole images, and its
//!     noise `rmse(A, B) / 2` (the dual-buffer estimate).
//! - **Step bias**, which no number of samples removes: from images at `dt0`, `2 dt0` and
//!   `4 dt0`, see [`StepBias`].
//!
//! From those, [`render_to_target`] picks the step (`dt0 · 2^j`, `j` in -3..=2, unless the
//! user fixed it) whose predicted time to the target is least, with the noise's measured rate
//! of fall ([`Convergence`]), renders to the predicted frames, checks the estimate and goes on
//! if it falls short. A time budget picks the step with the least predicted error for the time
//! left and renders until it is spent. Blue-noise sequences stop at the ends of mask cycles
//! once they need most of one (`stop_at`): a sequence is stratified there and only there.
//! The calibration is part of what a target costs; its images are kept, so the chosen step's
//! are never rendered twice, and a loose RMSE target that twice the step meets within
//! `LOOSE` times its calibration samples is decided from `2 dt0` and `4 dt0` alone
//! ([`StepBias::calibrate_coarse`]): the images at `dt0` would cost a large share of its frames.

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::RenderError;
use super::Resolved;
use super::cycles::{mask_cycle, stratified_cycle};
use super::session::RenderSession;
use super::settings::RenderSettings;
pub use super::step_bias::StepBias;
use crate::values::Image;
use crate::values::frame::half_lattice_size;

mod calibration;
mod levels;
#[cfg(test)]
mod tests;

use calibration::*;
use levels::*;

/// The measure of an image's error against the reference.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ErrorMetric {
    /// Root-mean-square difference over linear RGB.
    #[default]
    Rmse,
    /// Mean FLIP over the 8-bit sRGB images (perceptual; 0 to 1).
    Flip,
}

impl ErrorMetric {
    /// The name the command line and the scene file use.
    pub fn name(self) -> &'static str {
        match self {
            ErrorMetric::Rmse => "rmse",
            ErrorMetric::Flip => "flip",
        }
    }
}

/// The noise (RMSE over linear RGB) of the mean of `a` and `b`, two independent
/// accumulations of equally many frames (the dual-buffer estimate).
pub fn noise_of_pair(a: &Image, b: &Image) -> f64 {
    0.5 * a.rmse(b)
}

/// How the noise of an accumulated image falls with its frames: `noise(N) ∝ N^-rate`
/// (0.5 for independent samples; blue noise falls faster while its mask stratifies).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Convergence {
    /// The frames the noise was last estimated at.
    pub frames: u32,
    /// The noise (RMSE over linear RGB) at `frames`.
    pub noise: f64,
    /// The exponent the noise falls with, `noise(N) ∝ N^-rate`, in [0.5, 1].
    pub rate: f64,
}

impl Convergence {
    /// From the noise at two frame counts.
    fn of(a: (u32, f64), b: (u32, f64)) -> Convergence {
        let (lo, hi) = if a.0 < b.0 { (a, b) } else { (b, a) };
        let rate = if hi.0 > lo.0 && lo.1 > 0.0 && hi.1 > 0.0 && lo.1.is_finite() {
            ((lo.1 / hi.1).ln() / (f64::from(hi.0) / f64::from(lo.0)).ln()).clamp(0.5, 1.0)
        } else {
            0.5
        };
        Convergence {
            frames: hi.0,
            noise: hi.1,
            rate,
        }
    }

    /// The noise after `frames` frames.
    pub fn noise_at(&self, frames: f64) -> f64 {
        self.noise * (f64::from(self.frames) / frames).powf(self.rate)
    }

    /// The frames at which the noise falls to `noise`.
    pub fn frames_for(&self, noise: f64) -> f64 {
        f64::from(self.frames) * (self.noise / noise).powf(1.0 / self.rate)
    }
}

/// What a targeted render aims for: an error, a time, or both (whichever is reached first).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Target {
    /// The error to reach, in `metric`; `None`: only the time budget.
    pub error: Option<f64>,
    /// The time to render for; `None`: until the error is reached.
    pub time_budget: Option<Duration>,
    /// How `error` is measured.
    pub metric: ErrorMetric,
    /// The most samples per pixel it may take.
    pub max_spp: u32,
}

impl Target {
    /// The default for `max_spp`.
    pub const DEFAULT_MAX_SPP: u32 = 1 << 16;

    /// Rejects a target with neither an error nor a time budget, a non-positive error or budget, or
    /// fewer than 8 samples per pixel.
    pub fn check(&self) -> Result<(), RenderError> {
        if self.error.is_none() && self.time_budget.is_none() {
            return Err(RenderError::Settings(
                "a targeted render needs a target error or a time budget".into(),
            ));
        }
        if let Some(e) = self.error
            && !(e.is_finite() && e > 0.0)
        {
            return Err(RenderError::Settings(format!(
                "target error {e} must be a positive number"
            )));
        }
        if let Some(t) = self.time_budget
            && t.is_zero()
        {
            return Err(RenderError::Settings(
                "the time budget must be more than 0 s".into(),
            ));
        }
        if self.max_spp < 8 {
            return Err(RenderError::Settings(format!(
                "a targeted render needs at least 8 samples per pixel, not {}",
                self.max_spp
            )));
        }
        Ok(())
    }
}

/// A targeted render's image and what it estimates about it.
#[derive(Clone, Debug)]
pub struct Targeted {
    /// The accumulated image.
    pub image: Image,
    /// The march step chosen, data units.
    pub step_size: f64,
    /// Samples per pixel accumulated.
    pub spp: u32,
    /// The estimated error in the target's metric.
    pub estimate: f64,
    /// The estimated noise (RMSE over linear RGB).
    pub noise_rmse: f64,
    /// The step's bias as calibrated.
    pub bias: StepBias,
    /// How the noise fell with the frames (the last two estimates).
    pub convergence: Convergence,
    /// Whether the estimate meets the target error (always true with only a time budget).
    pub met: bool,
    /// Wall time of the whole render, calibration included.
    pub elapsed: Duration,
    /// Wall time of the calibration alone.
    pub calibration: Duration,
    /// Every frame rendered, the calibration's included, in frames at the starting step (a
    /// frame at twice the step counts a half): the work, free of the machine's speed.
    pub work: f64,
}

/// Frames each sequence of a calibration image starts with.
const CALIBRATION_FRAMES: u32 = 2;
/// The most frames a calibration sequence takes while the noise hides whether a coarser step
/// would do.
const MAX_CALIBRATION_FRAMES: u32 = 64;
/// A target that twice the default step meets within this many times the calibration's
/// samples there is loose: the default step's calibration images would cost a large share of
/// the whole render, and the coarser steps' difference decides alone. (At 4, the dam break's
/// 16-spp target, 24 spp at twice the step, paid 4 frames at the default step for images that
/// chose the same step: docs/accuracy.md, "The mid target through the loose path".)
const LOOSE: f64 = 8.0;
/// The least rate of fall of the noise over a sequence's first mask cycle at which its
/// renders stop only at whole cycles (independent samples fall at 0.5; the dam break's
/// marching at about 1.0 from 8 to 64 frames, and 2.9 over the cycle's last quarter).
const STRATIFIED_RATE: f64 = 0.75;
/// The fewest effective pixels ([`lattice_noise_pixels`]) on which the lattice's noise estimate
/// stands for the whole image; below it a pair measures the noise. On the sharp-gradient scene
/// (64x64, a few sub-pixel features hold the noise) the estimate rested on 10-13 of the
/// lattice's 1024 pixels and was 0.63-0.66 of the true noise (a pair: 0.95); on the PySPH
/// step, 120-128, 0.96-0.98. (At 48 the dam break's 32x32 targets in `tests/target_error.rs`,
/// whose lattice estimate was 0.84-1.09 of the truth, moved to a pair too.)
const MIN_LATTICE_PIXELS: f64 = 16.0;
/// The most the noise at four times the step may be, in times that at twice the step at as
/// many frames, for their difference to decide a loose target alone (the jittered march's
/// noise grows about linearly with the step while the step resolves the kernels).
const COARSE_NOISE: f64 = 4.0;
/// The share of the squared target error the bias may take (the rest is left to the noise).
const BIAS_SHARE: f64 = 0.75;
/// The second sequence's seed is the first's with these bits flipped.
const SECOND_SEED: u32 = 0x9E37_79B9;

/// The noise (RMSE over RGB) of `image`, one sequence of frames, from `lattice`, an independent
/// sequence of as many frames on its half-resolution lattice: their difference there has
/// twice the variance of either.
pub fn noise_on_lattice(image: &Image, lattice: &Image) -> f64 {
    image.half_lattice().rmse(lattice) * std::f64::consts::FRAC_1_SQRT_2
}

/// How many of the lattice's pixels the noise estimate of [`noise_on_lattice`] rests on: the
/// effective count `(sum d^2)^2 / sum d^4` of the squared differences `d^2` per pixel (all of
/// them where the noise is spread evenly, a handful where a few pixels hold it).
pub fn lattice_noise_pixels(image: &Image, lattice: &Image) -> f64 {
    let (sum, sum_sq) = image
        .half_lattice()
        .pixels
        .iter()
        .zip(&lattice.pixels)
        .map(|(a, b)| {
            (0..3)
                .map(|c| (f64::from(a[c]) - f64::from(b[c])).powi(2))
                .sum::<f64>()
        })
        .fold((0.0, 0.0), |(s, q), d| (s + d, q + d * d));
    if sum_sq > 0.0 {
        sum * sum / sum_sq
    } else {
        f64::INFINITY
    }
}

/// Where a sequence that has `reached` frames and is predicted to need `wanted` stops next.
///
/// A blue-noise sequence is stratified at the end of each mask cycle, and only there: the
/// frames of an incomplete cycle add far more noise than their number suggests (on the dam
/// break one sequence's noise fell 1.7e-3 -> 7.4e-4 from 48 to 64 frames, and a pair at 70
/// frames a sequence was noisier than at 64). So a sequence predicted to need most of its first
/// cycle or more stops at the cycle's end first (the power law measured early on cannot see
/// that drop), and past it only at whole cycles, where the cycles' means are independent
/// (each has its own shift of the mask) and the noise falls as `N^-1/2`.
fn stop_at(wanted: u32, reached: u32, cycle: Option<u32>) -> u32 {
    match cycle {
        None => wanted,
        Some(d) if reached < d => {
            if 4 * wanted >= 3 * d {
                d
            } else {
                wanted
            }
        }
        Some(d) => wanted.div_ceil(d).max(1) * d,
    }
}

/// Renders `settings` (its step size as the starting step, or fixed when set) until the
/// estimated error meets `target.error` or `target.time_budget` is spent.
pub fn render_to_target(
    session: &mut RenderSession,
    settings: &RenderSettings,
    target: &Target,
) -> Result<Targeted, RenderError> {
    render_chunks_to_target(&mut SessionChunks::new(session), settings, target)
}

/// What a targeted render renders with: chunks of a sequence's frames, and a clock. One
/// process's session ([`render_to_target`]), or the ranks of a distributed render, each
/// running the same decisions on the same images (`crate::dist::target`).
pub trait ChunkRenderer {
    /// What `settings` leaves automatic, resolved ([`RenderSession::resolve`]).
    fn resolve(&self, settings: &RenderSettings) -> Result<Resolved, RenderError>;

    /// Frames `first..first + count` of `settings` as a fresh accumulation, read back
    /// ([`RenderSession::render_frames`]); on the image's half-resolution lattice where
    /// `half_lattice` ([`RenderSession::render_frames_on_half_lattice`]).
    fn render_frames(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
        half_lattice: bool,
    ) -> Result<Image, RenderError>;

    /// The time since the render started. The decisions that follow from it must be the
    /// same in every process that makes them: a distributed render's clock moves only when
    /// a chunk ends, to what its rank 0 measured.
    fn elapsed(&self) -> Duration;
}

/// One process's session, on the wall clock.
pub(crate) struct SessionChunks<'a> {
    session: &'a mut RenderSession,
    started: Instant,
}

impl<'a> SessionChunks<'a> {
    /// The chunks `session` renders; its clock starts now.
    pub(crate) fn new(session: &'a mut RenderSession) -> SessionChunks<'a> {
        SessionChunks {
            session,
            started: Instant::now(),
        }
    }
}

impl ChunkRenderer for SessionChunks<'_> {
    fn resolve(&self, settings: &RenderSettings) -> Result<Resolved, RenderError> {
        self.session.resolve(settings)
    }

    fn render_frames(
        &mut self,
        settings: &RenderSettings,
        first: u32,
        count: u32,
        half_lattice: bool,
    ) -> Result<Image, RenderError> {
        if half_lattice {
            self.session
                .render_frames_on_half_lattice(settings, first, count)
        } else {
            self.session.render_frames(settings, first, count)
        }
    }

    fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }
}

/// [`render_to_target`] with the chunks rendered by `session` (a distributed render's ranks:
/// every rank calls it with the same arguments, and gets the same result).
pub fn render_chunks_to_target(
    session: &mut dyn ChunkRenderer,
    settings: &RenderSettings,
    target: &Target,
) -> Result<Targeted, RenderError> {
    target.check()?;
    let dt0 = session.resolve(settings)?.step_size;
    let step_fixed = settings.step_size.is_some();
    let seed = settings.seed;
    let mut run = Run {
        session,
        settings: settings.clone(),
        target: *target,
        dt0,
        work: 0.0,
    };

    // Calibrate: both sequences at dt0, 2 dt0 and 4 dt0, read at half their frames and at
    // all of them (the noise's rate of fall from the two). Two frames a sequence to start: a
    // loose target is then met by the finest level's own 4 samples, where 8 a sequence cost
    // 3.5 times the front's 4 (the study's 4-spp target).
    // One stratified sequence and the lattice that measures its noise where its frames are
    // stratified and the metric is RMSE; a pair of sequences otherwise.
    let lattice = match target.metric {
        ErrorMetric::Rmse => stratified_cycle(settings),
        ErrorMetric::Flip => None,
    };
    let mut levels = [dt0, 2.0 * dt0, 4.0 * dt0].map(|dt| Level::new(dt, seed, lattice));

    // A loose target first: the coarser steps alone, and twice the default step chosen on
    // their difference when it meets the target within `LOOSE` times their samples (the front's
    // cheapest there is a handful of samples at a coarse step, which the default step's
    // calibration images alone would cost twice over). Otherwise they are the full
    // calibration's first images. RMSE targets only: a FLIP target's estimate takes its
    // scale from the default step's images (from the coarser ones it overstated a loose
    // target's FLIP 3x).
    if let (Some(e), false, ErrorMetric::Rmse) = (target.error, step_fixed, target.metric)
        && target.time_budget.is_none()
        && run.allowed(2.0 * dt0)
        && run.allowed(4.0 * dt0)
        && let Some(done) = render_loose(&mut run, &mut levels, e, CALIBRATION_FRAMES)?
    {
        return Ok(done);
    }
    let (bias, e_rmse) = calibrate(&mut run, &mut levels, step_fixed, CALIBRATION_FRAMES)?;
    render_at_chosen_step(run, levels, bias, e_rmse, step_fixed, lattice)
}

/// A loose target `e` from twice and four times the step alone (`frames` a sequence to
/// start): the render at twice the step where their difference settles its bias, else `None`
/// and the full calibration goes on from these images.
fn render_loose(
    run: &mut Run<'_>,
    levels: &mut [Level; 3],
    e: f64,
    frames: u32,
) -> Result<Option<Targeted>, RenderError> {
    let dt0 = run.dt0;
    // Four times the step at half the frames: only its difference from twice the step is
    // used here (the full calibration extends it if this is not enough).
    run.extend(&mut levels[1], frames / 2)?;
    run.extend(&mut levels[1], frames)?;
    run.extend(&mut levels[2], frames / 2)?;
    let (middle, coarse) = (&levels[1], &levels[2]);
    let bias = StepBias::calibrate_coarse(
        dt0,
        [&middle.image(&run.settings), &coarse.image(&run.settings)],
        [middle.noise(), coarse.noise()],
    );
    let b = bias.at(2.0 * dt0);
    // The difference tells the bias at twice the step only where four times the step
    // still resolves what twice the step does: its noise (the march's jitter over the
    // features) at most `COARSE_NOISE` times twice the step's at as many frames. On the
    // sharp-gradient scene it was 8.8 times (the sheet and the halo's particles thinner
    // than the step), and the bias at twice the step (5.3e-4) hid in it; 1.0-2.1 on the
    // dam break and the PySPH step.
    let coarse_noise = coarse.noise()
        / middle
            .convergence()
            .noise_at(f64::from(coarse.spp()))
            .max(1e-300);
    // (Unless the bias at its most is negligible beside the target anyway: the dam
    // break demo's first step, 1000 times under it, paid 2.4x for the full calibration.)
    let negligible = bias.slow_bound[1].hypot(middle.noise()) <= StepBias::NEGLIGIBLE * e;
    if b * b <= BIAS_SHARE * e * e && (coarse_noise <= COARSE_NOISE || negligible) {
        let needed = middle.convergence().frames_for((e * e - b * b).sqrt());
        if needed <= LOOSE * f64::from(middle.spp()) {
            tracing::debug!(
                "targeted: loose: twice the step, bias {b:.3e}, {needed:.1} spp predicted"
            );
            let calibration = run.session.elapsed();
            let bias_images = (
                levels[2].image(&run.settings),
                levels[1].image(&run.settings),
            );
            let done = finish(
                run,
                &mut levels[1],
                needed,
                Chosen {
                    bias,
                    b,
                    bias_images,
                    calibration,
                },
            )?;
            // Four times the step can be too coarse for its image to tell anything (on
            // the sharp-gradient scene its noise was 36 times twice the step's): where
            // the difference leaves the bias unsettled beside the image's noise, the
            // full calibration goes on from these images.
            if !done.met || bias.settled(2.0 * dt0, done.noise_rmse, e) {
                return Ok(Some(done));
            }
            tracing::debug!(
                "targeted: loose: the bias at twice the step is not settled beside the noise {:.3e} ({bias:?}): the full calibration",
                done.noise_rmse
            );
        }
    }
    Ok(None)
}

/// The full calibration: every level's images from `frames` frames a sequence, grown while
/// the noise hides whether four times the step would meet the target. Returns the bias it
/// measured and the target error in RMSE (none with a time budget alone).
fn calibrate(
    run: &mut Run<'_>,
    levels: &mut [Level; 3],
    step_fixed: bool,
    mut frames: u32,
) -> Result<(StepBias, Option<f64>), RenderError> {
    let (target, dt0) = (run.target, run.dt0);
    loop {
        for level in levels.iter_mut() {
            if level.history.is_empty() {
                run.extend(level, frames / 2)?;
            }
            run.extend(level, frames)?;
        }
        let images = levels.each_ref().map(|l| l.image(&run.settings));
        let bias = StepBias::calibrate(
            dt0,
            [&images[0], &images[1], &images[2]],
            levels.each_ref().map(Level::noise),
        );
        // More calibration frames only while the noise hides whether four times the step
        // would meet the target, and while that costs little beside the frames the target
        // needs (the grown images' samples at most an eighth of them).
        let e_rmse = target
            .error
            .map(|e| e * rmse_per_unit(target.metric, &levels[0], &run.settings));
        // (Unclear only where four times the frames could settle it: the noise's part of the
        // bound falls at most fourfold with them, at the fastest rate `Convergence` allows.)
        let unclear = e_rmse.is_some_and(|e| {
            let (room, at, bound) = (
                BIAS_SHARE.sqrt() * e,
                bias.at(4.0 * dt0),
                bias.bound(4.0 * dt0),
            );
            bound > room && at < room && at + 0.25 * (bound - at) <= room
        });
        let needed = e_rmse.map_or(0.0, |e| {
            levels[0]
                .convergence()
                .frames_for((1.0 - BIAS_SHARE).sqrt() * e)
        });
        if !unclear
            || step_fixed
            || frames >= MAX_CALIBRATION_FRAMES
            || f64::from(levels[0].spp_at(4 * frames)) > 0.125 * needed
            || run.out_of_time()
        {
            return Ok((bias, e_rmse));
        }
        frames = (frames * 4).min(MAX_CALIBRATION_FRAMES);
    }
}

/// Renders at the step the calibration chooses, growing the calibration and choosing again
/// while the bias the estimate carries is not settled beside the image's noise.
fn render_at_chosen_step(
    mut run: Run<'_>,
    mut levels: [Level; 3],
    mut bias: StepBias,
    e_rmse: Option<f64>,
    step_fixed: bool,
    lattice: Option<u32>,
) -> Result<Targeted, RenderError> {
    let (target, dt0, seed) = (run.target, run.dt0, run.settings.seed);
    let calibration = run.session.elapsed();
    // The level at a step finer than dt0, where one was chosen: (j, level).
    let mut finer: Option<(i32, Level)> = None;
    loop {
        let (j, spp) = choose_step(&run, &levels, &bias, e_rmse, step_fixed, &finer);
        let dt = dt0 * 2f64.powi(j);
        let b = bias.at(dt);
        let bias_images = (
            levels[1].image(&run.settings),
            levels[0].image(&run.settings),
        );
        let level = match usize::try_from(j) {
            Ok(i) => &mut levels[i],
            Err(_) => {
                if finer.as_ref().is_none_or(|(k, _)| *k != j) {
                    finer = Some((j, Level::new(dt, seed, lattice)));
                }
                &mut finer.as_mut().expect("just set").1
            }
        };
        // Past its first mask cycle one sequence of whole cycles is no less noisy than two
        // of half as many, so a sequence predicted to need more than one cycle gains nothing
        // from the lattice and would pay it for its first cycle: a pair measures its noise
        // instead.
        if let Some(d) = lattice
            && level.frames_for(spp) > d
        {
            level.measure_by_pair();
        }
        let done = finish(
            &mut run,
            level,
            spp,
            Chosen {
                bias,
                b,
                bias_images,
                calibration,
            },
        )?;
        // The estimate holds where the bias it carries is settled beside the image's noise
        // (`StepBias::settled`); otherwise the calibration images the bias rests on grow
        // until it is, and the render goes on from the new estimate.
        let settled = !(done.met && target.error.is_some() && target.metric == ErrorMetric::Rmse)
            || step_fixed
            || bias.settled(dt, done.noise_rmse, e_rmse.unwrap_or(f64::INFINITY))
            || run.out_of_time();
        if settled || !grow_calibration(&mut run, &mut levels, j)? {
            return Ok(Targeted {
                calibration: done.calibration,
                ..done
            });
        }
        let images = levels.each_ref().map(|l| l.image(&run.settings));
        bias = StepBias::calibrate(
            dt0,
            [&images[0], &images[1], &images[2]],
            levels.each_ref().map(Level::noise),
        );
        tracing::debug!(
            "targeted: the bias at step x{} was not settled beside the noise {:.3e}: calibration grown to {:?} frames, bias now {:.3e} ({bias:?})",
            2f64.powi(j),
            done.noise_rmse,
            levels.each_ref().map(|l| l.a.frames),
            bias.at(dt),
        );
    }
}
