//! The converged reference every error is measured against (`aarbf render --reference`,
//! `aarbf bench accuracy`, the error-estimate tests): the CPU backend in f64, with a march step
//! and a sample count fine enough that doubling the samples and halving the step each change
//! the image by less than a stated tolerance (RMSE over linear RGB). Both changes are checked
//! and reported, and the image is cached on disk per scene (keyed by the frame's every
//! parameter and a digest of the step's particles), so studies and tests reuse it. One
//! search ([`search_reference`]) runs on any renderer of chunks of frames: one process's
//! session, or the ranks of a distributed render (`crate::dist::converged_reference_on`),
//! whose parts' digests join to the whole step's, so both find each other's references.
//!
//! The samples are doubled until their change is within half the tolerance first, so the
//! step check that follows compares images whose noise cannot by itself exceed it.

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::time::Instant;

use base64::Engine as _;
use serde::{Deserialize, Serialize};

use super::RenderError;
use super::cycles::CycleWeights;
use super::session::RenderSession;
use super::settings::RenderSettings;
use super::target::{ChunkRenderer, SessionChunks};
use crate::accel::ClusterSize;
use crate::backend::Precision;
use crate::backend::cpu::CpuBackend;
use crate::field::FieldSettings;
use crate::scene::TimeSeries;
use crate::values::{FrameParams, Image, Integrator, NoiseKind, Step};

/// The seed of every reference (renders under test use their own).
pub const REFERENCE_SEED: u32 = 0x5EED_0F0F;

/// How converged a reference must be.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceOptions {
    /// The most an image may change (RMSE, linear RGB) when the samples double or the step
    /// halves.
    pub tolerance: f64,
    /// Samples per pixel the search starts from.
    pub start_spp: u32,
    /// The most samples per pixel it takes.
    pub max_spp: u32,
    /// Where references are cached (`None`: not cached).
    pub cache: Option<PathBuf>,
}

impl Default for ReferenceOptions {
    fn default() -> Self {
        ReferenceOptions {
            tolerance: 1e-3,
            start_spp: 4,
            max_spp: 1 << 14,
            cache: default_cache(),
        }
    }
}

/// `$XDG_CACHE_HOME/aarbf/references`, else `~/.cache/aarbf/references`.
pub fn default_cache() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))?;
    Some(base.join("aarbf").join("references"))
}

/// A converged reference and how converged it is.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Reference {
    /// The converged image; always `Some` once made or read (the cache file stores its pixels apart
    /// from these fields).
    #[serde(skip)]
    pub image: Option<Image>,
    /// The march step it converged at, data units.
    pub step_size: f64,
    /// Samples per pixel it converged at.
    pub spp: u32,
    /// RMSE between the image at `spp / 2` and at `spp` samples (at twice its step): its own
    /// noise, as the dual-buffer estimate has it.
    pub spp_change: f64,
    /// RMSE between the image at its step and at twice it (both at `spp`); `None` where the
    /// step could not be halved within the march's sample bound.
    pub step_change: Option<f64>,
    /// The RMSE (linear RGB) that both changes were to stay within.
    pub tolerance: f64,
    /// Whether both changes are within the tolerance (false: the sample or step limit came
    /// first; the changes say how close it got).
    pub converged: bool,
    /// Seconds it took to render (when first rendered, for one read from the cache).
    pub seconds: f64,
    /// Whether it was read from the cache instead of rendered.
    #[serde(skip)]
    pub from_cache: bool,
}

impl Reference {
    /// The converged image; panics where it holds none.
    pub fn image(&self) -> &Image {
        self.image.as_ref().expect("a reference holds its image")
    }
}

/// What a cache file holds.
#[derive(Serialize, Deserialize)]
struct CacheFile {
    key: String,
    width: u32,
    height: u32,
    /// The pixels as little-endian f32 RGBA, base64.
    pixels: String,
    reference: Reference,
}

