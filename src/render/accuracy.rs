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

use super::cycles::{mask_cycle, stratified_cycle};
use super::session::{RenderError, RenderSession};
use super::settings::RenderSettings;
pub use super::step_bias::StepBias;
use crate::values::Image;
use crate::values::frame::half_lattice_size;

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
    pub frames: u32,
    pub noise: f64,
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
    pub error: Option<f64>,
    pub time_budget: Option<Duration>,
    pub metric: ErrorMetric,
    /// The most samples per pixel it may take.
    pub max_spp: u32,
}

impl Target {
    pub const DEFAULT_MAX_SPP: u32 = 1 << 16;

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
    pub image: Image,
    pub step_size: f64,
    pub spp: u32,
    /// The estimated error in the target's metric.
    pub estimate: f64,
    pub noise_rmse: f64,
    pub bias: StepBias,
    /// How the noise fell with the frames (the last two estimates).
    pub convergence: Convergence,
    /// Whether the estimate meets the target error (always true with only a time budget).
    pub met: bool,
    pub elapsed: Duration,
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
/// step, 120-128, 0.96-0.98. (At 48 the dam break's 32x32 targets in `tests/accuracy.rs`,
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

/// The running mean of one sequence of frames, in f64.
#[derive(Clone)]
struct Sequence {
    seed: u32,
    frames: u32,
    mean: Vec<[f64; 4]>,
    /// The means of its whole mask cycles, where they measure its noise.
    cycles: Option<WholeCycles>,
}

/// What a sequence keeps of its whole mask cycles' means: each cycle reads the mask at its own
/// shift, so they are independent, and their spread measures the noise of a sequence of
/// whole cycles.
#[derive(Clone)]
struct WholeCycles {
    /// Frames of a mask cycle.
    length: u32,
    /// The sequence's mean at the end of its last whole cycle.
    last_mean: Vec<[f64; 4]>,
    /// The sum over whole cycles of the square of each cycle's mean, per pixel (RGB).
    squares: Vec<[f64; 3]>,
}

impl Sequence {
    fn new(seed: u32) -> Sequence {
        Sequence {
            seed,
            frames: 0,
            mean: Vec::new(),
            cycles: None,
        }
    }

    /// A sequence that keeps its whole `length`-frame cycles' spread ([`Self::whole_cycles_noise`]);
    /// it takes its frames in chunks within one cycle each.
    fn with_cycles(seed: u32, length: u32) -> Sequence {
        Sequence {
            cycles: Some(WholeCycles {
                length,
                last_mean: Vec::new(),
                squares: Vec::new(),
            }),
            ..Sequence::new(seed)
        }
    }

    /// The most frames the next chunk may have (a chunk never spans two mask cycles where the
    /// cycles are kept).
    fn chunk_room(&self) -> u32 {
        self.cycles
            .as_ref()
            .map_or(u32::MAX, |c| c.length - self.frames % c.length)
    }

    /// Folds in `image`, the mean of this sequence's next `count` frames.
    fn add(&mut self, image: &Image, count: u32) {
        debug_assert!(count <= self.chunk_room(), "a chunk spans two mask cycles");
        let total = f64::from(self.frames + count);
        let (w_old, w_new) = (f64::from(self.frames) / total, f64::from(count) / total);
        if self.mean.len() != image.pixels.len() {
            self.mean = vec![[0.0; 4]; image.pixels.len()];
        }
        for (m, p) in self.mean.iter_mut().zip(&image.pixels) {
            for c in 0..4 {
                m[c] = w_old * m[c] + w_new * f64::from(p[c]);
            }
        }
        self.frames += count;
        if let Some(cycles) = &mut self.cycles
            && self.frames.is_multiple_of(cycles.length)
        {
            // The cycle just ended: its mean is k M_k - (k - 1) M_(k-1).
            let k = f64::from(self.frames / cycles.length);
            if cycles.last_mean.len() != self.mean.len() {
                cycles.last_mean = vec![[0.0; 4]; self.mean.len()];
                cycles.squares = vec![[0.0; 3]; self.mean.len()];
            }
            for ((m, last), sq) in self
                .mean
                .iter()
                .zip(cycles.last_mean.iter_mut())
                .zip(cycles.squares.iter_mut())
            {
                for c in 0..3 {
                    let cycle_mean = k * m[c] - (k - 1.0) * last[c];
                    sq[c] += cycle_mean * cycle_mean;
                }
                *last = *m;
            }
        }
    }

