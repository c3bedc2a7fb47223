//! Speed against accuracy: every knob's cost in time and in error against the converged
//! reference ([`crate::render::converged`]), the Pareto front of the two, how far the default
//! settings sit from it, and what `--target-error` costs against it.
//!
//! For each data set and backend, one camera (the default view) and the error images' size
//! (`--noise-size`), the study sweeps the samples per pixel (`--spp`) of configurations that
//! each change one knob from the defaults: the march step (`--step-factors` times the default),
//! white instead of blue noise, the other end of the cluster sizes (16 particles per cluster,
//! or 1 where the data's default is 16), and the other stochastic
//! single-scattering integrator (delta tracking for marching and the reverse; emission–absorption
//! converges to another image, so it is compared only with itself), and the other methods: the
//! voxel-grid baseline at each of `--voxel-grids` (cells along its longest side; marched with
//! the same integrators; its time includes voxelising, as a step change would), and, where the
//! study's integrator is emission–absorption (the only one it renders), Knoll et al.'s
//! splatter at each of `--splat-ks` (hits a slab). Each configuration is
//! rendered `--seeds` times; a row holds one value per seed: the time to accumulate the samples
//! (ms, wall clock, the image read back outside it), and the image's RMSE over linear RGB, its
//! RMSE after a 1-pixel blur (what an observer sees of blue noise) and its mean FLIP against
//! the reference. Then `--target-error` in RMSE, at the errors the defaults reached (up to
//! [`MAX_TARGET_SPP`]): its time (calibration included), its true error and its estimate.

use std::time::Instant;

use super::{
    Ctx, Dataset, Description, Device, Measurement, Options, StudyError, device_of, value,
};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::render::converged::{Reference, ReferenceOptions, converged_reference};
use crate::render::target::{ErrorMetric, Target, render_to_target};
use crate::render::{RenderSession, RenderSettings};
use crate::values::{Image, Integrator, NoiseKind};

mod summary;

pub use summary::summarise;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "Speed vs accuracy: error against time, the Pareto front",
    paper: "The paper trades image quality for speed with the march step, the samples per pixel, \
            the cluster size and blue noise, but reports only times; this study measures each \
            knob's error against a converged f64 reference beside its time, draws the front of \
            the best trades, and checks the defaults and --target-error against it.",
    settings: &[
        "configuration",
        "step_factor",
        "step_size",
        "spp",
        "k",
        "noise",
        "integrator",
        "method",
        "width",
        "height",
        "target_error",
        "reference_spp",
        "reference_step",
    ],
};

/// `--target-error` is asked for the defaults' errors up to this many spp: one blue-noise mask
/// cycle, where what a target costs beside the front is decided (beyond, its two sequences
/// lose nothing); past it, a target takes minutes on lavapipe and measures nothing new.
const MAX_TARGET_SPP: u32 = 64;

/// One configuration: the defaults with one knob changed.
#[derive(Clone, Debug)]
struct Config {
    name: String,
    step_factor: f64,
    k: u32,
    noise: NoiseKind,
    integrator: Integrator,
    /// `RenderSettings::voxel_grid` and `splat_k`: the method (neither: the RBFs).
    voxel_grid: Option<usize>,
    splat_k: Option<usize>,
}

impl Config {
    fn method(&self) -> String {
        match (self.voxel_grid, self.splat_k) {
            (Some(n), _) => format!("voxel {n}"),
            (None, Some(k)) => format!("splat {k}"),
            (None, None) => "rbf".into(),
        }
    }
}

