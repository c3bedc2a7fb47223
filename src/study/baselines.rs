//! Our method against the paper's two Table 3 baselines: emission-absorption frames with the
//! structure rebuilt every frame (time-series exploration: a new step each frame) against a
//! grid re-voxelised every frame and ray-marched with the same integrator, for each grid size,
//! and against Knoll et al.'s RT splatter with its BVH rebuilt every frame, for each buffer
//! size k; and each one's image error against a converged RBF reference, so the grid's
//! quantisation and the splatter's compositing and overflow are numbers (with the share of
//! hits the splatter's full buffers lost).
//!
//! The RBF and splatter rows run on every backend asked for (the splatter collects its hits
//! through the CPU BVH, [`crate::field::splat`], the RT pipeline on ash and the LBVH on wgpu;
//! only the CPU counts the hits it loses), and so do the voxel rows: each backend splats its
//! own grid and marches it ([`crate::backend::voxel`]; the CPU scatters in f64, the GPU
//! backends add with atomics on the device), voxelisation and march timed apart.

use super::plot::{self, Figure, Panel, Scale};
use super::{
    Ctx, Dataset, Description, Device, Measurement, Options, Row, StudyError, cameras, device_of,
};
use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::field::FieldSettings;
use crate::field::splat::SplatCounts;
use crate::render::{RenderSession, RenderSettings};
use crate::scene::Camera;
use crate::values::{Image, Integrator, NoiseKind};

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "RBF vs voxel grid and splatter, rebuilt every frame (paper Table 3)",
    paper: "The paper compares, for emission-absorption at 1 spp with the structure rebuilt every \
            frame (time-series exploration), its method with a 512^3 voxel grid re-voxelised \
            every frame and with Knoll et al.'s RT splatter (k = 15): voxelisation dominates the \
            voxel renderer (38x slower than ours on Viscus), the splatter was 5x slower on Viscus \
            and 1.3x faster on the surface-like Nozzle, and the grid's quantisation shows on fine \
            structures.",
    settings: &[
        "method",
        "grid",
        "radius",
        "k",
        "splat_k",
        "width",
        "height",
        "integrator",
        "noise",
        "spp",
        "cameras",
        "reference_spp",
    ],
};

