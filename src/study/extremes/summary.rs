//! The extremes study's rows as the table and the figure of its report.

use super::*;

/// A case's x on its sweep's axis.
pub(super) fn x_of(r: &Row) -> f64 {
    let get = |k| r.number(k);
    match r.setting("family") {
        Some("radius") => get("radius_fraction"),
        // A log axis has no 0: offset 0 is drawn at 1.
        Some("offset") => get("offset").max(1.0),
        _ => get("weight"),
    }
}

/// Errors below this are drawn at it (the CPU's automatic choice of f64 is the reference
/// itself, with no error at all).
pub(super) const PLOT_FLOOR: f64 = 1e-10;

pub(super) fn inputs_of(r: &Row) -> &str {
    r.setting("inputs").unwrap_or("")
}

pub(super) fn weight_of(r: &Row) -> f64 {
    r.setting("weight")
        .and_then(|v| v.parse().ok())
        .unwrap_or(1.0)
}

/// The largest `metric` over `rows` of `series` with `inputs`, and whether any was measured.
pub(super) fn worst(
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

pub(super) fn sci(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.1e}")
    }
}

/// The series (backend and precision) in the order measured.
pub(super) fn series_names(rows: &[Row]) -> Vec<String> {
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

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let notes = series_names(rows)
        .iter()
        .map(|s| series_note(rows, s))
        .collect();
    let count = options.count.unwrap_or(DEFAULT_COUNT);
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: sweep_panels(rows),
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

/// Series `s`'s errors for each kind of inputs (where terms stay normal, against the goal,
/// and over all cases), whether its stated bound held, and its non-finite values.
fn series_note(rows: &[Row], s: &str) -> String {
    let normal = |r: &Row| !reaches_denormals(weight_of(r));
    let mut parts = Vec::new();
    for inputs in Inputs::BOTH.map(Inputs::name) {
        let pick = |metric, keep: &dyn Fn(&Row) -> bool| worst(rows, s, inputs, metric, keep);
        let (Some(phi), Some(theta)) =
            (pick("phi_rel_max", &|_| true), pick("theta_max", &|_| true))
        else {
            continue;
        };
        let (phi_normal, theta_normal) = (pick("phi_rel_max", &normal), pick("theta_max", &normal));
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
    format!("`{s}`: {}", parts.join("; "))
}

/// A panel for each sweep and kind of inputs: the largest relative Phi error of each series
/// over the swept value, and the goal.
fn sweep_panels(rows: &[Row]) -> Vec<Panel> {
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
            let mut series =
                crate::study::plot::lines(&selected, "phi_rel_max", Row::series, x_of, 1.0);
            let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
            if let Some(across) = crate::study::plot::span(xs) {
                let label = format!("goal {}", sci(GOAL));
                series.push(Series::level(label, across, (GOAL, GOAL, GOAL)));
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
    panels
}