    /// The noise (RMSE over RGB) of this sequence's image where it is two or more whole mask
    /// cycles kept by [`Self::with_cycles`]: from the spread of the cycles' means (per pixel,
    /// their sample variance over the cycles, divided by the cycles).
    fn whole_cycles_noise(&self) -> Option<f64> {
        let cycles = self.cycles.as_ref()?;
        let k = self.frames / cycles.length;
        if k < 2 || !self.frames.is_multiple_of(cycles.length) {
            return None;
        }
        let k = f64::from(k);
        let sum: f64 = self
            .mean
            .iter()
            .zip(&cycles.squares)
            .map(|(m, sq)| {
                (0..3)
                    .map(|c| ((sq[c] - k * m[c] * m[c]) / (k - 1.0)).max(0.0))
                    .sum::<f64>()
            })
            .sum();
        Some((sum / (3 * self.mean.len().max(1)) as f64 / k).sqrt())
    }

    fn image(&self, width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            pixels: self.mean.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
    }
}

/// What measures the noise of a level's image beside its sequence of frames.
enum Companion {
    /// A second independent sequence of the whole image: the image is the mean of both and
    /// its noise half their RMS difference (the dual-buffer estimate). For frames that are not
    /// stratified, where the mean of two sequences is as good as one of twice the frames, and
    /// for FLIP targets, whose estimate needs a full-resolution realisation of the noise.
    Pair(Sequence),
    /// A sequence of the image's half-resolution lattice (the rays of its even pixels, a
    /// quarter of the work): the image is the first sequence alone, stratified over the mask's
    /// cycle as one sequence is and two independent ones are not, and its noise is that of
    /// the two sequences' difference on the lattice over sqrt 2. Once the image is two or more
    /// whole mask cycles their spread measures its noise instead, and the lattice stops.
    Lattice(Sequence),
}

/// The frames of one step: the image's sequence and its companion.
struct Level {
    dt: f64,
    a: Sequence,
    companion: Companion,
    /// (frames of the image's sequence, noise of the image) at each check, oldest first.
    history: Vec<(u32, f64)>,
    /// Seconds rendering, over all frames of both sequences.
    seconds: f64,
}

impl Level {
    /// A level at step `dt` whose noise is measured on the half-resolution lattice where
    /// `lattice` is `Some(mask cycle)`, by a pair otherwise.
    fn new(dt: f64, seed: u32, lattice: Option<u32>) -> Level {
        let second = Sequence::new(seed ^ SECOND_SEED);
        let (a, companion) = match lattice {
            Some(cycle) => (
                Sequence::with_cycles(seed, cycle),
                Companion::Lattice(second),
            ),
            None => (Sequence::new(seed), Companion::Pair(second)),
        };
        Level {
            dt,
            a,
            companion,
            history: Vec::new(),
            seconds: 0.0,
        }
    }

    /// From now on, the noise is measured by a second sequence of the whole image (rendered
    /// from its first frame at the next extension) instead of the lattice.
    fn measure_by_pair(&mut self) {
        if matches!(self.companion, Companion::Lattice(_)) {
            self.companion = Companion::Pair(Sequence::new(self.a.seed ^ SECOND_SEED));
            // A pair needs no whole cycles' spread (nor chunks cut at cycle ends).
            self.a.cycles = None;
            // The noise so far was of one sequence, not of a pair's mean.
            self.history.clear();
        }
    }

    /// The image's samples per pixel from `frames` frames of its sequence.
    fn spp_at(&self, frames: u32) -> u32 {
        match self.companion {
            Companion::Pair(_) => 2 * frames,
            Companion::Lattice(_) => frames,
        }
    }

    /// The image's samples per pixel.
    fn spp(&self) -> u32 {
        self.spp_at(self.a.frames)
    }