/// Samples per pixel of the images whose error is measured (at most the reference's).
const ERROR_SPP: u32 = 64;
const REFERENCE_SEED: u32 = 1000;

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let bar = ctx.bar(
        ctx.data.len() * (1 + ctx.backends.len() * (1 + o.splat_ks.len() + o.voxel_grids.len())),
        "baselines",
    );
    let cluster = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    let timed = RenderSettings {
        integrator: Integrator::Ea,
        ..ctx.frame_settings(NoiseKind::Stbn)
    };
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let bench = Bench::new(o, &ds, cluster, timed.clone())?;
        bar.inc(1);
        for &kind in ctx.backends {
            let mut session = super::session(kind, &ds)?;
            let device = device_of(&session);
            session.show(&ds.series, ds.step, &bench.field, cluster)?;
            bench.rbf(ctx, &mut session, &device)?;
            bar.inc(1);
            for &n in &o.voxel_grids {
                bench.voxel_grid(ctx, &mut session, &device, n)?;
                bar.inc(1);
            }
            // The splatter, its structure (over single particles, as Knoll et al.'s) rebuilt
            // every frame. The CPU's splats through its f64 BVH; the GPU backends' at the
            // scene's precision.
            let mut splatter = super::session(kind, &ds)?;
            if kind == BackendKind::Cpu {
                splatter.set_precision(crate::backend::Precision::F64);
            }
            splatter.show(&ds.series, ds.step, &bench.field, cluster)?;
            for &k in &o.splat_ks {
                bench.splatter(ctx, &mut splatter, &device, k)?;
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// What every method on one data set is measured with: the orbit, the timed frames' and the
/// error images' settings, and the converged RBF reference the errors are taken against.
struct Bench<'a> {
    o: &'a Options,
    ds: &'a Dataset,
    field: FieldSettings,
    orbit: Vec<Camera>,
    timed: RenderSettings,
    error_spp: u32,
    reference: Image,
}

impl<'a> Bench<'a> {
    /// The bench for `ds` with frames timed under `timed`, its reference rendered on the CPU.
    fn new(
        o: &'a Options,
        ds: &'a Dataset,
        cluster: ClusterSize,
        timed: RenderSettings,
    ) -> Result<Self, StudyError> {
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        let mut s = super::session(BackendKind::Cpu, ds)?;
        s.show(&ds.series, ds.step, &field, cluster)?;
        let reference = s.render(&error_image(o, REFERENCE_SEED), o.reference_spp)?;
        Ok(Bench {
            o,
            ds,
            field,
            orbit: cameras(ds.bounds, o.cameras),
            timed,
            error_spp: ERROR_SPP.min(o.reference_spp),
            reference,
        })
    }

    /// The timed frame from camera `c`.
    fn at(&self, c: Camera) -> RenderSettings {
        RenderSettings {
            camera: Some(c),
            ..self.timed.clone()
        }
    }

    /// The settings of an image whose error is measured.
    fn error_image(&self, seed: u32) -> RenderSettings {
        error_image(self.o, seed)
    }

    /// Over each repetition, the mean over the orbit (ms) of the frames' sum, structure and
    /// march times, `frame(repetition, camera)` giving each frame's two (s).
    fn orbit_means(
        &self,
        mut frame: impl FnMut(usize, Camera) -> Result<(f64, f64), StudyError>,
    ) -> Result<[Vec<f64>; 3], StudyError> {
        let (mut total, mut structure, mut march) = (Vec::new(), Vec::new(), Vec::new());
        for repetition in 0..self.o.repetitions {
            let (mut b, mut m) = (0.0, 0.0);
            for &c in &self.orbit {
                let (db, dm) = frame(repetition, c)?;
                b += db;
                m += dm;
            }
            let n = self.orbit.len() as f64;
            structure.push(1e3 * b / n);
            march.push(1e3 * m / n);
            total.push(1e3 * (b + m) / n);
        }
        Ok([total, structure, march])
    }

    /// Records a method's rows: `timed` under the timed frames' settings, then its error
    /// images' RMSE (at `error_spp`). A row without values (a backend that does not count
    /// lost hits) is left out.
    fn record(
        &self,
        ctx: &mut Ctx<'_>,
        device: &Device,
        variant: &str,
        grid: &str,
        timed: Vec<(&'static str, &'static str, Vec<f64>)>,
        (error_spp, rmse): (u32, Vec<f64>),
    ) -> Result<(), StudyError> {
        let timed_settings = self.settings(variant, grid, self.o.image, 1);
        let error_settings = self.settings(variant, grid, self.o.noise_image, error_spp);
        let rows = timed
            .into_iter()
            .map(|(metric, unit, values)| (metric, unit, timed_settings.clone(), values))
            .chain([("rmse", "linear rgba", error_settings, rmse)]);
        for (metric, unit, settings, values) in rows {
            if values.is_empty() {
                continue;
            }
            let m = Measurement::new(device.clone(), self.ds, settings).variant(variant);
            ctx.record(&m, metric, unit, values)?;
        }
        Ok(())
    }

    /// A row's settings, for `variant` ("rbf", "voxel 512", "splat 15") on `grid` at an image
    /// of `(w, h)` and `spp`.
    fn settings(
        &self,
        variant: &str,
        grid: &str,
        (w, h): (u32, u32),
        spp: u32,
    ) -> Vec<(&'static str, String)> {
        let splat_k = variant
            .strip_prefix("splat ")
            .map_or("-".to_owned(), str::to_owned);
        vec![
            (
                "method",
                variant.split(' ').next().unwrap_or(variant).to_owned(),
            ),
            ("grid", grid.to_owned()),
            ("radius", super::value(self.ds.radius)),
            ("k", "1".to_owned()),
            ("splat_k", splat_k),
            ("width", w.to_string()),
            ("height", h.to_string()),
            ("integrator", "ea".to_owned()),
            ("noise", "stbn".to_owned()),
            ("spp", spp.to_string()),
            ("cameras", self.o.cameras.to_string()),
            ("reference_spp", self.o.reference_spp.to_string()),
        ]
    }

    /// RBF: a rebuild and a frame per camera (the warm-up first).
    fn rbf(
        &self,
        ctx: &mut Ctx<'_>,
        session: &mut RenderSession,
        device: &Device,
    ) -> Result<(), StudyError> {
        session.backend_mut().build()?;
        session.accumulate(&self.at(self.orbit[0]), 1)?;
        let [total, build, march] = self.orbit_means(|_, c| {
            session.backend_mut().build()?;
            let b = session.backend().timings().build.as_secs_f64();
            session.accumulate(&self.at(c), 1)?;
            Ok((b, session.backend().timings().frame.as_secs_f64()))
        })?;
        let mut errors = Vec::new();
        for seed in 0..self.o.seeds {
            let image = session.render(&self.error_image(seed), self.error_spp)?;
            errors.push(image.rmse(&self.reference));
        }
        let timed = vec![
            ("frame", "ms", total),
            ("structure", "ms", build),
            ("march", "ms", march),
        ];
        self.record(ctx, device, "rbf", "-", timed, (self.error_spp, errors))
    }

    /// The voxel grid of `n` cells along the longest side, splatted and marched by the backend
    /// itself (the GPU backends on the device, timed by its timestamps where it has them).
    fn voxel_grid(
        &self,
        ctx: &mut Ctx<'_>,
        session: &mut RenderSession,
        device: &Device,
        n: usize,
    ) -> Result<(), StudyError> {
        let frame0 = session.frame_params(&self.at(self.orbit[0]), 0)?;
        // The warm-up: one voxelisation and frame.
        session.backend_mut().voxelize(&frame0, n)?;
        session.backend_mut().reset();
        session.backend_mut().render_voxels(&frame0)?;
        let [total, voxelise, march] = self.orbit_means(|_, c| {
            let params = session.frame_params(&self.at(c), 0)?;
            session.backend_mut().voxelize(&params, n)?;
            let v = session.backend().timings().voxelize.as_secs_f64();
            session.backend_mut().reset();
            session.backend_mut().render_voxels(&params)?;
            Ok((v, session.backend().timings().frame.as_secs_f64()))
        })?;
        let mut errors = Vec::new();
        let params = session.frame_params(&self.error_image(0), 0)?;
        session.backend_mut().voxelize(&params, n)?;
        for seed in 0..self.o.seeds {
            session.backend_mut().reset();
            for f in 0..self.error_spp {
                let params = session.frame_params(&self.error_image(seed), f)?;
                session.backend_mut().render_voxels(&params)?;
            }
            errors.push(session.backend_mut().image()?.rmse(&self.reference));
        }
        let timed = vec![
            ("frame", "ms", total),
            ("structure", "ms", voxelise),
            ("march", "ms", march),
        ];
        let variant = format!("voxel {n}");
        self.record(
            ctx,
            device,
            &variant,
            &n.to_string(),
            timed,
            (self.error_spp, errors),
        )
    }

    /// The splatter with `k` hits a slab, its structure rebuilt every frame; deterministic, so
    /// one frame is its image.
    fn splatter(
        &self,
        ctx: &mut Ctx<'_>,
        splatter: &mut RenderSession,
        device: &Device,
        k: usize,
    ) -> Result<(), StudyError> {
        splatter.backend_mut().build()?;
        let warm_up = splatter.frame_params(&self.at(self.orbit[0]), 0)?;
        splatter.backend_mut().render_splat(&warm_up, k)?;
        // Each repetition's hit counts, while every frame of it counted them.
        let mut counts = vec![Some(SplatCounts::default()); self.o.repetitions];
        let [total, build, composite] = self.orbit_means(|repetition, c| {
            splatter.backend_mut().build()?;
            let b = splatter.backend().timings().build.as_secs_f64();
            let params = splatter.frame_params(&self.at(c), 0)?;
            splatter.backend_mut().reset();
            let frame_counts = splatter.backend_mut().render_splat(&params, k)?;
            counts[repetition] = counts[repetition].zip(frame_counts).map(|(a, b)| a + b);
            Ok((b, splatter.backend().timings().frame.as_secs_f64()))
        })?;
        let lost = counts
            .into_iter()
            .flatten()
            .map(|c| 100.0 * c.lost_fraction())
            .collect();
        let params = splatter.frame_params(&self.error_image(0), 0)?;
        splatter.backend_mut().reset();
        splatter.backend_mut().render_splat(&params, k)?;
        let error = splatter.backend_mut().image()?.rmse(&self.reference);
        let timed = vec![
            ("frame", "ms", total),
            ("structure", "ms", build),
            ("march", "ms", composite),
            ("lost", "% of hits", lost),
        ];
        let variant = format!("splat {k}");
        self.record(ctx, device, &variant, "-", timed, (1, vec![error]))
    }
}

/// The settings of an image whose error is measured.
fn error_image(o: &Options, seed: u32) -> RenderSettings {
    RenderSettings {
        width: o.noise_image.0,
        height: o.noise_image.1,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        seed,
        ..RenderSettings::default()
    }
}

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let category = |r: &Row| format!("{} {}", r.device.backend, r.variant);
    let (categories, mut series) = plot::bars(rows, "frame", category, |_| {
        "frame (structure + march)".into()
    });
    let (_, structure) = plot::bars(rows, "structure", category, |_| {
        "structure (rebuild or voxelise)".into()
    });
    series.extend(structure);
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: vec![
            Panel::Bars {
                title: "EA frame with the structure rebuilt (splat k: hits per slab)".into(),
                y_label: "time per frame (ms)".into(),
                categories,
                series,
            },
            Panel::Lines {
                title: format!("error vs a {}-spp RBF reference", options.reference_spp),
                x_label: "voxel grid (cells along the longest side)".into(),
                y_label: "RMSE (linear RGBA)".into(),
                x_scale: Scale::Log2,
                y_scale: Scale::Log10,
                series: error_lines(rows),
            },
        ],
        caption: vec![
            "Paper (Table 3): with a rebuild every frame, ours was 38x faster than a re-voxelised 512^3 grid on Viscus (voxelising dominates) and 5x faster than Knoll et al.'s splatter (k = 15); the grid's quantisation shows on fine structures."
                .into(),
            format!(
                "{}x{} px EA, mean over {} orbit cameras, median of {} repetitions; each backend voxelises and marches its own grid.",
                options.image.0, options.image.1, options.cameras, options.repetitions
            ),
        ],
    };
    (notes(rows), figure)
}

