//! Blue (STBN) vs white noise (the paper's Fig. 10b): the frame time over the benchmark orbit
//! with each, and the image error against a converged reference at 1, 4, 16, 64 and 1024
//! samples per pixel, on every backend. (This replaces `benches/noise_rmse.rs`.)
//!
//! The reference is the CPU backend's render of `reference_spp` blue-noise samples with
//! another seed: past 64 frames every cycle of the mask reads it at a new shift
//! (`BlueNoiseMask::cycle_shift`), so it converges like the images it judges, where a
//! white-noise reference of the same cost would be noisier than the 1024-spp blue images.
//! The error is measured for `--seeds` seeds (its spread is over them): RMSE over linear RGBA, raw and after a
//! 1-pixel Gaussian blur (the low-pass an observer's eye applies).

use super::plot::{self, Figure, Panel, Scale};
use super::{
    Ctx, Description, Measurement, Options, Row, StudyError, cameras, device_of, frame_times, value,
};
use crate::accel::ClusterSize;
use crate::backend::BackendKind;
use crate::field::FieldSettings;
use crate::render::RenderSettings;
use crate::values::NoiseKind;

/// The study's title, what the paper found and its settings' columns.
pub const DESCRIPTION: Description = Description {
    title: "Blue vs white noise: frame time and error (paper Fig. 10b)",
    paper: "The paper replaces white noise by spatiotemporal blue noise (STBN) for the random \
            numbers of the march and the free-flight decisions: frames got 1-2x faster on its \
            GPUs (Fig. 10b), and the image converges faster at equal samples per pixel.",
    settings: &[
        "radius",
        "k",
        "noise",
        "width",
        "height",
        "integrator",
        "spp",
        "cameras",
        "reference_spp",
        "step_size",
    ],
};

/// The seed of the reference (the repetitions use seeds 0, 1, ...).
const REFERENCE_SEED: u32 = 1000;

