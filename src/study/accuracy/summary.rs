//! The accuracy study's rows as its notes and figure: the Pareto front of time against error
//! for each device and data set, the defaults and `--target-error` held to it.

use super::DESCRIPTION;
use crate::study::plot::{Figure, Panel, Scale, Series};
use crate::study::{Options, Row, report};

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

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    let mut panels = Vec::new();
    for g in groups(rows) {
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
                    report::number(p.error)
                ))
                .collect::<Vec<_>>()
                .join("; ")
        ));
        notes.extend(defaults_note(g, &pts, &rbf_front, &front));
        notes.extend(target_notes(rows, g, &rbf_front, &front));
        panels.push(group_panel(rows, g, &pts, &front));
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

/// The defaults against the RBF front at equal error (and every method's), for group `g`.
fn defaults_note(
    g: &Row,
    pts: &[Point<'_>],
    rbf_front: &[Point<'_>],
    front: &[Point<'_>],
) -> Option<String> {
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
    let (ratios, all_ratios) = (ratios_against(rbf_front), ratios_against(front));
    let list = |r: &[f64]| {
        r.iter()
            .map(|r| format!("{r:.2}x"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if ratios.is_empty() {
        return None;
    }
    Some(format!(
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
    ))
}

/// --target-error in group `g`: its cost against the front, and its estimate against the
/// truth.
fn target_notes(
    rows: &[Row],
    g: &Row,
    rbf_front: &[Point<'_>],
    front: &[Point<'_>],
) -> Vec<String> {
    let mut notes = Vec::new();
    for (t, truth, estimate) in targeted(rows, g) {
        let Some(estimate) = estimate else {
            continue;
        };
        let e = t.number("target_error");
        notes.push(format!(
            "{} on {}: --target-error {}: {:.1} ms at step x{} and {} spp; true error {} (estimate {}, estimate / true {:.2}); the RBF front's cheapest at error <= target: {} ({}){}",
            g.device.backend,
            g.data,
            report::number(e),
            t.median(),
            t.setting("step_factor").and_then(|v| v.parse::<f64>().ok()).map_or("?".into(), |f| format!("{f:.3}")),
            t.setting("spp").unwrap_or("?"),
            report::number(truth.median()),
            report::number(estimate.median()),
            estimate.median() / truth.median(),
            front_time_at(rbf_front, e).map_or("none".into(), |f| format!("{f:.1} ms")),
            front_time_at(rbf_front, e).map_or("-".into(), |f| format!("{:.2}x of it; goal 1.5x", t.median() / f)),
            other_method_note(front, rbf_front, e, t.median()),
        ));
    }
    notes
}

/// Group `g`'s panel: one line per configuration through its spp sweep, the front, and
/// --target-error's renders (their time and true error).
fn group_panel(rows: &[Row], g: &Row, pts: &[Point<'_>], front: &[Point<'_>]) -> Panel {
    let mut series = Vec::new();
    let mut by: std::collections::BTreeMap<String, Vec<(f64, f64, f64, f64)>> = Default::default();
    for p in pts {
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
    Panel::Lines {
        title: format!("{} on {}", g.device.backend, g.data),
        x_label: "time to the image (ms)".into(),
        y_label: "RMSE (linear RGB)".into(),
        x_scale: Scale::Log10,
        y_scale: Scale::Log10,
        series,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::Device;

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
