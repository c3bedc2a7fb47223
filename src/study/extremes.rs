//! f32 against f64 at the extremes: the field error of every backend's reduced
//! precision (the CPU's f32 kernel and its automatic choice, the GPU backends' f32 and
//! double-single positions) against the f64 reference, over radii from 1e-6 to 1e2 of the
//! domain, coordinate offsets up to 1e6 and Phi down to f32's denormal range.
//!
//! Each case is generated here as a simulation writes data: particles uniform in a unit box
//! (the domain), in f64, the box then offset by the same amount on every axis. Each case is
//! measured twice:
//! - **f64 inputs**: positions, query points, radius and attribute as drawn; what a backend
//!   rounds to f32 carries the rounding of its inputs as well as that of its arithmetic;
//! - **f32-exact inputs**: the same drawn onto values f32 holds exactly, so what remains is the
//!   arithmetic's error. "Exactly" means in the coordinates a backend rounds: every backend
//!   subtracts the series' centre in f64 before rounding to f32 (`gpu_data`), so positions and
//!   query points lie on a grid of 2^-24 of the box's side, which makes both their data
//!   coordinates (up to offsets of 2^28) and their local coordinates (at most half the side
//!   from the centre) exact; the radius is an f32 value, and the attribute is normalised over
//!   [0, 1] from f32 values. Rounding data coordinates to f32 instead would put points at an
//!   offset of 1e6 on a grid of 1/16 of the domain, which measures nothing.
//!
//! Query points lie within √3/2 of the radius of a particle (a random offset in a cube of
//! side r around it), so the reference Phi is never 0: at a radius of 1e-6 of the domain a
//! random point would find no particle. The metrics per case, inputs, backend and precision:
//! Phi's relative error |Phi - Phi_ref| / Phi_ref (maximum and median over the points; where
//! Phi_ref is 0 a non-zero Phi would count as 1, wholly wrong), Theta's error as a fraction of
//! the attribute's range (maximum; Theta as [`finish_sums`] defines it, 0 where Phi is 0 or
//! denormal in f64), the points whose Phi or Theta numerator is not finite (left out of the
//! errors), and the bound on the relative Phi error the backend states for its representation
//! (`backend::precision`: positions, kernel, terms and sums; none for the f64 reference).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::sync::Arc;

use glam::DVec3;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use super::plot::{Figure, Panel, Scale, Series};
use super::record::Device;
use super::{Ctx, Description, Options, Row, StudyError, value};
use crate::accel::ClusterSize;
use crate::backend::precision::PositionKind;
use crate::backend::{self, Backend, BackendKind, Precision, Representation, StepInput};
use crate::field::{FieldSettings, ReferenceField, finish_sums};
use crate::scene::maps::{DensityMap, PiecewiseLinear};
use crate::values::{Attribute, Bounds, Step};

pub const DESCRIPTION: Description = Description {
    title: "f32 against f64 at the extremes",
    paper: "Not a figure of the paper: the field error of each backend's f32 path (and of the \
            double-single positions the GPU backends switch to) against the f64 reference at \
            radii from 1e-6 to 1e2 of the domain, coordinate offsets up to 1e6 and Phi down to \
            f32's denormal range. The goal: at most 1e-5 relative Phi error where the f32 \
            inputs are exact.",
    settings: &[
        "family",
        "radius_fraction",
        "offset",
        "weight",
        "inputs",
        "precision",
        "positions",
        "queries",
    ],
};

/// The relative Phi error f32 arithmetic is held to on f32-exact inputs.
pub const GOAL: f64 = 1e-5;

/// Particles of every case when `--count` is not given: a few thousand keeps a query at a
/// radius of 100 domains (every particle reaches every point) cheap on lavapipe.
pub const DEFAULT_COUNT: usize = 4000;

/// Query points per case.
pub const QUERIES: usize = 1024;

/// The radius of the offset and Phi cases, as a fraction of the domain: a few particles reach
/// each point at the default count.
pub const MODERATE_RADIUS: f64 = 0.05;

/// The grid of f32-exact inputs, as a fraction of the domain (2^-24).
const EXACT_GRID: f64 = 1.0 / (1u64 << 24) as f64;

/// The largest offset whose f32-exact data coordinates f64 holds exactly (offset + k 2^-24
/// needs the offset's bits above 2^-24: 52 bits of mantissa cover up to 2^28).
pub const MAX_OFFSET: f64 = (1u64 << 28) as f64;

