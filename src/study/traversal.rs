//! Hardware vs software traversal (the paper's Fig. 10a): the same frames through the ash
//! backend's RT pipeline and through its LBVH compute traversal on the same device, beside the
//! wgpu backend's LBVH (the portable path) and the CPU backend, on the paper's Uniform and
//! Random sets (60K) and the dam break, one particle per cluster.

use super::plot::{self, Figure, Panel};
use super::{Ctx, Description, Options, Row, StudyError, cameras, device_of, frame_times, value};
use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::backend::ash_rt::{AshBackend, Traversal};
use crate::field::FieldSettings;
use crate::render::RenderSession;
use crate::values::NoiseKind;

pub const DESCRIPTION: Description = Description {
    title: "RT pipeline vs LBVH traversal (paper Fig. 10a)",
    paper: "The paper renders Uniform and Random (60K particles in the unit cube) and the Cabana \
            dam break, with shadows and one particle per cluster, through the RT pipeline and \
            through a software LBVH stack traversal on the same GPU: the RT pipeline is faster \
            on all three vendors, much more on NVIDIA and Intel (MIMD RT cores) than on AMD \
            RDNA 2, and more on Random than on Uniform.",
    settings: &[
        "radius",
        "k",
        "traversal",
        "width",
        "height",
        "integrator",
        "noise",
        "spp",
        "cameras",
        "step_size",
    ],
};

/// The traversals a backend offers: (variant name, how to make its session).
fn variants(kind: BackendKind) -> Vec<(&'static str, Option<Traversal>)> {
    match kind {
        BackendKind::Ash => vec![
            ("rt pipeline", Some(Traversal::RtPipeline)),
            ("lbvh compute", Some(Traversal::Lbvh)),
        ],
        BackendKind::Wgpu => vec![("lbvh compute", None)],
        _ => vec![("bvh", None)],
    }
}

pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let total: usize = ctx.backends.iter().map(|&b| variants(b).len()).sum();
    let bar = ctx.bar(ctx.data.len() * total, "traversal");
    let cluster = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let orbit = cameras(ds.bounds, o.cameras);
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        for &kind in ctx.backends {
            for (variant, traversal) in variants(kind) {
                let mut session = match traversal {
                    Some(t) => {
                        let mut b = AshBackend::new()?;
                        b.set_traversal(t);
                        RenderSession::new(Box::new(b), &ds.series)
                    }
                    None => super::session(kind, &ds)?,
                };
                let device = device_of(&session);
                session.show(&ds.series, ds.step, &field, cluster)?;
                let settings = ctx.frame_settings(NoiseKind::Stbn);
                let dt = session.resolve(&settings)?.step_size;
                let values = frame_times(&mut session, &settings, &orbit, o.repetitions)?;
                ctx.recorder.record(Row {
                    device,
                    variant: variant.into(),
                    data: ds.name.clone(),
                    step: ds.step,
                    n: ds.n,
                    settings: super::with_frame_settings(
                        vec![
                            ("radius", value(ds.radius)),
                            ("k", "1".into()),
                            ("traversal", variant.into()),
                        ],
                        o,
                        dt,
                    ),
                    metric: "frame",
                    unit: "ms",
                    values,
                })?;
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    for rt in rows.iter().filter(|r| r.variant == "rt pipeline") {
        let same_device = |r: &&Row| r.data == rt.data && r.device == rt.device;
        if let Some(lbvh) = rows
            .iter()
            .filter(same_device)
            .find(|r| r.variant == "lbvh compute")
        {
            notes.push(format!(
                "{} ({}): RT pipeline {:.3} ms, LBVH compute {:.3} ms on the same device: speed-up of the RT pipeline {:.2}x",
                rt.data,
                rt.device.adapter,
                rt.median(),
                lbvh.median(),
                lbvh.median() / rt.median()
            ));
        }
        for other in rows
            .iter()
            .filter(|r| r.data == rt.data && r.device.backend != "ash")
        {
            notes.push(format!(
                "{}: {} {} {:.3} ms, {:.2}x the RT pipeline's time",
                rt.data,
                other.device.backend,
                other.variant,
                other.median(),
                other.median() / rt.median()
            ));
        }
    }
    let (categories, series) = plot::bars(rows, "frame", |r| r.data.clone(), Row::series);
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: vec![Panel::Bars {
            title: "mean frame time over the orbit, K = 1".into(),
            y_label: "frame time (ms)".into(),
            categories,
            series,
        }],
        caption: vec![
            "Paper (Fig. 10a): the RT pipeline beats a software LBVH traversal on the same GPU (most on NVIDIA and Intel, and more on Random than Uniform). Lavapipe emulates RT on the CPU: it cannot show this."
                .into(),
            super::timing_caption(options),
        ],
    };
    (notes, figure)
}