/// Each baseline's frame time against ours and its structure's share of it, the hits the
/// splatter lost, and every error.
fn notes(rows: &[Row]) -> Vec<String> {
    let mut notes = Vec::new();
    for ours in rows
        .iter()
        .filter(|r| r.variant == "rbf" && r.metric == "frame")
    {
        for voxel in rows.iter().filter(|r| {
            r.metric == "frame"
                && r.data == ours.data
                && r.device.backend == ours.device.backend
                && r.variant != "rbf"
        }) {
            let share = rows
                .iter()
                .find(|r| {
                    r.metric == "structure"
                        && r.variant == voxel.variant
                        && r.data == voxel.data
                        && r.device.backend == voxel.device.backend
                })
                .map_or(f64::NAN, |s| s.median() / voxel.median());
            notes.push(format!(
                "{} on {}: RBF with a rebuild {:.3} ms per frame, {} {:.3} ms ({:.2}x ours; {} is {:.0}% of it)",
                ours.data,
                ours.device.backend,
                ours.median(),
                voxel.variant,
                voxel.median(),
                voxel.median() / ours.median(),
                if voxel.variant.starts_with("voxel") {
                    "voxelising"
                } else {
                    "the structure's rebuild"
                },
                100.0 * share
            ));
        }
    }
    for r in rows.iter().filter(|r| r.metric == "lost") {
        notes.push(format!(
            "{} {} on {}: {:.2}% of the hits lost to full buffers (median over repetitions)",
            r.device.backend,
            r.variant,
            r.data,
            r.median()
        ));
    }
    for r in rows.iter().filter(|r| r.metric == "rmse") {
        notes.push(format!(
            "{} {} on {}: RMSE {} against the converged RBF reference at {} spp",
            r.device.backend,
            r.variant,
            r.data,
            super::report::number(r.median()),
            r.setting("spp").unwrap_or("?")
        ));
    }
    notes
}

/// The voxel grids' error over the grid size; each other method's error as a dashed level.
fn error_lines(rows: &[Row]) -> Vec<plot::Series> {
    let grid_of = |r: &Row| r.number("grid");
    let voxel_rows: Vec<Row> = rows
        .iter()
        .filter(|r| r.variant.starts_with("voxel"))
        .cloned()
        .collect();
    let mut errors = plot::lines(
        &voxel_rows,
        "rmse",
        |r| format!("{} voxel grid ({})", r.device.backend, r.data),
        grid_of,
        1.0,
    );
    let grids = voxel_rows.iter().map(grid_of).filter(|g| g.is_finite());
    let across = plot::span(grids).unwrap_or((1.0, 2.0));
    for r in rows
        .iter()
        .filter(|r| !r.variant.starts_with("voxel") && r.metric == "rmse")
    {
        let label = format!(
            "{} {}, {} spp ({})",
            r.device.backend,
            r.variant,
            r.setting("spp").unwrap_or("?"),
            r.data
        );
        errors.push(plot::Series::level(
            label,
            across,
            (r.median(), r.min(), r.max()),
        ));
    }
    errors
}
