//! Frame time against the global radius at K = 1 and K = 16 (the paper's Fig. 9, blue): the
//! mean over the benchmark orbit of one-sample frames with shadows, for radii from half to
//! twice the data set's radius. The march step is the data set's own throughout (the one
//! resolved at its radius), so every frame takes the same samples and the sweep measures what
//! a sample costs as more particles overlap it.

use super::plot::{self, Figure, Panel, Scale};
use super::{
    Ctx, Description, Measurement, Options, Row, StudyError, cameras, frame_columns, frame_times,
    value, with_frame_settings,
};
use crate::accel::ClusterSize;
use crate::field::FieldSettings;
use crate::render::RenderSettings;
use crate::values::NoiseKind;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "Frame time vs radius (paper Fig. 9, blue)",
    paper: "The paper (Fig. 9, blue lines) renders each data set from 50 orbit cameras at radii \
            across a sensible range, with 1 (solid) and 16 (dotted) particles per cluster: frame \
            time rises with the radius, as more particles overlap every sample; clustering made \
            frames faster on three of its five data sets.",
    settings: frame_columns!["radius", "radius_pct_diagonal", "radius_factor", "k"],
};

/// The cluster sizes of Fig. 9's blue lines.
const KS: [u32; 2] = [1, 16];

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let bar = ctx.bar(
        ctx.data.len() * ctx.backends.len() * KS.len() * o.radius_factors.len(),
        "radius",
    );
    ctx.each_session(|ctx, ds, session, device| {
        let orbit = cameras(ds.bounds, o.cameras);
        // One march step for the whole sweep, the data set's own (at its radius): the samples
        // per ray stay the same, so the sweep shows what more overlap per sample costs.
        let at_own = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        session.show(
            &ds.series,
            ds.step,
            &at_own,
            ClusterSize::new(1).map_err(StudyError::Invalid)?,
        )?;
        let settings = RenderSettings {
            step_size: Some(
                session
                    .resolve(&ctx.frame_settings(NoiseKind::Stbn))?
                    .step_size,
            ),
            ..ctx.frame_settings(NoiseKind::Stbn)
        };
        for k in KS {
            let cluster = ClusterSize::new(k).map_err(StudyError::Invalid)?;
            for &factor in &o.radius_factors {
                let radius = ds.radius * factor;
                let field = FieldSettings::new(ds.attribute.as_deref(), radius);
                session.show(&ds.series, ds.step, &field, cluster)?;
                let dt = session.resolve(&settings)?.step_size;
                let values = frame_times(session, &settings, &orbit, o.repetitions)?;
                let own = vec![
                    ("radius", value(radius)),
                    (
                        "radius_pct_diagonal",
                        format!("{:.4}", 100.0 * radius / ds.bounds.diagonal()),
                    ),
                    ("radius_factor", format!("{factor}")),
                    ("k", k.to_string()),
                ];
                let m = Measurement::new(device.clone(), ds, with_frame_settings(own, o, dt))
                    .variant(format!("K={k}"));
                ctx.record(&m, "frame", "ms", values)?;
                bar.inc(1);
            }
        }
        Ok(())
    })?;
    bar.finish_and_clear();
    Ok(())
}

fn pct(r: &Row) -> f64 {
    r.number("radius_pct_diagonal")
}

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let series = plot::lines(rows, "frame", |r| super::line_name(r, rows), pct, 1.0);
    let mut notes = Vec::new();
    for s in &series {
        if let (Some(first), Some(last)) = (s.points.first(), s.points.last())
            && s.points.len() > 1
        {
            notes.push(format!(
                "{}: {:.3} ms at {:.2}% of the diagonal, {:.3} ms at {:.2}% ({:.2}x for {:.1}x the radius)",
                s.label,
                first.1,
                first.0,
                last.1,
                last.0,
                last.1 / first.1,
                last.0 / first.0
            ));
        }
    }
    // K = 16 against K = 1 at each data set's own radius.
    for r16 in rows
        .iter()
        .filter(|r| r.variant == "K=16" && r.setting("radius_factor") == Some("1"))
    {
        if let Some(r1) = rows.iter().find(|r| {
            r.variant == "K=1"
                && r.device == r16.device
                && r.data == r16.data
                && r.setting("radius_factor") == Some("1")
        }) {
            notes.push(format!(
                "{} on {} at the data set's radius: K = 16 takes {:.2}x the frame time of K = 1",
                r16.device.backend,
                r16.data,
                r16.median() / r1.median()
            ));
        }
    }
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: vec![Panel::Lines {
            title: "mean frame time over the orbit".into(),
            x_label: "global radius (% of the bounding-box diagonal)".into(),
            y_label: "frame time (ms)".into(),
            x_scale: Scale::Linear,
            y_scale: Scale::Linear,
            series,
        }],
        caption: vec![
            "Paper (Fig. 9, blue): frame time rises with the radius (more particles overlap each sample); K = 16 was faster than K = 1 on three of its five data sets."
                .into(),
            super::timing_caption(options),
        ],
    };
    (notes, figure)
}