    /// Frames of the image's sequence for `spp` samples per pixel (rounded up).
    fn frames_for(&self, spp: f64) -> u32 {
        let per_frame = f64::from(self.spp_at(1));
        (spp / per_frame).ceil().min(f64::from(u32::MAX)) as u32
    }

    /// Seconds per sample per pixel of the image, the companion's share included.
    fn frame_time(&self) -> f64 {
        self.seconds / f64::from(self.spp().max(1))
    }

    /// Seconds per frame of the image's sequence, the companion's share included.
    fn step_time(&self) -> f64 {
        self.seconds / f64::from(self.a.frames.max(1))
    }

    /// Whether the noise at `frames` frames of the image's sequence needs the companion there.
    fn needs_companion_at(&self, frames: u32) -> bool {
        match (&self.companion, &self.a.cycles) {
            (Companion::Lattice(_), Some(c)) => {
                frames < 2 * c.length || !frames.is_multiple_of(c.length)
            }
            _ => true,
        }
    }

    fn image(&self, settings: &RenderSettings) -> Image {
        let a = self.a.image(settings.width, settings.height);
        match &self.companion {
            Companion::Pair(b) => a.offset_by(&a, &b.image(settings.width, settings.height), -0.5),
            Companion::Lattice(_) => a,
        }
    }

    /// The two sequences' images where the companion is a pair: their half difference is a
    /// realisation of the image's noise.
    fn pair_images(&self, settings: &RenderSettings) -> Option<(Image, Image)> {
        let (w, h) = (settings.width, settings.height);
        match &self.companion {
            Companion::Pair(b) => Some((self.a.image(w, h), b.image(w, h))),
            Companion::Lattice(_) => None,
        }
    }

    /// The noise (RMSE over RGB) of the image now, or `None` where the lattice measured it
    /// on too few pixels to stand for the image ([`MIN_LATTICE_PIXELS`]).
    fn measure_noise(&self, settings: &RenderSettings) -> Option<f64> {
        let (w, h) = (settings.width, settings.height);
        match &self.companion {
            Companion::Pair(b) => Some(noise_of_pair(&self.a.image(w, h), &b.image(w, h))),
            Companion::Lattice(b) => match self.a.whole_cycles_noise() {
                Some(noise) => Some(noise),
                None => {
                    debug_assert_eq!(b.frames, self.a.frames);
                    let (lw, lh) = half_lattice_size(w, h);
                    let (image, lattice) = (self.a.image(w, h), b.image(lw, lh));
                    let pixels = lattice_noise_pixels(&image, &lattice);
                    tracing::debug!(
                        "targeted: the lattice's noise rests on {pixels:.0} of {} pixels",
                        lattice.pixels.len()
                    );
                    (pixels >= MIN_LATTICE_PIXELS).then(|| noise_on_lattice(&image, &lattice))
                }
            },
        }
    }

    fn noise(&self) -> f64 {
        self.history.last().map_or(f64::INFINITY, |h| h.1)
    }

    /// How the noise fell over the last two checks (in the image's samples per pixel).
    fn convergence(&self) -> Convergence {
        match self.history.as_slice() {
            [.., a, b] => Convergence::of((self.spp_at(a.0), a.1), (self.spp_at(b.0), b.1)),
            [b] => Convergence {
                frames: self.spp_at(b.0),
                noise: b.1,
                rate: 0.5,
            },
            [] => Convergence {
                frames: 1,
                noise: f64::INFINITY,
                rate: 0.5,
            },
        }
    }
}

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

struct Run<'a> {
    session: &'a mut RenderSession,
    settings: RenderSettings,
    target: Target,
    started: Instant,
    dt0: f64,
    work: f64,
}