/// The configurations, around the defaults for data whose default cluster size is `k`
/// ([`ClusterSize::for_overlap`]); the cluster-size variant takes the other end of 1..=16.
fn configs(o: &Options, k: u32) -> Vec<Config> {
    let base = Config {
        name: String::new(),
        step_factor: 1.0,
        k,
        noise: NoiseKind::Stbn,
        integrator: o.integrator,
        voxel_grid: None,
        splat_k: None,
    };
    let mut out: Vec<Config> = o
        .step_factors
        .iter()
        .map(|&f| Config {
            name: if f == 1.0 {
                "defaults".into()
            } else {
                format!("step x{f}")
            },
            step_factor: f,
            ..base.clone()
        })
        .collect();
    out.push(Config {
        name: "white noise".into(),
        noise: NoiseKind::White,
        ..base.clone()
    });
    let other_k = if k == 16 { 1 } else { 16 };
    out.push(Config {
        name: format!("K={other_k}"),
        k: other_k,
        ..base.clone()
    });
    let other = match o.integrator {
        Integrator::Marching => Some(Integrator::Delta),
        Integrator::Delta | Integrator::SsReference => Some(Integrator::Marching),
        Integrator::Ea => None,
    };
    if let Some(integrator) = other {
        out.push(Config {
            name: format!("{integrator:?}").to_lowercase(),
            integrator,
            ..base.clone()
        });
    }
    for &n in &o.voxel_grids {
        out.push(Config {
            name: format!("voxel {n}"),
            voxel_grid: Some(n),
            ..base.clone()
        });
    }
    if o.integrator == Integrator::Ea {
        for &k in &o.splat_ks {
            out.push(Config {
                name: format!("splat {k}"),
                splat_k: Some(k),
                ..base.clone()
            });
        }
    }
    out
}

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let mut spps = o.spps.clone();
    spps.sort_unstable();
    spps.dedup();
    // As many configurations for every data set (their K differs).
    let config_count = configs(o, 1).len();
    let bar = ctx.bar(
        ctx.data.len() * (1 + ctx.backends.len() * (config_count + 1)),
        "accuracy",
    );
    let base = RenderSettings {
        width: o.noise_image.0,
        height: o.noise_image.1,
        integrator: o.integrator,
        ..RenderSettings::default()
    };
    let k1 = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        let overlap = crate::render::auto::mean_overlap(&ds.series, &field)?;
        let configs = configs(o, ClusterSize::for_overlap(overlap).get() as u32);
        let reference = reference(o, &ds, &field, k1, &base)?;
        let truth = reference.image();
        let truth_blurred = truth.blurred(1.0);
        bar.inc(1);
        for &kind in ctx.backends {
            let mut session = super::session(kind, &ds)?;
            let device = device_of(&session);
            session.show(&ds.series, ds.step, &field, k1)?;
            let sweep = Sweep {
                o,
                ds: &ds,
                device,
                spps: &spps,
                base: &base,
                dt0: session.resolve(&base)?.step_size,
                reference: &reference,
                truth,
                truth_blurred: &truth_blurred,
            };
            let mut defaults_errors = Vec::new();
            for c in &configs {
                let cluster = ClusterSize::new(c.k).map_err(StudyError::Invalid)?;
                session.show(&ds.series, ds.step, &field, cluster)?;
                let errors = sweep.config(ctx, &mut session, c)?;
                if c.name == "defaults" {
                    defaults_errors.extend(errors);
                }
                bar.inc(1);
            }
            session.show(&ds.series, ds.step, &field, k1)?;
            sweep.targets(ctx, &mut session, &configs[0], &defaults_errors)?;
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// The converged reference of `ds` under `base`, found (or read from the cache) and logged.
fn reference(
    o: &Options,
    ds: &Dataset,
    field: &FieldSettings,
    cluster: ClusterSize,
    base: &RenderSettings,
) -> Result<Reference, StudyError> {
    let reference = converged_reference(
        &ds.series,
        ds.step,
        field,
        cluster,
        base,
        &ReferenceOptions {
            tolerance: o.reference_tolerance,
            cache: Some(o.out.join("references")),
            ..ReferenceOptions::default()
        },
    )?;
    tracing::info!(
        "accuracy: reference of {} at step {:.3e}, {} spp (changes: samples {:.2e}, step {:?}; {:.1} s{})",
        ds.name,
        reference.step_size,
        reference.spp,
        reference.spp_change,
        reference.step_change,
        reference.seconds,
        if reference.from_cache { ", cached" } else { "" }
    );
    Ok(reference)
}

/// What every configuration on one data set and backend is measured with and against.
struct Sweep<'a> {
    o: &'a Options,
    ds: &'a Dataset,
    device: Device,
    /// The samples per pixel, ascending, each once.
    spps: &'a [u32],
    base: &'a RenderSettings,
    /// The march step the defaults resolve to.
    dt0: f64,
    reference: &'a Reference,
    truth: &'a Image,
    truth_blurred: &'a Image,
}

