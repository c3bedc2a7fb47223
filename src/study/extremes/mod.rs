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
use super::{Ctx, Description, Measurement, Options, Row, StudyError, value};
use crate::accel::ClusterSize;
use crate::backend::precision::PositionKind;
use crate::backend::{self, Backend, BackendKind, Precision, Representation, StepInput};
use crate::field::{FieldSettings, ReferenceField, finish_sums};
use crate::scene::maps::{DensityMap, PiecewiseLinear};
use crate::values::{Attribute, Bounds, Step};

mod summary;
#[cfg(test)]
mod tests;

pub use summary::{summarise, table};

/// The study's title, what the paper found and its settings' columns.
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
    /// The name rows and tables use.
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
    /// Both kinds, f64 first.
    pub const BOTH: [Inputs; 2] = [Inputs::F64, Inputs::F32Exact];

    /// The name rows and tables use.
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
    /// The sweep it belongs to.
    pub family: Family,
    /// The particles' radius as a fraction of the box's side.
    pub radius_fraction: f64,
    /// Added to every coordinate, in box sides.
    pub offset: f64,
    /// The density weight w (Phi scales with it).
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
    /// The particles.
    pub step: Arc<Step>,
    /// The field over them.
    pub field: FieldSettings,
    /// The box the particles were drawn in: the series' bounds a backend gets, whose centre is
    /// the origin of its local coordinates.
    pub bounds: Bounds,
    /// The attribute's range the field normalises over.
    pub range: (f64, f64),
    /// The points Phi and Theta are compared at: each within half a radius of a particle.
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
    /// The largest relative error of Phi.
    pub phi_max: f64,
    /// The median relative error of Phi.
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

/// Measures every case of every sweep on every backend asked for, recording each row as it is
/// taken.
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
                    let m = Measurement {
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
                    };
                    ctx.record(&m, "phi_rel_max", "relative", vec![e.phi_max])?;
                    ctx.record(&m, "phi_rel_median", "relative", vec![e.phi_median])?;
                    ctx.record(&m, "theta_max", "of range", vec![e.theta_max])?;
                    ctx.record(&m, "nonfinite", "points", vec![e.nonfinite as f64])?;
                    // (None where terms leave f32's normal range: the bound is infinite.)
                    if let Some(r) = positions
                        .filter(|r| r.positions != PositionKind::F64 && r.bound.phi().is_finite())
                    {
                        ctx.record(&m, "stated_bound", "relative", vec![r.bound.phi()])?;
                    }
                    bar.inc(1);
                }
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}