/// The smallest a particle's Phi term gets before the kernel cuts it off: w exp(-4.5).
fn smallest_term(weight: f64) -> f64 {
    weight * (-4.5f64).exp()
}

/// Whether a case's particle terms reach below f32's smallest normal number, where a GPU that
/// flushes denormals to zero (lavapipe does) drops them.
pub fn reaches_denormals(weight: f64) -> bool {
    smallest_term(weight) < f64::from(f32::MIN_POSITIVE)
}

/// Which sweep a case belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Family {
    /// The radius from 1e-6 to 1e2 of the domain, at offset 0 and weight 1.
    Radius,
    /// The coordinate offset, at the moderate radius.
    Offset,
    /// The density weight w (so Phi ~ w), at the moderate radius and offset 0.
    Phi,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::Radius => "radius",
            Family::Offset => "offset",
            Family::Phi => "phi",
        }
    }
}

/// How a case's inputs are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Inputs {
    /// As drawn, in f64.
    F64,
    /// On values f32 holds exactly in every backend's local coordinates (module docs).
    F32Exact,
}

impl Inputs {
    pub const BOTH: [Inputs; 2] = [Inputs::F64, Inputs::F32Exact];

    pub fn name(self) -> &'static str {
        match self {
            Inputs::F64 => "f64",
            Inputs::F32Exact => "f32-exact",
        }
    }
}

/// One case: a unit box of particles at `offset` with radius `radius_fraction` (of the box's
/// side) and density weight `weight`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    pub family: Family,
    pub radius_fraction: f64,
    pub offset: f64,
    pub weight: f64,
}

impl Case {
    /// The moderate case every sweep starts from: offset 0, weight 1.
    pub fn moderate(family: Family) -> Case {
        Case {
            family,
            radius_fraction: MODERATE_RADIUS,
            offset: 0.0,
            weight: 1.0,
        }
    }

    /// Its row label, e.g. `radius 1e-6`.
    pub fn name(&self) -> String {
        match self.family {
            Family::Radius => format!("radius {}", short(self.radius_fraction)),
            Family::Offset => format!("offset {}", short(self.offset)),
            Family::Phi => format!("w {}", short(self.weight)),
        }
    }
}

/// A sweep value as people write it: `1e-6`, `0`, `1e2`, `0.05`.
fn short(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let e = v.abs().log10().round();
    if (v.abs() / 10f64.powf(e) - 1.0).abs() < 1e-9 && e.abs() >= 2.0 {
        format!("{}1e{e}", if v < 0.0 { "-" } else { "" })
    } else {
        format!("{v}")
    }
}

/// The cases `options` ask for: the radius sweep, the offset sweep and the weight sweep.
pub fn cases(options: &Options) -> Vec<Case> {
    let mut out = Vec::new();
    for &f in &options.radius_fractions {
        out.push(Case {
            radius_fraction: f,
            ..Case::moderate(Family::Radius)
        });
    }
    for &o in &options.offsets {
        out.push(Case {
            offset: o,
            ..Case::moderate(Family::Offset)
        });
    }
    for &w in &options.phi_weights {
        out.push(Case {
            weight: w,
            ..Case::moderate(Family::Phi)
        });
    }
    out
}

/// Checks the sweeps: positive radii and weights (weights within what an f32 table holds, down
/// to its smallest denormal), offsets within [`MAX_OFFSET`].
pub fn check_sweeps(options: &Options) -> Result<(), String> {
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    if options.radius_fractions.is_empty()
        || options.offsets.is_empty()
        || options.phi_weights.is_empty()
    {
        return Err("--radius-fractions, --offsets and --weights need at least one value".into());
    }
    if !options.radius_fractions.iter().all(positive) {
        return Err("--radius-fractions: every fraction must be positive".into());
    }
    if !options
        .offsets
        .iter()
        .all(|o| o.is_finite() && o.abs() <= MAX_OFFSET)
    {
        return Err(format!(
            "--offsets: every offset must lie within ±{MAX_OFFSET:e} (the f32-exact inputs' \
             data coordinates must be exact in f64)"
        ));
    }
    // Below f32's smallest denormal the density table holds 0 and there is nothing to compare;
    // above its largest finite value, infinity.
    let lowest = f64::from(f32::from_bits(1));
    if !options
        .phi_weights
        .iter()
        .all(|w| positive(w) && *w >= lowest && *w <= f64::from(f32::MAX))
    {
        return Err(format!(
            "--weights: every weight must lie in [{lowest:e}, {:e}] (what an f32 table holds)",
            f32::MAX
        ));
    }
    Ok(())
}