impl Run<'_> {
    fn at(&self, dt: f64, seed: u32) -> RenderSettings {
        RenderSettings {
            step_size: Some(dt),
            seed,
            ..self.settings.clone()
        }
    }

    fn out_of_time(&self) -> bool {
        self.target
            .time_budget
            .is_some_and(|b| self.started.elapsed() >= b)
    }

    /// Extends the image's sequence of `level` to `frames` frames (or fewer when the time
    /// budget runs out: whole chunks of one frame then), and its companion where the noise
    /// needs it, and records the noise.
    fn extend(&mut self, level: &mut Level, frames: u32) -> Result<(), RenderError> {
        let before = level.a.frames;
        let companion_follows = level.needs_companion_at(frames);
        while level.a.frames < frames {
            let mut count = frames - level.a.frames;
            if let Some(budget) = self.target.time_budget {
                if level.a.frames == 0 {
                    // A fresh level's frame time is unknown: one frame measures it.
                    count = 1;
                } else {
                    // Chunks of at most half the time left, at the frame time measured so
                    // far: a chunk that runs slower than measured (a busy machine) overshoots
                    // the budget by at most its share of that half, and the next one measures
                    // again.
                    let left = budget.saturating_sub(self.started.elapsed()).as_secs_f64();
                    let step_time = level.step_time().max(1e-9);
                    if left < step_time {
                        break;
                    }
                    count = count.min(((0.5 * left / step_time).floor() as u32).max(1));
                }
            }
            count = count.min(level.a.chunk_room());
            let started = Instant::now();
            let settings = self.at(level.dt, level.a.seed);
            let image = self
                .session
                .render_frames(&settings, level.a.frames, count)?;
            level.a.add(&image, count);
            level.seconds += started.elapsed().as_secs_f64();
            self.work += f64::from(count) * self.dt0 / level.dt;
            if companion_follows {
                self.extend_companion(level)?;
            }
        }
        // A budget that stopped the sequence short of `frames` may need the companion where
        // it did not follow.
        if level.needs_companion_at(level.a.frames) {
            self.extend_companion(level)?;
        }
        if level.a.frames > before || level.history.is_empty() {
            let noise = match level.measure_noise(&self.settings) {
                Some(noise) => noise,
                None => {
                    // The noise sits in too few pixels for a quarter of them to measure it:
                    // a second sequence of the whole image does, from its first frame.
                    level.measure_by_pair();
                    self.extend_companion(level)?;
                    level
                        .measure_noise(&self.settings)
                        .expect("a pair always measures")
                }
            };
            level.history.push((level.a.frames, noise));
        }
        Ok(())
    }

    /// Brings the companion of `level` to as many frames as its image's sequence.
    fn extend_companion(&mut self, level: &mut Level) -> Result<(), RenderError> {
        let started = Instant::now();
        let (to, dt) = (level.a.frames, level.dt);
        let (sequence, on_lattice) = match &mut level.companion {
            Companion::Pair(b) => (b, false),
            Companion::Lattice(b) => (b, true),
        };
        if sequence.frames >= to {
            return Ok(());
        }
        let count = to - sequence.frames;
        let settings = self.at(dt, sequence.seed);
        let (image, share) = if on_lattice {
            let (w, h) = (settings.width, settings.height);
            let (lw, lh) = half_lattice_size(w, h);
            let image =
                self.session
                    .render_frames_on_half_lattice(&settings, sequence.frames, count)?;
            (image, f64::from(lw * lh) / f64::from(w * h))
        } else {
            let image = self
                .session
                .render_frames(&settings, sequence.frames, count)?;
            (image, 1.0)
        };
        sequence.add(&image, count);
        level.seconds += started.elapsed().as_secs_f64();
        self.work += share * f64::from(count) * self.dt0 / dt;
        Ok(())
    }

    /// Whether the session accepts step `dt` (the march's sample bound).
    fn allowed(&self, dt: f64) -> bool {
        self.session.resolve(&self.at(dt, 0)).is_ok()
    }
}

/// Renders `settings` (its step size as the starting step, or fixed when set) until the
/// estimated error meets `target.error` or `target.time_budget` is spent.
pub fn render_to_target(
    session: &mut RenderSession,
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
        started: Instant::now(),
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
    let mut frames = CALIBRATION_FRAMES;

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
    {
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
                let calibration = run.started.elapsed();
                let bias_images = (
                    levels[2].image(&run.settings),
                    levels[1].image(&run.settings),
                );
                let done = finish(
                    &mut run,
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
                    return Ok(done);
                }
                tracing::debug!(
                    "targeted: loose: the bias at twice the step is not settled beside the noise {:.3e} ({bias:?}): the full calibration",
                    done.noise_rmse
                );
            }
        }
    }
    let (bias, e_rmse) = loop {
        for level in &mut levels {
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
            break (bias, e_rmse);
        }
        frames = (frames * 4).min(MAX_CALIBRATION_FRAMES);
    };
    let calibration = run.started.elapsed();
    let mut bias = bias;
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

