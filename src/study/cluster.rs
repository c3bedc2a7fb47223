//! Cluster size K = 1..16 (the paper's Fig. 9 red, Tables 1 and 2): the frame time over the
//! benchmark orbit, the structure's build and refit times, and its bytes beside the
//! particles' bytes, on every backend.

use super::plot::{self, Figure, Panel, Scale};
use super::{
    Ctx, Description, Measurement, Options, Row, StudyError, build_and_refit_times, cameras,
    frame_columns, frame_times, value, with_frame_settings,
};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::values::NoiseKind;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "Cluster size: frame, build, refit and bytes (paper Fig. 9 red, Tables 1-2)",
    paper: "The paper varies the particles per cluster K from 1 to 16 at a fixed radius: frame \
            time depends far less on K than on the radius (Fig. 9, red); rebuild and refit get \
            faster with K, a refit costing at most about a third of a rebuild (Table 1); and the \
            structure's size falls linearly with K, from about 9x the particles' bytes at K = 1 \
            to about half of them at K = 16 (Table 2).",
    settings: frame_columns!["radius", "k"],
};

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let bar = ctx.bar(
        ctx.data.len() * ctx.backends.len() * o.clusters.len(),
        "cluster",
    );
    ctx.each_session(|ctx, ds, session, device| {
        let orbit = cameras(ds.bounds, o.cameras);
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        let mut wider = field.clone();
        wider.radius *= 1.1;
        for &k in &o.clusters {
            let cluster = ClusterSize::new(k).map_err(StudyError::Invalid)?;
            // Builds (after the untimed warm-up) and refits after a 10% radius change, back and
            // forth (the first untimed).
            let (builds, refits) =
                build_and_refit_times(session, ds, &field, &wider, cluster, o.repetitions)?;
            let memory = session.backend().memory();
            let settings = ctx.frame_settings(NoiseKind::Stbn);
            let dt = session.resolve(&settings)?.step_size;
            let frames = frame_times(session, &settings, &orbit, o.repetitions)?;
            let m = Measurement::new(
                device.clone(),
                ds,
                with_frame_settings(
                    vec![("radius", value(ds.radius)), ("k", k.to_string())],
                    o,
                    dt,
                ),
            );
            ctx.record(&m, "frame", "ms", frames)?;
            ctx.record(&m, "build", "ms", builds)?;
            ctx.record(&m, "refit", "ms", refits)?;
            let bytes = |b: usize| vec![b as f64];
            ctx.record(
                &m,
                "structure_bytes",
                "bytes",
                bytes(memory.structure_bytes),
            )?;
            ctx.record(&m, "particle_bytes", "bytes", bytes(memory.particle_bytes))?;
            bar.inc(1);
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    Ok(())
}

fn k_of(r: &Row) -> f64 {
    r.number("k")
}

fn find<'a>(rows: &'a [Row], like: &Row, metric: &str, k: &str) -> Option<&'a Row> {
    rows.iter().find(|r| {
        r.metric == metric
            && r.device == like.device
            && r.data == like.data
            && r.setting("k") == Some(k)
    })
}

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let name = |r: &Row| super::line_name(r, rows);
    let mut notes = Vec::new();
    for base in rows.iter().filter(|r| r.metric == "build") {
        let k = base.setting("k").unwrap_or("?");
        if let Some(refit) = find(rows, base, "refit", k) {
            notes.push(format!(
                "{} K = {k}: refit {:.3} ms, build {:.3} ms (refit / build = {:.2})",
                name(base),
                refit.median(),
                base.median(),
                refit.median() / base.median()
            ));
        }
    }
    for s1 in rows
        .iter()
        .filter(|r| r.metric == "structure_bytes" && r.setting("k") == Some("1"))
    {
        let p = find(rows, s1, "particle_bytes", "1").map_or(f64::NAN, Row::median);
        let mut line = format!(
            "{}: structure {:.2} MB at K = 1 ({:.2}x the particles' {:.2} MB)",
            name(s1),
            s1.median() / 1e6,
            s1.median() / p,
            p / 1e6
        );
        if let Some(s16) = find(rows, s1, "structure_bytes", "16") {
            line += &format!(
                ", {:.2} MB at K = 16 ({:.2}x the particles'; K = 1 / K = 16 = {:.1}, linear would be 16)",
                s16.median() / 1e6,
                s16.median() / p,
                s1.median() / s16.median()
            );
        }
        notes.push(line);
        if let (Some(f1), Some(f16)) = (find(rows, s1, "frame", "1"), find(rows, s1, "frame", "16"))
        {
            notes.push(format!(
                "{}: frame {:.3} ms at K = 1, {:.3} ms at K = 16 ({:.2}x)",
                name(s1),
                f1.median(),
                f16.median(),
                f16.median() / f1.median()
            ));
        }
    }
    let mut bytes = plot::lines(rows, "structure_bytes", name, k_of, 1e-6);
    for mut p in plot::lines(rows, "particle_bytes", name, k_of, 1e-6) {
        p.label = format!("{} particles", p.label);
        p.dashed = true;
        bytes.push(p);
    }
    let panel = |title: &str, metric: &str, y: &str| Panel::Lines {
        title: title.into(),
        x_label: "particles per cluster K".into(),
        y_label: y.into(),
        x_scale: Scale::Log2,
        y_scale: Scale::Log10,
        series: plot::lines(rows, metric, name, k_of, 1.0),
    };
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: vec![
            panel("frame time over the orbit (Fig. 9 red)", "frame", "frame time (ms)"),
            panel("structure build (Table 1)", "build", "build time (ms)"),
            panel("refit after a radius change (Table 1)", "refit", "refit time (ms)"),
            Panel::Lines {
                title: "structure bytes vs particle bytes (Table 2)".into(),
                x_label: "particles per cluster K".into(),
                y_label: "memory (MB)".into(),
                x_scale: Scale::Log2,
                y_scale: Scale::Log10,
                series: bytes,
            },
        ],
        caption: vec![
            "Paper: frame time depends little on K (Fig. 9 red); builds and refits get faster with K, a refit at most ~1/3 of a rebuild (Table 1); structure bytes fall linearly with K (Table 2; dashed: particle bytes)."
                .into(),
            super::timing_caption(options),
        ],
    };
    (notes, figure)
}
