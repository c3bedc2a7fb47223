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

use super::plot::{Figure, Panel, Scale, Series};
use super::{Ctx, Description, Options, Row, StudyError, device_of, value};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::render::RenderSettings;
use crate::render::converged::{ReferenceOptions, converged_reference};
use crate::render::target::{ErrorMetric, Target, render_to_target};
use crate::values::{Integrator, NoiseKind};

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
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        let overlap = crate::render::auto::mean_overlap(&ds.series, &field)?;
        let configs = configs(o, ClusterSize::for_overlap(overlap).get() as u32);
        let base = RenderSettings {
            width: o.noise_image.0,
            height: o.noise_image.1,
            integrator: o.integrator,
            ..RenderSettings::default()
        };
        let k1 = ClusterSize::new(1).map_err(StudyError::Invalid)?;
        let reference = converged_reference(
            &ds.series,
            ds.step,
            &field,
            k1,
            &base,
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
        let truth = reference.image();
        let truth_blurred = truth.blurred(1.0);
        bar.inc(1);
        for &kind in ctx.backends {
            let mut session = super::session(kind, &ds)?;
            let device = device_of(&session);
            session.show(&ds.series, ds.step, &field, k1)?;
            let dt0 = session.resolve(&base)?.step_size;
            let row =
                |c: &Config, dt: f64, spp: u32, target: Option<f64>, metric, unit, values| Row {
                    device: device.clone(),
                    variant: c.name.clone(),
                    data: ds.name.clone(),
                    step: ds.step,
                    n: ds.n,
                    settings: vec![
                        ("configuration", c.name.clone()),
                        ("step_factor", value(dt / dt0)),
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
                    ],
                    metric,
                    unit,
                    values,
                };
            let mut defaults_errors = Vec::new();
            for c in &configs {
                let cluster = ClusterSize::new(c.k).map_err(StudyError::Invalid)?;
                session.show(&ds.series, ds.step, &field, cluster)?;
                let dt = dt0 * c.step_factor;
                // [time, rmse, rmse_blurred, flip] per seed, at each spp.
                let mut m = vec![[const { Vec::new() }; 4]; spps.len()];
                // The warm-up: lavapipe compiles this configuration's pipeline now.
                let warm = RenderSettings {
                    step_size: Some(dt),
                    integrator: c.integrator,
                    noise: c.noise,
                    voxel_grid: c.voxel_grid,
                    splat_k: c.splat_k,
                    seed: u32::MAX,
                    ..base.clone()
                };
                session.accumulate(&warm, 1)?;
                for seed in 0..o.seeds {
                    let settings = RenderSettings {
                        seed,
                        ..warm.clone()
                    };
                    let (mut done, mut elapsed) = (0, 0.0);
                    for (s, &spp) in spps.iter().enumerate() {
                        let t = Instant::now();
                        session.accumulate(&settings, spp - done)?;
                        elapsed += t.elapsed().as_secs_f64();
                        done = spp;
                        let image = session.image()?;
                        m[s][0].push(1e3 * elapsed);
                        m[s][1].push(image.rmse(truth));
                        m[s][2].push(image.blurred(1.0).rmse(&truth_blurred));
                        m[s][3].push(image.flip(truth));
                    }
                }
                for (&spp, [time, rmse, blurred, flip]) in spps.iter().zip(m) {
                    if c.name == "defaults" {
                        defaults_errors.push(super::record::median(&rmse));
                    }
                    let r = |metric, unit, values| row(c, dt, spp, None, metric, unit, values);
                    ctx.recorder.record(r("time", "ms", time))?;
                    ctx.recorder.record(r("rmse", "linear rgb", rmse))?;
                    ctx.recorder
                        .record(r("rmse_blurred", "linear rgb", blurred))?;
                    ctx.recorder.record(r("flip", "mean flip", flip))?;
                }
                bar.inc(1);
            }
            // --target-error at the errors the defaults reached beyond their fewest samples:
            // "as good as the defaults at N spp", which the front may reach more cheaply.
            let target_config = Config {
                name: "target-error".into(),
                ..configs[0].clone()
            };
            session.show(&ds.series, ds.step, &field, k1)?;
            let targets: Vec<f64> = defaults_errors
                .iter()
                .zip(&spps)
                .skip(1)
                .filter(|&(_, &spp)| spp <= MAX_TARGET_SPP)
                .map(|(&e, _)| e)
                .collect();
            let max_spp = 4 * spps.last().copied().unwrap_or(1).max(16);
            for e in targets {
                let (mut time, mut truth_error, mut estimate, mut spp, mut dt) =
                    (Vec::new(), Vec::new(), Vec::new(), 0, dt0);
                for seed in 0..o.seeds {
                    let settings = RenderSettings {
                        seed,
                        ..base.clone()
                    };
                    let done = render_to_target(
                        &mut session,
                        &settings,
                        &Target {
                            error: Some(e),
                            time_budget: None,
                            metric: ErrorMetric::Rmse,
                            max_spp,
                        },
                    )?;
                    time.push(done.elapsed.as_secs_f64() * 1e3);
                    truth_error.push(done.image.rmse(truth));
                    estimate.push(done.estimate);
                    (spp, dt) = (done.spp, done.step_size);
                }
                let r = |metric, unit, values| {
                    row(&target_config, dt, spp, Some(e), metric, unit, values)
                };
                ctx.recorder.record(r("time", "ms", time))?;
                ctx.recorder.record(r("rmse", "linear rgb", truth_error))?;
                ctx.recorder.record(r("estimate", "linear rgb", estimate))?;
            }
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// A measured point: (time ms, error), from a configuration at one spp.
#[derive(Clone, Debug)]
struct Point<'a> {
    time: f64,
    error: f64,
    time_row: &'a Row,
}

/// The (time, rmse) points of `rows` for one device and data set, configurations only.
fn points<'a>(rows: &'a [Row], like: &Row) -> Vec<Point<'a>> {
    rows.iter()
        .filter(|r| {
            r.metric == "time"
                && r.variant != "target-error"
                && r.device == like.device
                && r.data == like.data
        })
        .filter_map(|t| {
            let e = rows.iter().find(|r| {
                r.metric == "rmse"
                    && r.device == t.device
                    && r.data == t.data
                    && r.variant == t.variant
                    && r.setting("spp") == t.setting("spp")
                    && r.setting("step_size") == t.setting("step_size")
            })?;
            Some(Point {
                time: t.median(),
                error: e.median(),
                time_row: t,
            })
        })
        .collect()
}