/// What a reference of `settings` renders: its own noise and seed, and for a scattering
/// integrator the deterministic `ss-reference`, which every single-scattering integrator
/// converges to with the least noise (the step and samples are the search's).
pub fn reference_settings(settings: &RenderSettings) -> RenderSettings {
    let integrator = if settings.integrator.scatters() {
        Integrator::SsReference
    } else {
        settings.integrator
    };
    RenderSettings {
        noise: NoiseKind::Stbn,
        seed: REFERENCE_SEED,
        integrator,
        ..settings.clone()
    }
}

/// The converged reference of `settings` (its camera, size, maps and light; its noise and seed
/// are the reference's own, and a scattering integrator is the deterministic `ss-reference`
/// all of them converge to) for step `step` of `series` under `field`: one process's session
/// on the CPU backend in f64 (the ranks' is `crate::dist::converged_reference_on`).
pub fn converged_reference(
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: ClusterSize,
    settings: &RenderSettings,
    options: &ReferenceOptions,
) -> Result<Reference, RenderError> {
    options.check()?;
    let mut session = RenderSession::new(Box::new(CpuBackend::new()), series);
    session.set_precision(Precision::F64);
    session.show(series, step, field, cluster)?;
    let base = reference_settings(settings);
    let key = cache_key(
        &session.frame_params(&base, 0)?,
        ParticlesDigest::of(&*series.step(step)?),
        field,
        options,
    );
    let cache = ReferenceCache::new(options, key);
    if let Some(found) = cache.load() {
        tracing::info!("reference from the cache");
        return Ok(found);
    }
    let reference = search_reference(&mut SessionChunks::new(&mut session), &base, options, true)?;
    cache.store(&reference);
    Ok(reference)
}

impl ReferenceOptions {
    /// Refuses a tolerance or sample bounds no search can meet.
    pub fn check(&self) -> Result<(), RenderError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(RenderError::Settings(format!(
                "reference tolerance {} must be a positive number",
                self.tolerance
            )));
        }
        if self.start_spp == 0 || self.start_spp > self.max_spp {
            return Err(RenderError::Settings(format!(
                "reference samples: start {} must lie in 1..={}",
                self.start_spp, self.max_spp
            )));
        }
        Ok(())
    }
}

/// The search for the converged reference of `base` (already [`reference_settings`]) on the
/// frames `chunks` renders: the samples doubled until they change the image by at most half
/// the tolerance, then the step halved, until both changes are within it. Every process that
/// renders the chunks runs it on the same images and makes the same decisions; the one that
/// `speaks` shows the progress and warns where it did not converge.
pub fn search_reference(
    chunks: &mut dyn ChunkRenderer,
    base: &RenderSettings,
    options: &ReferenceOptions,
    speaks: bool,
) -> Result<Reference, RenderError> {
    let started = Instant::now();
    let at = |dt: f64| RenderSettings {
        step_size: Some(dt),
        ..base.clone()
    };
    let mut dt = chunks.resolve(base)?.step_size / 2.0;
    let mut spp = options.start_spp;
    let bar = if speaks {
        crate::progress::bar(u64::from(options.max_spp), "reference")
    } else {
        indicatif::ProgressBar::hidden()
    };
    let mut frames = Accumulation::default();
    let (image, step_size, spp_change, step_change, converged) = loop {
        // Double the samples until they change the image by at most half the tolerance.
        frames.extend_to(chunks, &at(dt), spp)?;
        let mut before = frames.image();
        let (spp_change, coarse) = loop {
            frames.extend_to(chunks, &at(dt), 2 * spp)?;
            bar.set_position(u64::from(2 * spp));
            let after = frames.image();
            let change = before.rmse(&after);
            spp *= 2;
            if change <= 0.5 * options.tolerance || spp >= options.max_spp {
                break (change, after);
            }
            before = after;
        };
        // Halve the step at the same samples.
        let finer = dt / 2.0;
        if chunks.resolve(&at(finer)).is_err() {
            break (coarse, dt, spp_change, None, false);
        }
        frames.extend_to(chunks, &at(finer), spp)?;
        let fine = frames.image();
        let step_change = coarse.rmse(&fine);
        let converged = spp_change <= options.tolerance && step_change <= options.tolerance;
        if step_change <= options.tolerance || spp >= options.max_spp {
            break (fine, finer, spp_change, Some(step_change), converged);
        }
        dt = finer;
    };
    bar.finish_and_clear();
    let reference = Reference {
        image: Some(image),
        step_size,
        spp,
        spp_change,
        step_change,
        tolerance: options.tolerance,
        converged,
        seconds: started.elapsed().as_secs_f64(),
        from_cache: false,
    };
    if speaks && !reference.converged {
        tracing::warn!(
            "the reference did not converge to {} within {} spp: doubling the samples changed it by {:.3e}, halving the step by {}",
            options.tolerance,
            options.max_spp,
            reference.spp_change,
            reference
                .step_change
                .map_or("(the step could not be halved)".into(), |c| format!(
                    "{c:.3e}"
                ))
        );
    }
    Ok(reference)
}