/// Measures every configuration on every data set and backend asked for, recording each row as it
/// is taken.
pub fn measure(ctx: &mut Ctx<'_>) -> Result<(), StudyError> {
    let o = ctx.options;
    let mut spps = o.spps.clone();
    spps.sort_unstable();
    spps.dedup();
    let noises = [NoiseKind::Stbn, NoiseKind::White];
    let bar = ctx.bar(ctx.data.len() * (1 + ctx.backends.len() * 2), "noise");
    let cluster = ClusterSize::new(1).map_err(StudyError::Invalid)?;
    for spec in ctx.data {
        let ds = ctx.load(spec)?;
        let orbit = cameras(ds.bounds, o.cameras);
        let field = FieldSettings::new(ds.attribute.as_deref(), ds.radius);
        let error_settings = |noise, seed| RenderSettings {
            width: o.noise_image.0,
            height: o.noise_image.1,
            integrator: o.integrator,
            noise,
            seed,
            ..RenderSettings::default()
        };
        let reference = {
            let mut s = super::session(BackendKind::Cpu, &ds)?;
            s.show(&ds.series, ds.step, &field, cluster)?;
            s.render(
                &error_settings(NoiseKind::Stbn, REFERENCE_SEED),
                o.reference_spp,
            )?
        };
        let blurred_reference = reference.blurred(1.0);
        bar.inc(1);
        for &kind in ctx.backends {
            let mut session = super::session(kind, &ds)?;
            let device = device_of(&session);
            session.show(&ds.series, ds.step, &field, cluster)?;
            for noise in noises {
                let timed = ctx.frame_settings(noise);
                let dt = session.resolve(&timed)?.step_size;
                let measured = |(w, h): (u32, u32), spp: u32| {
                    let settings = vec![
                        ("radius", value(ds.radius)),
                        ("k", "1".into()),
                        ("noise", noise.name().into()),
                        ("width", w.to_string()),
                        ("height", h.to_string()),
                        ("integrator", format!("{:?}", o.integrator).to_lowercase()),
                        ("spp", spp.to_string()),
                        ("cameras", o.cameras.to_string()),
                        ("reference_spp", o.reference_spp.to_string()),
                        ("step_size", value(dt)),
                    ];
                    Measurement::new(device.clone(), &ds, settings).variant(noise.name())
                };
                let frames = frame_times(&mut session, &timed, &orbit, o.repetitions)?;
                ctx.record(&measured(o.image, 1), "frame", "ms", frames)?;
                // errors[s] = [raw, blurred] per seed at spps[s].
                let mut errors = vec![[Vec::new(), Vec::new()]; spps.len()];
                for seed in 0..o.seeds {
                    let settings = error_settings(noise, seed);
                    let mut done = 0;
                    for (s, &spp) in spps.iter().enumerate() {
                        session.accumulate(&settings, spp - done)?;
                        done = spp;
                        let image = session.image()?;
                        errors[s][0].push(image.rmse(&reference));
                        errors[s][1].push(image.blurred(1.0).rmse(&blurred_reference));
                    }
                }
                for (&spp, [raw, blurred]) in spps.iter().zip(errors) {
                    let m = measured(o.noise_image, spp);
                    ctx.record(&m, "rmse", "linear rgba", raw)?;
                    ctx.record(&m, "rmse_blurred", "linear rgba", blurred)?;
                }
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    Ok(())
}

fn spp_of(r: &Row) -> f64 {
    r.number("spp")
}

/// The page's notes (what the rows say against the paper) and the figure, from the rows measured so
/// far.
pub fn summarise(rows: &[Row], options: &Options) -> (Vec<String>, Figure) {
    let mut notes = Vec::new();
    for blue in rows.iter().filter(|r| r.variant == "stbn") {
        let Some(white) = rows.iter().find(|r| {
            r.variant == "white"
                && r.metric == blue.metric
                && r.device == blue.device
                && r.data == blue.data
                && r.setting("spp") == blue.setting("spp")
        }) else {
            continue;
        };
        match blue.metric {
            "frame" => notes.push(format!(
                "{} on {}: frame {:.3} ms with blue noise, {:.3} ms with white: speed-up of blue noise {:.2}x",
                blue.device.backend,
                blue.data,
                blue.median(),
                white.median(),
                white.median() / blue.median()
            )),
            "rmse" => notes.push(format!(
                "{} on {} at {} spp: RMSE blue {}, white {} (blue / white = {:.2})",
                blue.device.backend,
                blue.data,
                blue.setting("spp").unwrap_or("?"),
                super::report::number(blue.median()),
                super::report::number(white.median()),
                blue.median() / white.median()
            )),
            _ => {}
        }
    }
    let (categories, bars) = plot::bars(
        rows,
        "frame",
        |r| format!("{} ({})", r.device.backend, r.data),
        |r| r.variant.clone(),
    );
    let figure = Figure {
        title: DESCRIPTION.title.into(),
        panels: vec![
            Panel::Lines {
                title: format!(
                    "error vs a {}-spp reference ({}x{} px)",
                    options.reference_spp, options.noise_image.0, options.noise_image.1
                ),
                x_label: "samples per pixel".into(),
                y_label: "RMSE (linear RGBA)".into(),
                x_scale: Scale::Log10,
                y_scale: Scale::Log10,
                series: plot::lines(rows, "rmse", |r| super::line_name(r, rows), spp_of, 1.0),
            },
            Panel::Bars {
                title: "mean frame time over the orbit".into(),
                y_label: "frame time (ms)".into(),
                categories,
                series: bars,
            },
        ],
        caption: vec![
            "Paper (Fig. 10b): blue noise made frames 1-2x faster than white noise on its GPUs; at equal spp blue noise's error is lower once frames accumulate (error: median over the seeds, whiskers min to max)."
                .into(),
            super::timing_caption(options),
        ],
    };
    (notes, figure)
}