/// The Pareto front: the points no other point beats in both time and error, by time.
fn front<'a>(points: &[Point<'a>]) -> Vec<Point<'a>> {
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.time.total_cmp(&b.time).then(a.error.total_cmp(&b.error)));
    let mut out: Vec<Point<'a>> = Vec::new();
    for p in sorted {
        if out.last().is_none_or(|last| p.error < last.error) {
            out.push(p);
        }
    }
    out
}

/// The least time on `front` that reaches error `e` or better.
fn front_time_at(front: &[Point<'_>], e: f64) -> Option<f64> {
    cheapest_at(front, e).map(|p| p.time)
}

/// The point of least time on `front` that reaches error `e` or better.
fn cheapest_at<'p, 'a>(front: &'p [Point<'a>], e: f64) -> Option<&'p Point<'a>> {
    front
        .iter()
        .filter(|p| p.error <= e)
        .min_by(|a, b| a.time.total_cmp(&b.time))
}

/// Whether a point renders the RBFs (rows written before the study had methods did).
fn is_rbf(p: &Point<'_>) -> bool {
    p.time_row.setting("method").is_none_or(|m| m == "rbf")
}

/// Where every method's front is cheaper than the RBF settings' own at error `e`, what
/// reaches it there and `time` against it ("; every method's front: voxel 512 at 64 spp,
/// 2429.2 ms (3.51x of it)"); otherwise nothing.
fn other_method_note(all: &[Point<'_>], rbf: &[Point<'_>], e: f64, time: f64) -> String {
    match (cheapest_at(all, e), front_time_at(rbf, e)) {
        (Some(p), Some(t)) if !is_rbf(p) && p.time < t => format!(
            "; every method's front: {} at {} spp, {:.1} ms ({:.2}x of it)",
            p.time_row.variant,
            p.time_row.setting("spp").unwrap_or("?"),
            p.time,
            time / p.time
        ),
        _ => String::new(),
    }
}