/// The frames of one setting rendered so far, as a session accumulates them: their mean (in
/// f64, from chunks of frames), and past a blue-noise mask cycle the cycles' weights
/// ([`CycleWeights`]), each chunk ending where the weights may want the mean.
#[derive(Default)]
struct Accumulation {
    settings: Option<RenderSettings>,
    frames: u32,
    size: (u32, u32),
    mean: Vec<[f64; 4]>,
    cycles: Option<CycleWeights>,
}

impl Accumulation {
    /// Renders the frames of `settings` up to `frames` (from the first where the settings
    /// changed).
    fn extend_to(
        &mut self,
        chunks: &mut dyn ChunkRenderer,
        settings: &RenderSettings,
        frames: u32,
    ) -> Result<(), RenderError> {
        if self.settings.as_ref() != Some(settings) {
            *self = Accumulation {
                settings: Some(settings.clone()),
                cycles: CycleWeights::of(settings),
                ..Accumulation::default()
            };
        }
        while self.frames < frames {
            if self
                .cycles
                .as_ref()
                .is_some_and(|c| c.wants_mean_at(self.frames))
            {
                let mean = self.mean_image();
                if let Some(cycles) = &mut self.cycles {
                    cycles.took_mean(self.frames, mean);
                }
            }
            let stop = (self.frames + 1..frames)
                .find(|&f| self.cycles.as_ref().is_some_and(|c| c.may_want_mean_at(f)))
                .unwrap_or(frames);
            let count = stop - self.frames;
            let chunk = chunks.render_frames(settings, self.frames, count, false)?;
            let total = f64::from(stop);
            let (w_old, w_new) = (f64::from(self.frames) / total, f64::from(count) / total);
            if self.mean.len() != chunk.pixels.len() {
                self.mean = vec![[0.0; 4]; chunk.pixels.len()];
            }
            for (m, p) in self.mean.iter_mut().zip(&chunk.pixels) {
                for c in 0..4 {
                    m[c] = w_old * m[c] + w_new * f64::from(p[c]);
                }
            }
            self.size = (chunk.width, chunk.height);
            self.frames = stop;
        }
        Ok(())
    }

    fn mean_image(&self) -> Image {
        Image {
            width: self.size.0,
            height: self.size.1,
            pixels: self.mean.iter().map(|p| p.map(|v| v as f32)).collect(),
        }
    }

    /// The image of the frames so far.
    fn image(&self) -> Image {
        let mean = self.mean_image();
        match &self.cycles {
            Some(cycles) => cycles.image(self.frames, mean),
            None => mean,
        }
    }
}

/// An order-free digest of a step's particles (every bit of each record, and the attributes'
/// names): the wrapping sum of the records' hashes, so that the parts the ranks read of a step
/// join to the whole step's digest ([`ParticlesDigest::joined`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParticlesDigest {
    /// Records digested.
    pub records: u64,
    /// The wrapping sum of their hashes.
    pub sum: u64,
}

