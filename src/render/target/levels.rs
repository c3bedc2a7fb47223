//! The sequences of frames a targeted render keeps, one per step it tries, and what each
//! says of its noise.

use super::*;

/// The running mean of one sequence of frames, in f64.
#[derive(Clone)]
pub(super) struct Sequence {
    pub(super) seed: u32,
    pub(super) frames: u32,
    pub(super) mean: Vec<[f64; 4]>,
    /// The means of its whole mask cycles, where they measure its noise.
    pub(super) cycles: Option<WholeCycles>,
}

/// What a sequence keeps of its whole mask cycles' means: each cycle reads the mask at its own
/// shift, so they are independent, and their spread measures the noise of a sequence of
/// whole cycles.
#[derive(Clone)]
pub(super) struct WholeCycles {
    /// Frames of a mask cycle.
    pub(super) length: u32,
    /// The sequence's mean at the end of its last whole cycle.
    pub(super) last_mean: Vec<[f64; 4]>,
    /// The sum over whole cycles of the square of each cycle's mean, per pixel (RGB).
    pub(super) squares: Vec<[f64; 3]>,
}

impl Sequence {
    pub(super) fn new(seed: u32) -> Sequence {
        Sequence {
            seed,
            frames: 0,
            mean: Vec::new(),
            cycles: None,
        }
    }

    /// A sequence that keeps its whole `length`-frame cycles' spread ([`Self::whole_cycles_noise`]);
    /// it takes its frames in chunks within one cycle each.
    pub(super) fn with_cycles(seed: u32, length: u32) -> Sequence {
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
    pub(super) fn chunk_room(&self) -> u32 {
        self.cycles
            .as_ref()
            .map_or(u32::MAX, |c| c.length - self.frames % c.length)
    }

    /// Folds in `image`, the mean of this sequence's next `count` frames.
    pub(super) fn add(&mut self, image: &Image, count: u32) {
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
    pub(super) fn whole_cycles_noise(&self) -> Option<f64> {
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

    pub(super) fn image(&self, width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            pixels: self.mean.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
    }
}

/// What measures the noise of a level's image beside its sequence of frames.
pub(super) enum Companion {
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
pub(super) struct Level {
    pub(super) dt: f64,
    pub(super) a: Sequence,
    pub(super) companion: Companion,
    /// (frames of the image's sequence, noise of the image) at each check, oldest first.
    pub(super) history: Vec<(u32, f64)>,
    /// Seconds rendering, over all frames of both sequences.
    pub(super) seconds: f64,
}

impl Level {
    /// A level at step `dt` whose noise is measured on the half-resolution lattice where
    /// `lattice` is `Some(mask cycle)`, by a pair otherwise.
    pub(super) fn new(dt: f64, seed: u32, lattice: Option<u32>) -> Level {
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
    pub(super) fn measure_by_pair(&mut self) {
        if matches!(self.companion, Companion::Lattice(_)) {
            self.companion = Companion::Pair(Sequence::new(self.a.seed ^ SECOND_SEED));
            // A pair needs no whole cycles' spread (nor chunks cut at cycle ends).
            self.a.cycles = None;
            // The noise so far was of one sequence, not of a pair's mean.
            self.history.clear();
        }
    }

    /// The image's samples per pixel from `frames` frames of its sequence.
    pub(super) fn spp_at(&self, frames: u32) -> u32 {
        match self.companion {
            Companion::Pair(_) => 2 * frames,
            Companion::Lattice(_) => frames,
        }
    }

    /// The image's samples per pixel.
    pub(super) fn spp(&self) -> u32 {
        self.spp_at(self.a.frames)
    }

    /// Frames of the image's sequence for `spp` samples per pixel (rounded up).
    pub(super) fn frames_for(&self, spp: f64) -> u32 {
        let per_frame = f64::from(self.spp_at(1));
        (spp / per_frame).ceil().min(f64::from(u32::MAX)) as u32
    }

    /// Seconds per sample per pixel of the image, the companion's share included.
    pub(super) fn frame_time(&self) -> f64 {
        self.seconds / f64::from(self.spp().max(1))
    }

    /// Seconds per frame of the image's sequence, the companion's share included.
    pub(super) fn step_time(&self) -> f64 {
        self.seconds / f64::from(self.a.frames.max(1))
    }

    /// Whether the noise at `frames` frames of the image's sequence needs the companion there.
    pub(super) fn needs_companion_at(&self, frames: u32) -> bool {
        match (&self.companion, &self.a.cycles) {
            (Companion::Lattice(_), Some(c)) => {
                frames < 2 * c.length || !frames.is_multiple_of(c.length)
            }
            _ => true,
        }
    }

    pub(super) fn image(&self, settings: &RenderSettings) -> Image {
        let a = self.a.image(settings.width, settings.height);
        match &self.companion {
            Companion::Pair(b) => a.offset_by(&a, &b.image(settings.width, settings.height), -0.5),
            Companion::Lattice(_) => a,
        }
    }

    /// The two sequences' images where the companion is a pair: their half difference is a
    /// realisation of the image's noise.
    pub(super) fn pair_images(&self, settings: &RenderSettings) -> Option<(Image, Image)> {
        let (w, h) = (settings.width, settings.height);
        match &self.companion {
            Companion::Pair(b) => Some((self.a.image(w, h), b.image(w, h))),
            Companion::Lattice(_) => None,
        }
    }

    /// The noise (RMSE over RGB) of the image now, or `None` where the lattice measured it
    /// on too few pixels to stand for the image ([`MIN_LATTICE_PIXELS`]).
    pub(super) fn measure_noise(&self, settings: &RenderSettings) -> Option<f64> {
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

    pub(super) fn noise(&self) -> f64 {
        self.history.last().map_or(f64::INFINITY, |h| h.1)
    }

    /// How the noise fell over the last two checks (in the image's samples per pixel).
    pub(super) fn convergence(&self) -> Convergence {
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