/// A case's data, field settings, bounds and query points for one kind of inputs.
pub struct Scene {
    pub step: Arc<Step>,
    pub field: FieldSettings,
    /// The box the particles were drawn in: the series' bounds a backend gets, whose centre is
    /// the origin of its local coordinates.
    pub bounds: Bounds,
    /// The attribute's range the field normalises over.
    pub range: (f64, f64),
    pub queries: Vec<DVec3>,
}

impl Scene {
    /// Generates `case` with `count` particles and [`QUERIES`] query points, from `seed`.
    pub fn generate(
        case: &Case,
        inputs: Inputs,
        count: usize,
        seed: u64,
    ) -> Result<Scene, StudyError> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let exact = inputs == Inputs::F32Exact;
        let offset = if exact {
            (case.offset / EXACT_GRID).round() * EXACT_GRID
        } else {
            case.offset
        };
        let lo = DVec3::splat(offset);
        // A fraction of the domain in [0, 1], on the exact grid when asked for. The offset is
        // added after snapping, so data coordinates are offset + k 2^-24, exact in f64.
        let snap = |u: f64| {
            if exact {
                (u / EXACT_GRID).round() * EXACT_GRID
            } else {
                u
            }
        };
        let unit: Vec<DVec3> = (0..count)
            .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()).map(snap))
            .collect();
        let s: Vec<f64> = (0..count)
            .map(|_| {
                let u: f64 = rng.random();
                if exact { f64::from(u as f32) } else { u }
            })
            .collect();
        let radius = if exact {
            f64::from(case.radius_fraction as f32)
        } else {
            case.radius_fraction
        };
        let half = 0.5 * radius;
        let queries: Vec<DVec3> = (0..if count > 0 { QUERIES } else { 0 })
            .map(|_| {
                let c = unit[rng.random_range(0..count)];
                let d = DVec3::new(
                    rng.random_range(-half..=half),
                    rng.random_range(-half..=half),
                    rng.random_range(-half..=half),
                );
                lo + (c + d).clamp(DVec3::ZERO, DVec3::ONE).map(snap)
            })
            .collect();
        let range = if exact {
            // f32 values normalised over [0, 1]: t = s, exact.
            (0.0, 1.0)
        } else {
            s.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                })
        };
        let mut field = FieldSettings::new(Some("s"), radius);
        field.density_map = DensityMap::new(PiecewiseLinear::constant(case.weight))
            .map_err(|e| StudyError::Invalid(e.to_string()))?;
        Ok(Scene {
            step: Arc::new(Step {
                name: case.name(),
                positions: unit.iter().map(|&u| lo + u).collect(),
                attributes: vec![Attribute {
                    name: "s".into(),
                    values: s,
                }],
            }),
            field,
            bounds: Bounds {
                min: lo,
                max: lo + DVec3::ONE,
            },
            range,
            queries,
        })
    }

    /// The step as a backend receives it.
    pub fn input(&self, precision: Precision) -> StepInput<'_> {
        StepInput {
            step: &self.step,
            field: &self.field,
            cluster: CLUSTER,
            series_bounds: self.bounds,
            series_range: Some(self.range),
            precision,
        }
    }

    /// The f64 reference's Phi and Theta numerator at the query points.
    pub fn reference(&self) -> Result<Vec<(f64, [f64; 3])>, StudyError> {
        let field = ReferenceField::of_step(
            &self.step,
            &self.field,
            CLUSTER,
            self.bounds,
            Some(self.range),
        )
        .map_err(|e| StudyError::Backend(e.into()))?;
        Ok(self
            .queries
            .par_iter()
            .map(|&x| field.eval_sums(x))
            .collect())
    }
}

/// Cluster size of every case: one particle a box, as the other studies' default.
const CLUSTER: ClusterSize = ClusterSize::ALL[0];

/// The precisions measured on a backend, with their names: the CPU's f32 kernel and its
/// automatic choice at the 1e-5 `aarbf field` asks for (f32 where the stated bound allows it,
/// else the f64 reference itself); the GPU backends' f32 and double-single positions (their
/// automatic choice is one of the two, by the same bound).
pub fn precisions(kind: BackendKind) -> Vec<(Precision, &'static str)> {
    match kind {
        BackendKind::Cpu => vec![(Precision::F32, "f32"), (Precision::FIELD, "auto")],
        _ => vec![(Precision::F32, "f32"), (Precision::DoubleSingle, "ds")],
    }
}