/// Grows the calibration images that the bias at step `dt0 · 2^j` rests on (the images at
/// `dt0` and `2 dt0`, or `dt0` and `4 dt0` for `j = 2`), after the render at that step met
/// the target while its bias was not settled ([`StepBias::settled`]): the noisier of the two
/// (the chosen step's image counts with its final frames) to four times its frames, at most
/// to the other's noise, or both to twice where they are about as noisy. Returns whether
/// anything was rendered (false at the sample limit).
fn grow_calibration(
    run: &mut Run<'_>,
    levels: &mut [Level; 3],
    j: i32,
) -> Result<bool, RenderError> {
    let other = if j == 2 { 2 } else { 1 };
    let cycle = mask_cycle(&run.settings);
    let (n0, n1) = (levels[0].noise(), levels[other].noise());
    let mut grown = false;
    let even = n0 >= 0.7 * n1 && n1 >= 0.7 * n0;
    let plan = [(0, n0 >= 0.7 * n1, n1), (other, n1 >= 0.7 * n0, n0)];
    for (i, grow, towards) in plan {
        if !grow {
            continue;
        }
        let level = &mut levels[i];
        let reached = level.a.frames;
        let factor = if even { 3 } else { 4 };
        let mut wanted = f64::from(reached * factor);
        if !even {
            wanted =
                wanted.min(level.convergence().frames_for(towards) / f64::from(level.spp_at(1)));
        }
        let frames = stop_at(
            wanted.max(f64::from(reached + 1)).ceil() as u32,
            reached,
            cycle,
        )
        .min(run.target.max_spp / level.spp_at(1))
        .max(reached);
        if frames > reached {
            run.extend(level, frames)?;
            grown = true;
        }
    }
    Ok(grown)
}

/// The step (`dt0 · 2^j`) and samples per pixel of the least predicted time to the target, or
/// the least predicted error within the budget, from the calibration.
fn choose_step(
    run: &Run<'_>,
    levels: &[Level; 3],
    bias: &StepBias,
    e_rmse: Option<f64>,
    step_fixed: bool,
    finer: &Option<(i32, Level)>,
) -> (i32, f64) {
    let (target, dt0) = (run.target, run.dt0);
    let steps: Vec<i32> = if step_fixed {
        vec![0]
    } else {
        (-3..=2).collect()
    };
    let fine = &levels[0];
    let mut best: Option<(f64, i32, f64)> = None; // (score, j, spp)
    for &j in &steps {
        let dt = dt0 * 2f64.powi(j);
        if !run.allowed(dt) {
            continue;
        }
        let level = usize::try_from(j)
            .ok()
            .and_then(|j| levels.get(j))
            .or_else(|| finer.as_ref().filter(|(k, _)| *k == j).map(|(_, l)| l));
        let convergence = level.map_or(fine.convergence(), Level::convergence);
        let frame_time = level.map_or(fine.frame_time() * 2f64.powi(-j), Level::frame_time);
        let b = bias.at(dt);
        // Twice dt0 on its estimated bias (the default step resolves the kernel with room to
        // spare: its doubling's bias stayed below 0.3 of the noise in every scene measured);
        // four times only where the bias is known to fit, noise and all.
        let b_choice = if j > 1 { bias.bound(dt) } else { b };
        let held = level.map_or(0, Level::spp);
        let (score, spp) = match (e_rmse, target.time_budget) {
            (Some(e), _) => {
                if b_choice * b_choice > BIAS_SHARE * e * e {
                    continue;
                }
                let spp = convergence.frames_for((e * e - b * b).sqrt()).ceil();
                ((spp - f64::from(held)).max(0.0) * frame_time, spp)
            }
            (None, Some(budget)) => {
                let left = budget.saturating_sub(run.started.elapsed()).as_secs_f64();
                let spp = f64::from(held) + left / frame_time.max(1e-9);
                let noise = convergence.noise_at(spp);
                (b_choice * b_choice + noise * noise, spp)
            }
            (None, None) => unreachable!("checked: a target has an error or a budget"),
        };
        tracing::debug!(
            "targeted: step x{:.3}: bias {b:.3e} (bound {:.3e}), noise {:.3e} at {} spp falling at rate {:.2}, frame {:.3e} s: {spp} spp, score {score:.3e}",
            2f64.powi(j),
            bias.bound(dt),
            convergence.noise,
            convergence.frames,
            convergence.rate,
            frame_time,
        );
        if best.is_none_or(|(s, _, _)| score < s) {
            best = Some((score, j, spp));
        }
    }
    // A target no step reaches within its bias share: the finest allowed step.
    match best {
        Some((_, j, spp)) => (j, spp),
        None => {
            let j = steps
                .iter()
                .copied()
                .find(|&j| run.allowed(dt0 * 2f64.powi(j)))
                .unwrap_or(0);
            tracing::warn!(
                "the target error is below the march's estimated bias at every step tried; rendering at the finest"
            );
            (j, f64::from(target.max_spp))
        }
    }
}

