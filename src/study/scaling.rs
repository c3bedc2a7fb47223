//! How cost grows with work: structure build and refit, field queries and frame time against
//! the particle count N, from 10K up to what this machine holds, on a log-log plot with the
//! exponent fitted to each line (cost ∝ N^e).
//!
//! The data is a generator's (`uniform` by default) at each N, or random nested subsets of a
//! data set's largest step up to the whole step (`--data PATH`: the largest step this machine
//! holds is the one the user has); the radius keeps the overlap constant (about 30 particles
//! reach a point in `uniform` and `random`; for other generators the default radius shrinks as
//! N^(-1/3) from the generator's default count; a subset's grows as (N_step / N)^(1/3)), so the
//! work per sample stays the same and the curves show what N alone costs.

use super::plot::{Figure, Panel, Scale};
use super::{
    Ctx, DataSpec, Description, Measurement, Options, Row, StudyError, cameras, device_of,
    frame_columns, frame_times, value,
};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::scene::synth::Generator;
use crate::values::NoiseKind;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "Scaling with the particle count",
    paper: "Not a figure of the paper: how build, refit, query and frame time grow with N at a \
            constant overlap. A GPU LBVH build (radix sort, hierarchy, bottom-up bounds) and a \
            refit are linear in N; a query's cost grows with the tree's depth (log N) at a fixed \
            number of particles per point.",
    settings: frame_columns!["radius", "k", "queries"],
};

/// The particle counts: from `min_n` times 4 while at most `max_n`, and `max_n` itself.
pub fn sizes(min_n: usize, max_n: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut n = min_n;
    while n <= max_n {
        out.push(n);
        n = n.saturating_mul(4);
    }
    if out.last() != Some(&max_n) {
        out.push(max_n);
    }
    out
}

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let ns = sizes(o.min_n, o.max_n);
    let bar = ctx.bar(ctx.data.len() * ns.len() * ctx.backends.len(), "scaling");
    let cluster = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    for spec in ctx.data {
        // A data set on disk: random subsets of its largest step (or of --step), up to the
        // whole step; a generator: its data generated at each N.
        let (whole, generator) = match spec {
            DataSpec::Path(_) => {
                let load =
                    |step| super::Dataset::load(spec, None, step, o.attribute.as_deref(), o.radius);
                let ds = load(o.step)?;
                let largest = ds.largest_step();
                let ds = if o.step.is_none() && largest != ds.step {
                    load(Some(largest))?
                } else {
                    ds
                };
                (Some(ds), None)
            }
            DataSpec::Generated(g) => (None, Some(*g)),
        };
        let ns = match &whole {
            Some(w) => sizes(o.min_n.min(w.n), o.max_n.min(w.n)),
            None => ns.clone(),
        };
        for &n in &ns {
            let ds = match (&whole, generator) {
                (Some(whole), _) => whole.subset(n, 17, o.radius.is_none())?,
                (None, generator) => {
                    let mut ds = super::Dataset::load(
                        spec,
                        Some(n),
                        o.step,
                        o.attribute.as_deref(),
                        o.radius,
                    )?;
                    if o.radius.is_none()
                        && let Some(g) = generator
                        && !matches!(g, Generator::Uniform | Generator::Random)
                    {
                        ds.radius *= (g.default_count() as f64 / ds.n as f64).cbrt();
                    }
                    ds
                }
            };
            let orbit = cameras(ds.bounds, o.cameras);
            let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
            let mut wider = field.clone();
            wider.radius *= 1.1;
            let points = super::query_points(o.queries, ds.bounds, 11);
            for &kind in ctx.backends {
                let mut session = super::session(kind, &ds)?;
                let device = device_of(&session);
                // Builds (after the untimed warm-up) and refits after a 10% radius change, back and
                // forth (the first untimed).
                let (builds, refits) = super::build_and_refit_times(
                    &mut session,
                    &ds,
                    &field,
                    &wider,
                    cluster,
                    o.repetitions,
                )?;
                session
                    .backend_mut()
                    .query(&points[..points.len().min(1024)])?;
                let mut queries = Vec::new();
                for _ in 0..o.repetitions {
                    session.backend_mut().query(&points)?;
                    queries.push(super::ms(session.backend().timings().query));
                }
                let settings = ctx.frame_settings(NoiseKind::Stbn);
                let dt = session.resolve(&settings)?.step_size;
                let frames = frame_times(&mut session, &settings, &orbit, o.repetitions)?;
                let m = Measurement::new(
                    device.clone(),
                    &ds,
                    super::with_frame_settings(
                        vec![
                            ("radius", value(ds.radius)),
                            ("k", "1".into()),
                            ("queries", points.len().to_string()),
                        ],
                        o,
                        dt,
                    ),
                );
                ctx.record(&m, "build", "ms", builds)?;
                ctx.record(&m, "refit", "ms", refits)?;
                ctx.record(&m, "query", "ms", queries)?;
                ctx.record(&m, "frame", "ms", frames)?;
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    let mut panels = Vec::new();
    for (metric, title) in [
        ("build", "structure build"),
        ("refit", "refit after a radius change"),
        ("query", "field queries"),
        ("frame", "frame over the orbit"),
    ] {
        let mut series = super::plot::lines(
            rows,
            metric,
            |r| super::line_name(r, rows),
            |r| r.n as f64,
            1.0,
        );
        for s in &mut series {
            let fit: Vec<(f64, f64)> = s.points.iter().map(|p| (p.0, p.1)).collect();
            if let Some(e) = super::fitted_exponent(&fit) {
                notes.push(format!(
                    "{} {metric}: time ∝ N^{e:.2} over N = {:.0}..{:.0}",
                    s.label,
                    fit.first().map_or(0.0, |p| p.0),
                    fit.last().map_or(0.0, |p| p.0)
                ));
                s.label = format!("{} (∝ N^{e:.2})", s.label);
            }
        }
        let y = if metric == "query" {
            format!("time for {} queries (ms)", options.queries)
        } else {
            format!("{metric} time (ms)")
        };
        panels.push(Panel::Lines {
            title: title.into(),
            x_label: "particles N".into(),
            y_label: y,
            x_scale: Scale::Log10,
            y_scale: Scale::Log10,
            series,
        });
    }
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels,
        caption: vec![
            "Cost vs N at constant overlap, log-log, with the fitted exponent e (time ∝ N^e) in each label: builds and refits are expected near-linear (e ≈ 1); queries and frames grow slowly (tree depth)."
                .into(),
            super::timing_caption(options),
        ],
    };
    (notes, figure)
}

#[cfg(test)]
mod tests {
    #[test]
    fn sizes_grow_by_four_to_the_largest() {
        assert_eq!(
            super::sizes(10_000, 200_000),
            [10_000, 40_000, 160_000, 200_000]
        );
        assert_eq!(super::sizes(100, 1600), [100, 400, 1600]);
        assert_eq!(super::sizes(300, 300), [300]);
    }
}