/// `--target-error`'s renders of one device and data set: (time, true error, estimate) rows.
fn targeted<'a>(rows: &'a [Row], like: &Row) -> Vec<(&'a Row, &'a Row, Option<&'a Row>)> {
    rows.iter()
        .filter(|t| {
            t.variant == "target-error"
                && t.metric == "time"
                && t.device == like.device
                && t.data == like.data
        })
        .filter_map(|t| {
            let find = |metric: &str| {
                rows.iter().find(|r| {
                    r.metric == metric
                        && r.variant == t.variant
                        && r.device == t.device
                        && r.data == t.data
                        && r.setting("target_error") == t.setting("target_error")
                })
            };
            Some((t, find("rmse")?, find("estimate")))
        })
        .collect()
}

/// Each (device, data set) once, in the rows' order.
fn groups(rows: &[Row]) -> Vec<&Row> {
    let mut out: Vec<&Row> = Vec::new();
    for r in rows {
        if !out.iter().any(|o| o.device == r.device && o.data == r.data) {
            out.push(r);
        }
    }
    out
}

pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    let mut panels = Vec::new();
    for g in groups(rows) {
        let mut series = Vec::new();
        let pts = points(rows, g);
        // The defaults and --target-error choose among the RBF settings: they are held to
        // those settings' front, and every method's is stated beside it.
        let rbf_points: Vec<Point<'_>> = pts.iter().filter(|p| is_rbf(p)).cloned().collect();
        let rbf_front = front(&rbf_points);
        let front = front(&pts);
        notes.push(format!(
            "{} on {}: the Pareto front (time to the image, RMSE over linear RGB): {}",
            g.device.backend,
            g.data,
            front
                .iter()
                .map(|p| format!(
                    "{} at {} spp: {:.1} ms, {}",
                    p.time_row.variant,
                    p.time_row.setting("spp").unwrap_or("?"),
                    p.time,
                    super::report::number(p.error)
                ))
                .collect::<Vec<_>>()
                .join("; ")
        ));
        // The defaults against the RBF front at equal error (and every method's).
        let defaults: Vec<&Point<'_>> = pts
            .iter()
            .filter(|p| p.time_row.variant == "defaults")
            .collect();
        let ratios_against = |front: &[Point<'_>]| -> Vec<f64> {
            defaults
                .iter()
                .filter_map(|p| Some(p.time / front_time_at(front, p.error)?))
                .collect()
        };
        let (ratios, all_ratios) = (ratios_against(&rbf_front), ratios_against(&front));
        let list = |r: &[f64]| {
            r.iter()
                .map(|r| format!("{r:.2}x"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !ratios.is_empty() {
            notes.push(format!(
                "{} on {}: the defaults take {} the RBF front's time at their error (worst {:.2}x; goal: within 1.5x){}",
                g.device.backend,
                g.data,
                list(&ratios),
                ratios.iter().copied().fold(0.0, f64::max),
                if all_ratios == ratios {
                    String::new()
                } else {
                    format!("; {} every method's", list(&all_ratios))
                }
            ));
        }
        // --target-error: its cost against the front, and its estimate against the truth.
        for (t, truth, estimate) in targeted(rows, g) {
            let Some(estimate) = estimate else {
                continue;
            };
            let e: f64 = t
                .setting("target_error")
                .and_then(|v| v.parse().ok())
                .unwrap_or(f64::NAN);
            notes.push(format!(
                "{} on {}: --target-error {}: {:.1} ms at step x{} and {} spp; true error {} (estimate {}, estimate / true {:.2}); the RBF front's cheapest at error <= target: {} ({}){}",
                g.device.backend,
                g.data,
                super::report::number(e),
                t.median(),
                t.setting("step_factor").and_then(|v| v.parse::<f64>().ok()).map_or("?".into(), |f| format!("{f:.3}")),
                t.setting("spp").unwrap_or("?"),
                super::report::number(truth.median()),
                super::report::number(estimate.median()),
                estimate.median() / truth.median(),
                front_time_at(&rbf_front, e).map_or("none".into(), |f| format!("{f:.1} ms")),
                front_time_at(&rbf_front, e).map_or("-".into(), |f| format!("{:.2}x of it; goal 1.5x", t.median() / f)),
                other_method_note(&front, &rbf_front, e, t.median()),
            ));
        }
        // One line per configuration through its spp sweep, and the front.
        let mut by: std::collections::BTreeMap<String, Vec<(f64, f64, f64, f64)>> =
            Default::default();
        for p in &pts {
            by.entry(p.time_row.variant.clone())
                .or_default()
                .push((p.time, p.error, p.error, p.error));
        }
        for (name, mut points) in by {
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            series.push(Series {
                label: name,
                points,
                dashed: false,
            });
        }
        series.push(Series {
            label: "front".into(),
            points: front
                .iter()
                .map(|p| (p.time, p.error, p.error, p.error))
                .collect(),
            dashed: true,
        });
        // --target-error's renders: their time and true error.
        let targeted: Vec<(f64, f64, f64, f64)> = targeted(rows, g)
            .iter()
            .map(|(t, e, _)| (t.median(), e.median(), e.min(), e.max()))
            .collect();
        if !targeted.is_empty() {
            series.push(Series {
                label: "--target-error".into(),
                points: targeted,
                dashed: true,
            });
        }
        panels.push(Panel::Lines {
            title: format!("{} on {}", g.device.backend, g.data),
            x_label: "time to the image (ms)".into(),
            y_label: "RMSE (linear RGB)".into(),
            x_scale: Scale::Log10,
            y_scale: Scale::Log10,
            series,
        });
    }
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels,
        caption: vec![
            format!(
                "RMSE against a converged f64 reference ({}x{} px); a line per configuration (one knob of the defaults changed) over {:?} spp; median over the seeds.",
                options.noise_image.0, options.noise_image.1, options.spps
            ),
            "Dashed: the Pareto front (nothing else is both faster and more accurate) and --target-error's renders (time, true error)."
                .into(),
            format!(
                "Reference: CPU f64, samples doubled and step halved until each changes the image by at most {} RMSE.",
                options.reference_tolerance
            ),
        ],
    };
    (notes, figure)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::record::Device;

    /// A (time, rmse) pair of rows for a configuration at one spp.
    fn measured(variant: &str, method: &str, spp: u32, time: f64, rmse: f64) -> [Row; 2] {
        let row = |metric, values: Vec<f64>| Row {
            device: Device {
                backend: "ash".into(),
                adapter: "a".into(),
                driver: "d".into(),
                timer: "device timestamps",
            },
            variant: variant.into(),
            data: "dambreak-demo".into(),
            step: 0,
            n: 1,
            settings: vec![
                ("spp", spp.to_string()),
                ("step_size", "0.01".into()),
                ("method", method.into()),
            ],
            metric,
            unit: "",
            values,
        };
        [row("time", vec![time]), row("rmse", vec![rmse])]
    }

    #[test]
    fn the_defaults_are_held_to_the_rbf_front_and_every_method_is_stated_beside_it() {
        let rows: Vec<Row> = [
            measured("defaults", "rbf", 4, 10.0, 0.02),
            measured("defaults", "rbf", 64, 100.0, 0.001),
            measured("step x2", "rbf", 64, 60.0, 0.0015),
            // Cheaper at the defaults' 64-spp error, by another method.
            measured("voxel 512", "voxel 512", 64, 40.0, 0.0009),
        ]
        .into_iter()
        .flatten()
        .collect();
        let (notes, _) = summarise(&rows, &Options::default());
        let defaults = notes
            .iter()
            .find(|n| n.contains("the defaults take"))
            .expect("a defaults line");
        // Against the RBF settings: on their front at both errors; against every method's,
        // 2.5x at 64 spp.
        assert!(
            defaults.contains("1.00x, 1.00x the RBF front's time")
                && defaults.contains("1.00x, 2.50x every method's"),
            "{defaults}"
        );
        let front = notes
            .iter()
            .find(|n| n.contains("the Pareto front"))
            .expect("a front line");
        assert!(front.contains("voxel 512 at 64 spp"), "{front}");
    }
}