/// What the calibration chose, for the render to the target.
struct Chosen {
    bias: StepBias,
    /// The estimated bias at the chosen step.
    b: f64,
    /// Two calibration images a step apart (the coarser first): a realisation of the bias
    /// for the FLIP estimate.
    bias_images: (Image, Image),
    calibration: Duration,
}

/// Renders `level` from `spp` samples on, checking the estimate and going on while it falls
/// short of the target.
fn finish(
    run: &mut Run<'_>,
    level: &mut Level,
    mut spp: f64,
    chosen: Chosen,
) -> Result<Targeted, RenderError> {
    let Chosen {
        bias,
        b,
        bias_images,
        calibration,
    } = chosen;
    let target = run.target;
    let dt = level.dt;
    // Render, check, and go on while the estimate falls short.
    let spinner = crate::progress::spinner("rendering to the target");
    // Whether the sequences stop only at the ends of mask cycles (see `stop_at`).
    let mut cycle = mask_cycle(&run.settings);
    loop {
        let before = level.a.frames;
        let mut frames = stop_at(level.frames_for(spp), before, cycle)
            .clamp(1, target.max_spp / level.spp_at(1))
            .max(before);
        // Past the first cycle a budget starts only the cycles that fit in the time left: an
        // incomplete one would make the image worse, not better.
        let mut no_cycle_fits = false;
        if let (Some(budget), Some(d)) = (target.time_budget, cycle)
            && before >= d
        {
            let left = budget.saturating_sub(run.started.elapsed()).as_secs_f64();
            let cycles = (left / (f64::from(d) * level.step_time()).max(1e-9)).floor();
            frames = frames.min(before + d * cycles.min(f64::from(u32::MAX / d)) as u32);
            no_cycle_fits = frames == before;
        }
        run.extend(level, frames)?;
        let image = level.image(&run.settings);
        let noise = level.noise();
        let estimate = match target.metric {
            ErrorMetric::Rmse => noise.hypot(b),
            ErrorMetric::Flip => {
                // One realisation of the noise ((A - B) / 2) and of the bias (the calibration
                // difference from dt0 to 2 dt0, scaled to the bias at this step) added.
                let (a, bb) = level
                    .pair_images(&run.settings)
                    .expect("FLIP targets measure their noise by a pair");
                let scale = b / bias_images.0.rmse(&bias_images.1).max(1e-30);
                let disturbed =
                    image
                        .offset_by(&a, &bb, 0.5)
                        .offset_by(&bias_images.0, &bias_images.1, scale);
                image.flip(&disturbed)
            }
        };
        spinner.set_message(format!(
            "{} spp at step {dt:.3e}: estimated error {estimate:.3e}{}",
            level.spp(),
            target
                .error
                .map_or(String::new(), |e| format!(" (target {e:.3e})"))
        ));
        let met = target.error.is_none_or(|e| estimate <= e);
        let reached = level.a.frames;
        // Where completing the first cycle brought the noise down no faster than independent
        // samples would (the integrator draws most of its numbers from white noise, as delta
        // tracking does), whole cycles buy nothing: stop anywhere from here.
        if let (Some(d), [.., earlier, now]) = (cycle, level.history.as_slice())
            && now.0 == d
            && earlier.0 < d
            && Convergence::of(*earlier, *now).rate < STRATIFIED_RATE
        {
            cycle = None;
        }
        tracing::debug!(
            "targeted: {reached} frames a sequence at step {dt:.3e}: noise {noise:.3e}, estimate {estimate:.3e}"
        );
        let finished = (target.error.is_some() && met)
            || run.out_of_time()
            || level.spp() >= target.max_spp
            || reached < frames
            || no_cycle_fits;
        if finished {
            spinner.finish_and_clear();
            return Ok(Targeted {
                image,
                step_size: dt,
                spp: level.spp(),
                estimate,
                noise_rmse: noise,
                bias,
                convergence: level.convergence(),
                met,
                elapsed: run.started.elapsed(),
                calibration,
                work: run.work,
            });
        }
        // Short: predict again from the noise measured now (a budget alone renders on until
        // the time is spent). At whole mask cycles the noise falls as N^-1/2 from here.
        let now = f64::from(level.spp());
        let convergence = match cycle {
            Some(d) if reached >= d && reached.is_multiple_of(d) => Convergence {
                frames: level.spp(),
                noise,
                rate: 0.5,
            },
            _ => level.convergence(),
        };
        let predicted = match (target.error, target.metric) {
            (Some(e), ErrorMetric::Rmse) => {
                convergence.frames_for((e * e - b * b).max(0.1 * e * e).sqrt())
            }
            (Some(e), ErrorMetric::Flip) => now * (estimate / e).powf(1.0 / convergence.rate),
            (None, _) => 2.0 * now,
        };
        spp = if predicted.is_finite() {
            // At most doubling: the prediction's rate is of the frames so far.
            predicted.clamp(now + 2.0, 2.0 * now)
        } else {
            2.0 * now
        };
    }
}

