//! The converged reference every error is measured against (`aarbf render --reference`,
//! `aarbf bench accuracy`, the error-estimate tests): the CPU backend in f64, with a march step
//! and a sample count fine enough that doubling the samples and halving the step each change
//! the image by less than a stated tolerance (RMSE over linear RGB). Both changes are checked
//! and reported, and the image is cached on disk per scene (keyed by the frame's every
//! parameter and a hash of the step's particles), so studies and tests reuse it.
//!
//! The samples are doubled until their change is within half the tolerance first, so the
//! step check that follows compares images whose noise cannot by itself exceed it.

use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::time::Instant;

use base64::Engine as _;
use serde::{Deserialize, Serialize};

use super::RenderError;
use super::session::RenderSession;
use super::settings::RenderSettings;
use crate::accel::ClusterSize;
use crate::backend::Precision;
use crate::backend::cpu::CpuBackend;
use crate::field::FieldSettings;
use crate::scene::TimeSeries;
use crate::values::{Image, Integrator, NoiseKind, Step};

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
/// all of them converge to) for step `step` of `series` under `field`.
pub fn converged_reference(
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: ClusterSize,
    settings: &RenderSettings,
    options: &ReferenceOptions,
) -> Result<Reference, RenderError> {
    if !(options.tolerance.is_finite() && options.tolerance > 0.0) {
        return Err(RenderError::Settings(format!(
            "reference tolerance {} must be a positive number",
            options.tolerance
        )));
    }
    if options.start_spp == 0 || options.start_spp > options.max_spp {
        return Err(RenderError::Settings(format!(
            "reference samples: start {} must lie in 1..={}",
            options.start_spp, options.max_spp
        )));
    }
    let started = Instant::now();
    let mut session = RenderSession::new(Box::new(CpuBackend::new()), series);
    session.set_precision(Precision::F64);
    session.show(series, step, field, cluster)?;
    let base = reference_settings(settings);
    let start_dt = session.resolve(&base)?.step_size / 2.0;
    let key = cache_key(&session, &base, &*series.step(step)?, field, options)?;
    let cache_path = options
        .cache
        .as_ref()
        .map(|dir| dir.join(format!("{:016x}.json", hash_of(&key))));
    if let Some(found) = cache_path.as_deref().and_then(|p| load(p, &key)) {
        tracing::info!("reference from the cache");
        return Ok(found);
    }

    let at = |dt: f64| RenderSettings {
        step_size: Some(dt),
        ..base.clone()
    };
    let mut dt = start_dt;
    let mut spp = options.start_spp;
    let bar = crate::progress::bar(u64::from(options.max_spp), "reference");
    let (image, step_size, spp_change, step_change, converged) = loop {
        // Double the samples until they change the image by at most half the tolerance.
        session.accumulate(&at(dt), spp.saturating_sub(session.frames_of(&at(dt))))?;
        let mut before = session.image()?;
        let (spp_change, coarse) = loop {
            session.accumulate(&at(dt), spp)?;
            bar.set_position(u64::from(2 * spp));
            let after = session.image()?;
            let change = before.rmse(&after);
            spp *= 2;
            if change <= 0.5 * options.tolerance || spp >= options.max_spp {
                break (change, after);
            }
            before = after;
        };
        // Halve the step at the same samples.
        let finer = dt / 2.0;
        if session.resolve(&at(finer)).is_err() {
            break (coarse, dt, spp_change, None, false);
        }
        session.accumulate(&at(finer), spp)?;
        let fine = session.image()?;
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
    if !reference.converged {
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
    if let Some(path) = &cache_path
        && let Err(e) = store(path, &key, &reference)
    {
        tracing::warn!("the reference was not cached: {e}");
    }
    Ok(reference)
}

fn hash_of<T: Hash + ?Sized>(value: &T) -> u64 {
    let mut h = std::hash::DefaultHasher::new();
    value.hash(&mut h);
    h.finish()
}

/// Everything the reference depends on: the frame's parameters (camera, box, maps, tables),
/// the field, the particles' every bit, the convergence options. A cache file is used only
/// if its key is this string exactly.
fn cache_key(
    session: &RenderSession,
    settings: &RenderSettings,
    step: &Step,
    field: &FieldSettings,
    options: &ReferenceOptions,
) -> Result<String, RenderError> {
    let params = session.frame_params(settings, 0)?;
    let mut h = std::hash::DefaultHasher::new();
    step.positions.len().hash(&mut h);
    for p in &step.positions {
        p.to_array().map(f64::to_bits).hash(&mut h);
    }
    for a in &step.attributes {
        a.name.hash(&mut h);
        for v in &a.values {
            v.to_bits().hash(&mut h);
        }
    }
    Ok(format!(
        "aarbf reference v1; particles {:016x}; field {field:?}; frame {params:?}; tolerance {}; spp {}..{}",
        h.finish(),
        options.tolerance,
        options.start_spp,
        options.max_spp
    ))
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