impl Sweep<'_> {
    /// A row of configuration `c` at march step `dt` and `spp` (and `target`, of
    /// `--target-error`).
    fn measurement(&self, c: &Config, dt: f64, spp: u32, target: Option<f64>) -> Measurement {
        let (o, reference) = (self.o, self.reference);
        let settings = vec![
            ("configuration", c.name.clone()),
            ("step_factor", value(dt / self.dt0)),
            ("step_size", value(dt)),
            ("spp", spp.to_string()),
            ("k", c.k.to_string()),
            ("noise", c.noise.name().into()),
            ("integrator", format!("{:?}", c.integrator).to_lowercase()),
            ("method", c.method()),
            ("width", o.noise_image.0.to_string()),
            ("height", o.noise_image.1.to_string()),
            ("target_error", target.map(value).unwrap_or_default()),
            ("reference_spp", reference.spp.to_string()),
            ("reference_step", value(reference.step_size)),
        ];
        Measurement::new(self.device.clone(), self.ds, settings).variant(c.name.clone())
    }

    /// Renders configuration `c` (its cluster size shown) `--seeds` times through the spp
    /// sweep and records its time and errors at each spp; returns the median RMSE at each.
    fn config(
        &self,
        ctx: &mut Ctx<'_>,
        session: &mut RenderSession,
        c: &Config,
    ) -> Result<Vec<f64>, StudyError> {
        let dt = self.dt0 * c.step_factor;
        // [time, rmse, rmse_blurred, flip] per seed, at each spp.
        let mut m = vec![[const { Vec::new() }; 4]; self.spps.len()];
        // The warm-up: lavapipe compiles this configuration's pipeline now.
        let warm = RenderSettings {
            step_size: Some(dt),
            integrator: c.integrator,
            noise: c.noise,
            voxel_grid: c.voxel_grid,
            splat_k: c.splat_k,
            seed: u32::MAX,
            ..self.base.clone()
        };
        session.accumulate(&warm, 1)?;
        for seed in 0..self.o.seeds {
            let settings = RenderSettings {
                seed,
                ..warm.clone()
            };
            let (mut done, mut elapsed) = (0, 0.0);
            for (s, &spp) in self.spps.iter().enumerate() {
                let t = Instant::now();
                session.accumulate(&settings, spp - done)?;
                elapsed += t.elapsed().as_secs_f64();
                done = spp;
                let image = session.image()?;
                m[s][0].push(1e3 * elapsed);
                m[s][1].push(image.rmse(self.truth));
                m[s][2].push(image.blurred(1.0).rmse(self.truth_blurred));
                m[s][3].push(image.flip(self.truth));
            }
        }
        let mut medians = Vec::new();
        for (&spp, [time, rmse, blurred, flip]) in self.spps.iter().zip(m) {
            medians.push(super::record::median(&rmse));
            let row = self.measurement(c, dt, spp, None);
            ctx.record(&row, "time", "ms", time)?;
            ctx.record(&row, "rmse", "linear rgb", rmse)?;
            ctx.record(&row, "rmse_blurred", "linear rgb", blurred)?;
            ctx.record(&row, "flip", "mean flip", flip)?;
        }
        Ok(medians)
    }

    /// `--target-error` (with `defaults`' settings, shown at K = 1) at the errors the defaults
    /// reached beyond their fewest samples: "as good as the defaults at N spp", which the
    /// front may reach more cheaply.
    fn targets(
        &self,
        ctx: &mut Ctx<'_>,
        session: &mut RenderSession,
        defaults: &Config,
        defaults_errors: &[f64],
    ) -> Result<(), StudyError> {
        let target_config = Config {
            name: "target-error".into(),
            ..defaults.clone()
        };
        let targets: Vec<f64> = defaults_errors
            .iter()
            .zip(self.spps)
            .skip(1)
            .filter(|&(_, &spp)| spp <= MAX_TARGET_SPP)
            .map(|(&e, _)| e)
            .collect();
        let max_spp = 4 * self.spps.last().copied().unwrap_or(1).max(16);
        for e in targets {
            let (mut time, mut truth_error, mut estimate, mut spp, mut dt) =
                (Vec::new(), Vec::new(), Vec::new(), 0, self.dt0);
            for seed in 0..self.o.seeds {
                let settings = RenderSettings {
                    seed,
                    ..self.base.clone()
                };
                let done = render_to_target(
                    session,
                    &settings,
                    &Target {
                        error: Some(e),
                        time_budget: None,
                        metric: ErrorMetric::Rmse,
                        max_spp,
                    },
                )?;
                time.push(done.elapsed.as_secs_f64() * 1e3);
                truth_error.push(done.image.rmse(self.truth));
                estimate.push(done.estimate);
                (spp, dt) = (done.spp, done.step_size);
            }
            let row = self.measurement(&target_config, dt, spp, Some(e));
            ctx.record(&row, "time", "ms", time)?;
            ctx.record(&row, "rmse", "linear rgb", truth_error)?;
            ctx.record(&row, "estimate", "linear rgb", estimate)?;
        }
        Ok(())
    }
}