/// The errors of one backend's field against the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Errors {
    pub phi_max: f64,
    pub phi_median: f64,
    /// As a fraction of the attribute's range.
    pub theta_max: f64,
    /// Points whose Phi or Theta numerator is not finite (left out of the errors above).
    pub nonfinite: usize,
}

/// The errors of `got` against `reference` (Phi and Theta numerators at the same points) for
/// an attribute normalised over its range (so Theta's error is a fraction of the range).
pub fn errors(reference: &[(f64, [f64; 3])], got: &[(f64, [f64; 3])]) -> Errors {
    let mut phi = Vec::with_capacity(got.len());
    let mut theta_max = 0.0f64;
    let mut nonfinite = 0;
    for (&(rphi, rnum), &(gphi, gnum)) in reference.iter().zip(got) {
        if !(gphi.is_finite() && gnum.iter().all(|v| v.is_finite())) {
            nonfinite += 1;
            continue;
        }
        phi.push(if rphi > 0.0 {
            (gphi - rphi).abs() / rphi
        } else if gphi == 0.0 {
            0.0
        } else {
            1.0
        });
        // The numerators hold t in [0, 1]: Theta over the unit range is the fraction of the
        // attribute's range.
        let t = |p, n| finish_sums(p, n, true, (0.0, 1.0)).theta[0];
        theta_max = theta_max.max((t(gphi, gnum) - t(rphi, rnum)).abs());
    }
    Errors {
        phi_max: phi.iter().copied().fold(0.0, f64::max),
        phi_median: if phi.is_empty() {
            0.0
        } else {
            super::record::median(&phi)
        },
        theta_max,
        nonfinite,
    }
}

/// Uploads `scene` to `backend` at `precision`, builds, queries its points and compares them
/// with `reference`: the errors and how the backend holds the positions.
pub fn measure_scene(
    backend: &mut dyn Backend,
    scene: &Scene,
    precision: Precision,
    reference: &[(f64, [f64; 3])],
) -> Result<(Errors, Option<Representation>), StudyError> {
    backend.upload(&scene.input(precision))?;
    backend.build()?;
    let got = backend::query_in_hilbert_order(backend, &scene.queries, |_| {})?;
    Ok((errors(reference, &got), backend.representation()))
}

fn positions_name(p: Option<Representation>) -> &'static str {
    match p.map(|r| r.positions) {
        Some(PositionKind::F64) => "f64",
        Some(PositionKind::F32) => "f32",
        Some(PositionKind::DoubleSingle) => "ds",
        None => "none",
    }
}

pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    if !o.data.is_empty() {
        tracing::info!("extremes: generates its own cases; --data is not used");
    }
    let count = o.count.unwrap_or(DEFAULT_COUNT);
    if count == 0 {
        return Err(StudyError::Invalid("--count must be at least 1".into()));
    }
    let cases = cases(o);
    // One backend of each kind for every case: a device starts once, and lavapipe compiles
    // each pipeline once.
    let mut backends: Vec<(BackendKind, Box<dyn Backend>, Device)> = Vec::new();
    for &kind in ctx.backends {
        let b = backend::create(kind)?;
        let caps = b.capabilities();
        let device = Device::of(caps.name, &caps.device, "none (errors only)");
        backends.push((kind, b, device));
    }
    let per_case: usize = ctx
        .backends
        .iter()
        .map(|&k| precisions(k).len())
        .sum::<usize>()
        * Inputs::BOTH.len();
    let bar = ctx.bar(cases.len() * per_case, "extremes");
    for (i, case) in cases.iter().enumerate() {
        for inputs in Inputs::BOTH {
            // The same particles for both inputs, snapped or not.
            let scene = Scene::generate(case, inputs, count, 1000 + i as u64)?;
            let reference = scene.reference()?;
            for (kind, b, device) in &mut backends {
                for (precision, name) in precisions(*kind) {
                    let (e, positions) = measure_scene(b.as_mut(), &scene, precision, &reference)?;
                    let row = |metric, unit, v: f64| Row {
                        device: device.clone(),
                        variant: name.into(),
                        data: case.name(),
                        step: 0,
                        n: count,
                        settings: vec![
                            ("family", case.family.name().into()),
                            ("radius_fraction", value(case.radius_fraction)),
                            ("offset", value(case.offset)),
                            ("weight", value(case.weight)),
                            ("inputs", inputs.name().into()),
                            ("precision", name.into()),
                            ("positions", positions_name(positions).into()),
                            ("queries", scene.queries.len().to_string()),
                        ],
                        metric,
                        unit,
                        values: vec![v],
                    };
                    ctx.recorder
                        .record(row("phi_rel_max", "relative", e.phi_max))?;
                    ctx.recorder
                        .record(row("phi_rel_median", "relative", e.phi_median))?;
                    ctx.recorder
                        .record(row("theta_max", "of range", e.theta_max))?;
                    ctx.recorder
                        .record(row("nonfinite", "points", e.nonfinite as f64))?;
                    // (None where terms leave f32's normal range: the bound is infinite.)
                    if let Some(r) = positions
                        .filter(|r| r.positions != PositionKind::F64 && r.bound.phi().is_finite())
                    {
                        ctx.recorder
                            .record(row("stated_bound", "relative", r.bound.phi()))?;
                    }
                    bar.inc(1);
                }
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// A case's x on its sweep's axis.
fn x_of(r: &Row) -> f64 {
    let get = |k| {
        r.setting(k)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    match r.setting("family") {
        Some("radius") => get("radius_fraction"),
        // A log axis has no 0: offset 0 is drawn at 1.
        Some("offset") => get("offset").max(1.0),
        _ => get("weight"),
    }
}

/// Errors below this are drawn at it (the CPU's automatic choice of f64 is the reference
/// itself, with no error at all).
const PLOT_FLOOR: f64 = 1e-10;

fn inputs_of(r: &Row) -> &str {
    r.setting("inputs").unwrap_or("")
}

fn weight_of(r: &Row) -> f64 {
    r.setting("weight")
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0)
}

/// The largest `metric` over `rows` of `series` with `inputs`, and whether any was measured.
fn worst(
    rows: &[Row],
    series: &str,
    inputs: &str,
    metric: &str,
    keep: impl Fn(&Row) -> bool,
) -> Option<f64> {
    rows.iter()
        .filter(|r| r.series() == series && inputs_of(r) == inputs && r.metric == metric)
        .filter(|r| keep(r))
        .map(Row::max)
        .reduce(f64::max)
}

fn sci(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.1e}")
    }
}

/// The series (backend and precision) in the order measured.
fn series_names(rows: &[Row]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in rows {
        let s = r.series();
        if !out.contains(&s) {
            out.push(s);
        }
    }
    out
}

/// The table of the page: a row per case and inputs, a column per backend and precision, each
/// cell the largest relative Phi error and the largest Theta error (fraction of the range).
pub fn table(rows: &[Row]) -> String {
    let series = series_names(rows);
    // (case, inputs) in the order measured.
    let mut keys: Vec<(String, String)> = Vec::new();
    let mut cells: BTreeMap<(String, String, String), (f64, f64, f64)> = BTreeMap::new();
    for r in rows {
        let key = (r.data.clone(), inputs_of(r).to_owned());
        if !keys.contains(&key) {
            keys.push(key.clone());
        }
        let cell = cells
            .entry((key.0, key.1, r.series()))
            .or_insert((f64::NAN, f64::NAN, 0.0));
        match r.metric {
            "phi_rel_max" => cell.0 = r.max(),
            "theta_max" => cell.1 = r.max(),
            "nonfinite" => cell.2 = r.max(),
            _ => {}
        }
    }
    let mut out = String::new();
    let _ = writeln!(
        out,
        "Largest relative Phi error / largest Theta error (fraction of the attribute's range) \
         over the query points, against the f64 reference:\n"
    );
    let _ = write!(out, "| case | inputs |");
    for s in &series {
        let _ = write!(out, " {s} |");
    }
    let _ = writeln!(out);
    let _ = write!(out, "|---|---|");
    for _ in &series {
        let _ = write!(out, "---|");
    }
    let _ = writeln!(out);
    for (case, inputs) in &keys {
        let _ = write!(out, "| {case} | {inputs} |");
        for s in &series {
            match cells.get(&(case.clone(), inputs.clone(), s.clone())) {
                Some(&(phi, theta, nonfinite)) => {
                    let _ = write!(out, " {} / {}", sci(phi), sci(theta));
                    if nonfinite > 0.0 {
                        let _ = write!(out, " ({nonfinite} non-finite)");
                    }
                    let _ = write!(out, " |");
                }
                None => {
                    let _ = write!(out, " – |");
                }
            }
        }
        let _ = writeln!(out);
    }
    out
}

pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    let normal = |r: &Row| !reaches_denormals(weight_of(r));
    for s in series_names(rows) {
        let mut parts = Vec::new();
        for inputs in Inputs::BOTH.map(Inputs::name) {
            let pick = |metric, keep: &dyn Fn(&Row) -> bool| worst(rows, &s, inputs, metric, keep);
            let (Some(phi), Some(theta)) =
                (pick("phi_rel_max", &|_| true), pick("theta_max", &|_| true))
            else {
                continue;
            };
            let (phi_normal, theta_normal) =
                (pick("phi_rel_max", &normal), pick("theta_max", &normal));
            let goal = if inputs == Inputs::F32Exact.name() {
                match phi_normal {
                    Some(v) if v <= GOAL => format!(" (the {} goal: met)", sci(GOAL)),
                    Some(_) => format!(" (the {} goal: missed)", sci(GOAL)),
                    None => String::new(),
                }
            } else {
                String::new()
            };
            parts.push(format!(
                "{inputs} inputs: Phi within {} relative and Theta within {} of the range where \
                 every term stays in f32's normal range{goal}; {} and {} over all cases",
                phi_normal.map_or("–".into(), sci),
                theta_normal.map_or("–".into(), sci),
                sci(phi),
                sci(theta),
            ));
        }
        // Does the whole bound a backend states hold, where terms stay normal (it bounds every
        // source of f32 error, not denormals)?
        let stated: Vec<(f64, f64)> = rows
            .iter()
            .filter(|r| r.series() == s && r.metric == "stated_bound" && normal(r))
            .filter_map(|b| {
                rows.iter()
                    .find(|r| {
                        r.metric == "phi_rel_max"
                            && r.series() == s
                            && r.settings == b.settings
                            && r.data == b.data
                    })
                    .map(|r| (r.max(), b.max()))
            })
            .collect();
        if !stated.is_empty() {
            let held = stated.iter().filter(|(err, bound)| err <= bound).count();
            parts.push(format!(
                "the stated error bound held in {held} of {} cases whose terms stay normal",
                stated.len()
            ));
        }
        let nonfinite = rows
            .iter()
            .filter(|r| r.series() == s && r.metric == "nonfinite")
            .map(Row::max)
            .sum::<f64>();
        if nonfinite > 0.0 {
            parts.push(format!("{nonfinite} non-finite values"));
        }
        notes.push(format!("`{s}`: {}", parts.join("; ")));
    }
    let mut panels = Vec::new();
    for (family, x_label) in [
        (Family::Radius, "radius (fraction of the domain)"),
        (Family::Offset, "coordinate offset (domains; 0 drawn at 1)"),
        (Family::Phi, "density weight w (Phi ≈ 0.03 w .. a few w)"),
    ] {
        for inputs in Inputs::BOTH {
            let selected: Vec<Row> = rows
                .iter()
                .filter(|r| r.setting("family") == Some(family.name()))
                .filter(|r| inputs_of(r) == inputs.name())
                .cloned()
                .map(|mut r| {
                    for v in &mut r.values {
                        *v = v.max(PLOT_FLOOR);
                    }
                    r
                })
                .collect();
            let mut series = super::plot::lines(&selected, "phi_rel_max", Row::series, x_of, 1.0);
            let xs: Vec<f64> = series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.0))
                .collect();
            let (lo, hi) = xs
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            if lo.is_finite() {
                series.push(Series {
                    label: format!("goal {}", sci(GOAL)),
                    points: vec![(lo, GOAL, GOAL, GOAL), (hi, GOAL, GOAL, GOAL)],
                    dashed: true,
                });
            }
            panels.push(Panel::Lines {
                title: format!("{} sweep, {} inputs", family.name(), inputs.name()),
                x_label: x_label.into(),
                y_label: "largest relative Phi error".into(),
                x_scale: Scale::Log10,
                y_scale: Scale::Log10,
                series,
            });
        }
    }
    let count = options.count.unwrap_or(DEFAULT_COUNT);
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels,
        caption: vec![
            format!(
                "Goal: relative Phi error at most {} where the f32 inputs are exact (right \
                 column; dashed line). Largest relative Phi error over {QUERIES} points near \
                 particles, against the f64 reference.",
                sci(GOAL)
            ),
            format!(
                "{count} particles uniform in a unit box; radius sweep at offset 0, offset and \
                 weight sweeps at radius {MODERATE_RADIUS}. f32-exact: positions on a 2^-24 \
                 grid of the box, an f32 radius, an attribute of f32 values."
            ),
            format!(
                "Errors below {} (none: the CPU's auto choosing f64, the reference itself) are \
                 drawn at {}.",
                sci(PLOT_FLOOR),
                sci(PLOT_FLOOR)
            ),
        ],
    };
    (notes, figure)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_are_relative_and_count_what_is_not_finite() {
        let reference = [
            (2.0, [1.0, 0.0, 0.0]),
            (1.0, [0.5, 0.0, 0.0]),
            (0.0, [0.0; 3]),
            (1.0, [1.0, 0.0, 0.0]),
        ];
        let got = [
            (2.0 + 2e-6, [1.0, 0.0, 0.0]),
            (1.0, [0.25, 0.0, 0.0]),
            (0.0, [0.0; 3]),
            (f64::NAN, [1.0, 0.0, 0.0]),
        ];
        let e = errors(&reference, &got);
        assert!((e.phi_max - 1e-6).abs() < 1e-12, "{e:?}");
        assert_eq!(e.phi_median, 0.0);
        // Theta 0.5 -> 0.25 at the second point.
        assert!((e.theta_max - 0.25).abs() < 1e-12, "{e:?}");
        assert_eq!(e.nonfinite, 1);
        // Density where the reference has none is wholly wrong; none where it has some too.
        let e = errors(
            &[(0.0, [0.0; 3]), (1.0, [0.0; 3])],
            &[(1e-30, [0.0; 3]), (0.0, [0.0; 3])],
        );
        assert_eq!(e.phi_max, 1.0);
    }

    #[test]
    fn f32_exact_inputs_are_exact_in_local_coordinates() {
        let case = Case {
            offset: 1e6,
            radius_fraction: 1e-6,
            ..Case::moderate(Family::Offset)
        };
        let scene = Scene::generate(&case, Inputs::F32Exact, 500, 3).unwrap();
        let origin = scene.bounds.center();
        for &p in scene.step.positions.iter().chain(&scene.queries) {
            let local = p - origin;
            for c in local.to_array() {
                assert_eq!(f64::from(c as f32), c, "{p}");
            }
        }
        assert_eq!(f64::from(scene.field.radius as f32), scene.field.radius);
        // The f64 inputs are not: most coordinates lose digits in f32.
        let scene = Scene::generate(&case, Inputs::F64, 500, 3).unwrap();
        let origin = scene.bounds.center();
        let inexact = scene
            .step
            .positions
            .iter()
            .filter(|&&p| {
                let l = p - origin;
                f64::from(l.x as f32) != l.x
            })
            .count();
        assert!(inexact > 450, "{inexact}");
    }

    #[test]
    fn query_points_lie_near_particles() {
        let case = Case {
            radius_fraction: 1e-6,
            ..Case::moderate(Family::Radius)
        };
        for inputs in Inputs::BOTH {
            let scene = Scene::generate(&case, inputs, 300, 4).unwrap();
            let reference = scene.reference().unwrap();
            assert_eq!(reference.len(), QUERIES);
            assert!(reference.iter().all(|(phi, _)| *phi > 0.0));
        }
    }

    #[test]
    fn sweeps_are_checked_and_named() {
        let o = Options::default();
        assert!(check_sweeps(&o).is_ok());
        assert_eq!(cases(&o).len(), 9 + 4 + o.phi_weights.len());
        for bad in [
            Options {
                radius_fractions: vec![0.0],
                ..Options::default()
            },
            Options {
                offsets: vec![1e12],
                ..Options::default()
            },
            Options {
                phi_weights: vec![1e-50],
                ..Options::default()
            },
        ] {
            assert!(check_sweeps(&bad).is_err());
        }
        assert_eq!(short(1e-6), "1e-6");
        assert_eq!(short(0.05), "0.05");
        assert_eq!(short(1e2), "1e2");
        assert!(reaches_denormals(1e-37) && !reaches_denormals(1e-30));
    }
}