impl ParticlesDigest {
    /// The digest of `step`'s records.
    pub fn of(step: &Step) -> ParticlesDigest {
        use rayon::prelude::*;
        let names = hash_of(
            &step
                .attributes
                .iter()
                .map(|a| a.name.as_str())
                .collect::<Vec<_>>(),
        );
        let sum = (0..step.len())
            .into_par_iter()
            .map(|i| {
                let mut h = std::hash::DefaultHasher::new();
                names.hash(&mut h);
                step.positions[i].to_array().map(f64::to_bits).hash(&mut h);
                for a in &step.attributes {
                    a.values[i].to_bits().hash(&mut h);
                }
                h.finish()
            })
            .reduce(|| 0, u64::wrapping_add);
        ParticlesDigest {
            records: step.len() as u64,
            sum,
        }
    }

    /// The digest of both digests' records together.
    pub fn joined(self, other: ParticlesDigest) -> ParticlesDigest {
        ParticlesDigest {
            records: self.records + other.records,
            sum: self.sum.wrapping_add(other.sum),
        }
    }
}

/// Where a reference is cached, under the key of everything it depends on.
pub struct ReferenceCache {
    path: Option<PathBuf>,
    key: String,
}

impl ReferenceCache {
    /// The cache file of `key` under `options.cache` (none where that is `None`).
    pub fn new(options: &ReferenceOptions, key: String) -> ReferenceCache {
        ReferenceCache {
            path: options
                .cache
                .as_ref()
                .map(|dir| dir.join(format!("{:016x}.json", hash_of(&key)))),
            key,
        }
    }

    /// The reference cached under the key, if any.
    pub fn load(&self) -> Option<Reference> {
        load(self.path.as_deref()?, &self.key)
    }

    /// Caches `reference` (a warning where it cannot).
    pub fn store(&self, reference: &Reference) {
        if let Some(path) = &self.path
            && let Err(e) = store(path, &self.key, reference)
        {
            tracing::warn!("the reference was not cached: {e}");
        }
    }
}

fn hash_of<T: Hash + ?Sized>(value: &T) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    value.hash(&mut h);
    h.finish()
}

/// Everything the reference depends on: the frame's parameters (camera, box, maps, tables),
/// the field, the particles' every bit, the convergence options. A cache file is used only
/// if its key is this string exactly.
pub fn cache_key(
    frame: &FrameParams,
    particles: ParticlesDigest,
    field: &FieldSettings,
    options: &ReferenceOptions,
) -> String {
    format!(
        "aarbf reference v2; particles {} {:016x}; field {field:?}; frame {frame:?}; tolerance {}; spp {}..{}",
        particles.records, particles.sum, options.tolerance, options.start_spp, options.max_spp
    )
}