/// RMSE per unit of the target's metric, from a calibration level's noise (FLIP grows about
/// linearly with small errors).
fn rmse_per_unit(metric: ErrorMetric, level: &Level, settings: &RenderSettings) -> f64 {
    match metric {
        ErrorMetric::Rmse => 1.0,
        ErrorMetric::Flip => {
            let (a, b) = level
                .pair_images(settings)
                .expect("FLIP targets measure their noise by a pair");
            let image = level.image(settings);
            let flip = image.flip(&image.offset_by(&a, &b, 0.5));
            if flip > 0.0 && level.noise().is_finite() {
                level.noise() / flip
            } else {
                1.0
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::BlueNoiseMask;
    use crate::values::NoiseKind;

    #[test]
    fn the_noise_falls_at_its_measured_rate() {
        let blue = Convergence::of((4, 0.1), (16, 0.025));
        assert!((blue.rate - 1.0).abs() < 1e-12);
        assert!((blue.frames_for(0.0125) - 32.0).abs() < 1e-9);
        let white = Convergence::of((16, 0.05), (4, 0.1));
        assert!((white.rate - 0.5).abs() < 1e-12);
        assert!((white.noise_at(64.0) - 0.025).abs() < 1e-12);
        // Rates outside what sampling gives are clamped.
        assert_eq!(Convergence::of((4, 0.1), (16, 0.001)).rate, 1.0);
        assert_eq!(Convergence::of((4, 0.1), (16, 0.2)).rate, 0.5);
    }

    /// A pixel value with Gaussian noise of standard deviation `sigma` (Box-Muller).
    fn noisy(rng: &mut rand_pcg::Pcg64, value: f64, sigma: f64) -> f32 {
        use rand::Rng;
        let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
        (value + sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
    }

    fn noisy_image(rng: &mut rand_pcg::Pcg64, w: u32, h: u32, sigma: f64) -> Image {
        Image {
            width: w,
            height: h,
            pixels: (0..w * h)
                .map(|k| {
                    // A smooth picture under the noise.
                    let v = 0.5 + 0.3 * (f64::from(k % w) * 0.1).sin();
                    [0, 1, 2, 3].map(|c| if c == 3 { 1.0 } else { noisy(rng, v, sigma) })
                })
                .collect(),
        }
    }

    #[test]
    fn whole_cycles_measure_the_noise_of_their_mean() {
        use rand::SeedableRng;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let (w, h, d, sigma) = (61, 47, 4, 0.02);
        let mut sequence = Sequence::with_cycles(1, d);
        assert_eq!(sequence.chunk_room(), d);
        for k in 1..=6u32 {
            // Each cycle's mean carries independent noise of `sigma`, in chunks of 3 and 1
            // frames whose own noise cancels over the cycle (stratified frames).
            let cycle = noisy_image(&mut rng, w, h, sigma);
            let spread = noisy_image(&mut rng, w, h, 0.3);
            let first = cycle.offset_by(&spread, &cycle, 1.0 / 3.0);
            let last = cycle.offset_by(&spread, &cycle, -1.0);
            sequence.add(&first, 3);
            assert_eq!(sequence.chunk_room(), 1);
            assert_eq!(sequence.whole_cycles_noise(), None, "within a cycle");
            sequence.add(&last, 1);
            let noise = sequence.whole_cycles_noise();
            if k < 2 {
                assert_eq!(noise, None, "one cycle has no spread");
                continue;
            }
            let want = sigma / f64::from(k).sqrt();
            let noise = noise.expect("whole cycles");
            assert!(
                (noise / want - 1.0).abs() < 0.05,
                "{k} cycles: {noise:.4e}, want {want:.4e}"
            );
        }
        // A sequence that keeps no cycles measures nothing by them.
        let mut plain = Sequence::new(1);
        plain.add(&noisy_image(&mut rng, w, h, sigma), 8);
        assert_eq!(plain.whole_cycles_noise(), None);
    }

    #[test]
    fn the_lattice_measures_the_noise_of_the_whole_image() {
        use rand::SeedableRng;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for (w, h) in [(96, 64), (97, 33)] {
            let sigma = 0.01;
            let image = noisy_image(&mut rng, w, h, sigma);
            // The lattice's own sequence: the same picture at the even pixels, its own noise.
            let independent = noisy_image(&mut rng, w, h, sigma).half_lattice();
            let estimate = noise_on_lattice(&image, &independent);
            assert!(
                (estimate / sigma - 1.0).abs() < 0.1,
                "{w}x{h}: {estimate:.4e}"
            );
        }
    }

    #[test]
    fn blue_noise_sequences_stop_at_whole_mask_cycles() {
        let d = Some(64);
        // Early in the first cycle: where the prediction says.
        assert_eq!(stop_at(12, 4, d), 12);
        assert_eq!(stop_at(47, 8, d), 47);
        // Most of the first cycle or beyond it: its end first, whatever the power law says.
        assert_eq!(stop_at(48, 8, d), 64);
        assert_eq!(stop_at(70, 8, d), 64);
        assert_eq!(stop_at(500, 2, d), 64);
        // Past it, whole cycles only.
        assert_eq!(stop_at(65, 64, d), 128);
        assert_eq!(stop_at(128, 64, d), 128);
        assert_eq!(stop_at(129, 128, d), 192);
        // White noise has no cycle.
        assert_eq!(stop_at(70, 8, None), 70);
        assert_eq!(stop_at(65, 64, None), 65);
        // The cycle of the settings: the built-in mask's depth, for blue noise only.
        let blue = RenderSettings::default();
        assert_eq!(mask_cycle(&blue), Some(BlueNoiseMask::builtin().depth));
        let white = RenderSettings {
            noise: NoiseKind::White,
            ..blue
        };
        assert_eq!(mask_cycle(&white), None);
    }

    #[test]
    fn targets_are_checked() {
        let ok = Target {
            error: Some(0.01),
            time_budget: None,
            metric: ErrorMetric::Rmse,
            max_spp: 64,
        };
        assert!(ok.check().is_ok());
        for bad in [
            Target { error: None, ..ok },
            Target {
                error: Some(-1.0),
                ..ok
            },
            Target {
                error: Some(f64::NAN),
                ..ok
            },
            Target { max_spp: 4, ..ok },
            Target {
                error: None,
                time_budget: Some(Duration::ZERO),
                ..ok
            },
        ] {
            assert!(bad.check().is_err(), "{bad:?}");
        }
    }
}
