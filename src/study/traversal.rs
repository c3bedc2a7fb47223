//! Hardware vs software traversal (the paper's Fig. 10a): the same frames through the ash
//! backend's RT pipeline and through its LBVH compute traversal on the same device, beside the
//! wgpu backend's LBVH (the portable path) on every adapter wgpu opens (the paper compares
//! several GPUs; this machine has lavapipe through Vulkan and llvmpipe through GL) and the CPU
//! backend, on the paper's Uniform and Random sets (60K) and the dam break, one particle per
//! cluster.

use super::plot::{self, Figure, Panel};
use super::{
    Ctx, Description, Measurement, Options, Row, StudyError, cameras, device_of, frame_columns,
    frame_times, value,
};
use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::backend::ash_rt::context::Context as AshContext;
use crate::backend::ash_rt::{AshBackend, Traversal};
use crate::backend::wgpu_lbvh::GpuContext;
use crate::field::FieldSettings;
use crate::render::RenderSession;
use crate::values::NoiseKind;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "RT pipeline vs LBVH traversal (paper Fig. 10a)",
    paper: "The paper renders Uniform and Random (60K particles in the unit cube) and the Cabana \
            dam break, with shadows and one particle per cluster, through the RT pipeline and \
            through a software LBVH stack traversal on the same GPU: the RT pipeline is faster \
            on all three vendors, much more on NVIDIA and Intel (MIMD RT cores) than on AMD \
            RDNA 2, and more on Random than on Uniform.",
    settings: frame_columns!["radius", "k", "traversal"],
};

/// How a row's session is made.
enum Maker {
    /// The ash backend on one device, with one traversal.
    Ash(Traversal, std::sync::Arc<AshContext>),
    /// The wgpu backend on one adapter.
    Wgpu(std::sync::Arc<GpuContext>),
    Default,
}

/// The traversals a backend offers, with how to make each one's session: the ash backend's
/// two on its device; the wgpu backend's LBVH on every adapter (the devices are opened once,
/// so every data set runs on the same ones).
/// The wgpu rows' variants name the graphics API, so two adapters (say Vulkan and GL on one
/// GPU) stay apart in the table and the plot.
fn variants(
    kind: BackendKind,
    adapters: &[std::sync::Arc<GpuContext>],
    devices: &[std::sync::Arc<AshContext>],
) -> Vec<(String, Maker)> {
    match kind {
        BackendKind::Ash => devices
            .iter()
            .flat_map(|d| {
                [
                    (
                        "rt pipeline".into(),
                        Maker::Ash(Traversal::RtPipeline, d.clone()),
                    ),
                    (
                        "lbvh compute".into(),
                        Maker::Ash(Traversal::Lbvh, d.clone()),
                    ),
                ]
            })
            .collect(),
        BackendKind::Wgpu => adapters
            .iter()
            .map(|a| {
                (
                    format!("lbvh compute, {:?}", a.info.backend),
                    Maker::Wgpu(a.clone()),
                )
            })
            .collect(),
        _ => vec![("bvh".into(), Maker::Default)],
    }
}

/// A device on every wgpu adapter that opens (those that do not are logged).
fn wgpu_adapters() -> Result<Vec<std::sync::Arc<GpuContext>>, StudyError> {
    let mut out = Vec::new();
    for opened in GpuContext::on_every_adapter() {
        match opened {
            Ok(ctx) => out.push(std::sync::Arc::new(ctx)),
            Err(e) => tracing::warn!("traversal: a wgpu adapter did not open: {e}"),
        }
    }
    if out.is_empty() {
        // The backend's own error, which says how to get an adapter.
        crate::backend::wgpu_lbvh::WgpuBackend::new()?;
        return Err(StudyError::Invalid("no wgpu adapter opened".into()));
    }
    Ok(out)
}

/// A context on every Vulkan device with ray-tracing pipelines (those that fail to open are
/// logged).
fn ash_devices() -> Result<Vec<std::sync::Arc<AshContext>>, StudyError> {
    let mut out = Vec::new();
    let mut first_error = None;
    for opened in crate::backend::ash_rt::context::on_every_device() {
        match opened {
            Ok(ctx) => out.push(ctx),
            Err(e) => {
                tracing::warn!("traversal: a Vulkan device did not open: {e}");
                first_error.get_or_insert(e);
            }
        }
    }
    match (out.is_empty(), first_error) {
        (true, Some(e)) => Err(e.into()),
        (true, None) => Err(StudyError::Invalid("no Vulkan device opened".into())),
        (false, _) => Ok(out),
    }
}

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let adapters = if ctx.backends.contains(&BackendKind::Wgpu) {
        wgpu_adapters()?
    } else {
        Vec::new()
    };
    let devices = if ctx.backends.contains(&BackendKind::Ash) {
        ash_devices()?
    } else {
        Vec::new()
    };
    let total: usize = ctx
        .backends
        .iter()
        .map(|&b| variants(b, &adapters, &devices).len())
        .sum();
    let bar = ctx.bar(ctx.data.len() * total, "traversal");
    let cluster = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let orbit = cameras(ds.bounds, o.cameras);
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        for &kind in ctx.backends {
            for (variant, maker) in variants(kind, &adapters, &devices) {
                let mut session = match maker {
                    Maker::Ash(t, device) => {
                        let mut b = AshBackend::on(device)?;
                        b.set_traversal(t);
                        RenderSession::new(Box::new(b), &ds.series)
                    }
                    Maker::Wgpu(device) => RenderSession::new(
                        Box::new(crate::backend::wgpu_lbvh::WgpuBackend::with_context(device)),
                        &ds.series,
                    ),
                    Maker::Default => super::session(kind, &ds)?,
                };
                let device = device_of(&session);
                session.show(&ds.series, ds.step, &field, cluster)?;
                let settings = ctx.frame_settings(NoiseKind::Stbn);
                let dt = session.resolve(&settings)?.step_size;
                let values = frame_times(&mut session, &settings, &orbit, o.repetitions)?;
                let own = vec![
                    ("radius", value(ds.radius)),
                    ("k", "1".into()),
                    ("traversal", variant.clone()),
                ];
                let m = Measurement::new(device, &ds, super::with_frame_settings(own, o, dt))
                    .variant(variant);
                ctx.record(&m, "frame", "ms", values)?;
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