fn load(path: &Path, key: &str) -> Option<Reference> {
    let text = std::fs::read_to_string(path).ok()?;
    let file: CacheFile = serde_json::from_str(&text).ok()?;
    if file.key != key {
        return None;
    }
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(file.pixels)
        .ok()?;
    let floats: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if floats.len() != 4 * file.width as usize * file.height as usize {
        return None;
    }
    let pixels = floats
        .chunks_exact(4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .collect();
    Some(Reference {
        image: Some(Image {
            width: file.width,
            height: file.height,
            pixels,
        }),
        from_cache: true,
        ..file.reference
    })
}

fn store(
    path: &Path,
    key: &str,
    reference: &Reference,
) -> Result<(), crate::io::output::OutputError> {
    let image = reference.image();
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| p.iter().flat_map(|v| v.to_le_bytes()))
        .collect();
    let file = CacheFile {
        key: key.to_owned(),
        width: image.width,
        height: image.height,
        pixels: base64::engine::general_purpose::STANDARD.encode(bytes),
        reference: reference.clone(),
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|error| crate::io::output::OutputError::Io {
            path: dir.display().to_string(),
            error,
        })?;
    }
    let text = serde_json::to_string(&file).expect("a reference serialises");
    crate::io::output::write_atomically(path, true, |tmp| std::fs::write(tmp, &text))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{Part, slice_step};
    use crate::scene::synth::Generator;

    #[test]
    fn the_parts_digests_join_to_the_whole_step_s() {
        let step = Generator::DambreakDemo.generate(3_011, 1, 5).remove(0);
        let whole = ParticlesDigest::of(&step);
        assert_eq!(whole.records, 3_011);
        for ranks in (1..=9).chain([16, 4_000]) {
            let joined = (0..ranks)
                .map(|r| ParticlesDigest::of(&slice_step(&step, Part::new(r, ranks))))
                .fold(ParticlesDigest::default(), ParticlesDigest::joined);
            assert_eq!(joined, whole, "{ranks} parts");
        }
        // The order of the records does not matter; every bit of each, and the names, do.
        let mut reversed = step.clone();
        reversed.positions.reverse();
        for a in &mut reversed.attributes {
            a.values.reverse();
        }
        assert_eq!(ParticlesDigest::of(&reversed), whole);
        let mut nudged = step.clone();
        let last = nudged.attributes.len() - 1;
        let v = &mut nudged.attributes[last].values[1_234];
        *v = f64::from_bits(v.to_bits() ^ 1);
        assert_ne!(ParticlesDigest::of(&nudged), whole);
        let mut moved = step.clone();
        moved.positions[7].z = f64::from_bits(moved.positions[7].z.to_bits() ^ 1);
        assert_ne!(ParticlesDigest::of(&moved), whole);
        let mut renamed = step.clone();
        renamed.attributes[0].name.push('_');
        assert_ne!(ParticlesDigest::of(&renamed), whole);
        // Two records swapping one attribute's values are other particles.
        let mut swapped = step.clone();
        swapped.attributes[last].values.swap(10, 2_000);
        assert_ne!(ParticlesDigest::of(&swapped), whole);
    }

    /// The search's frames, accumulated from chunks, make the image a session's own
    /// accumulation makes, past a mask cycle (where the cycles' weights combine them) too.
    #[test]
    fn chunks_accumulate_to_the_session_s_image() {
        let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(2_003, 1, 5));
        let field = FieldSettings::new(Some("velocity"), 0.04 * series.bounds().diagonal());
        let settings = RenderSettings {
            width: 23,
            height: 17,
            integrator: Integrator::Marching,
            ..RenderSettings::default()
        };
        let cycle = crate::noise::BlueNoiseMask::builtin().depth;
        let session = || {
            let mut session = RenderSession::new(Box::new(CpuBackend::new()), &series);
            session.set_precision(Precision::F64);
            session
                .show(&series, 0, &field, ClusterSize::new(8).unwrap())
                .unwrap();
            session
        };
        let mut whole = session();
        let mut chunked = session();
        let mut frames = Accumulation::default();
        for total in [
            3,
            cycle / 2,
            cycle + cycle / 4 + 1,
            cycle + cycle / 2 + 3,
            2 * cycle + 5,
        ] {
            whole
                .accumulate(&settings, total - whole.frames_of(&settings))
                .unwrap();
            frames
                .extend_to(&mut SessionChunks::new(&mut chunked), &settings, total)
                .unwrap();
            let (want, have) = (whole.image().unwrap(), frames.image());
            let diff = want
                .pixels
                .iter()
                .zip(&have.pixels)
                .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
                .fold(0.0f32, f32::max);
            assert!(diff <= 1e-5, "{total} frames: max |difference| {diff:e}");
        }
        // Other settings start again.
        let finer = RenderSettings {
            step_size: Some(0.01),
            ..settings.clone()
        };
        frames
            .extend_to(&mut SessionChunks::new(&mut chunked), &finer, 2)
            .unwrap();
        assert_eq!(frames.frames, 2);
    }
}
