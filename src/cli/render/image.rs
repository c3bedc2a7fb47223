//! One image of the step a session shows, made by the render's method: the paper's RBF
//! (a set number of samples, to a target error or time, or the converged reference), or a
//! Table 3 baseline (voxel grid, splatter).

use indicatif::ProgressBar;

use super::{RenderArgs, Setup};
use crate::backend::voxel::VoxelGeometry;
use crate::render::converged::{Reference, ReferenceOptions, converged_reference};
use crate::render::target::{Target, Targeted, render_to_target};
use crate::render::{Method, RenderSession};
use crate::values::Image;

/// An image, and what it used where it chose: the step size and samples of a targeted or
/// reference render.
pub(super) struct Rendered {
    pub image: Image,
    pub step_size: Option<f64>,
    pub spp: u32,
}

/// Renders step `step` (the one `session` shows) by `setup`'s method, counting on `bar`.
pub(super) fn render(
    session: &mut RenderSession,
    setup: &Setup,
    args: &RenderArgs,
    step: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Rendered> {
    let (settings, spp) = (&setup.settings, setup.spp);
    let fixed = |image| Rendered {
        image,
        step_size: None,
        spp,
    };
    Ok(match setup.method {
        Method::Rbf if args.reference => reference(setup, args, step, bar)?,
        Method::Rbf if setup.target.is_some() => {
            let target = setup.target.as_ref().expect("checked");
            targeted(session, setup, target, step, bar)?
        }
        Method::Rbf => {
            for _ in 0..spp {
                session.accumulate(settings, 1)?;
                bar.inc(1);
            }
            fixed(session.image()?)
        }
        Method::Voxel => fixed(voxel(session, setup, step, bar)?),
        Method::Splat => fixed(splat(session, setup, step, bar)?),
    })
}

/// The converged reference of step `step` (from the cache where it was made before).
fn reference(
    setup: &Setup,
    args: &RenderArgs,
    step: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Rendered> {
    let resolved = &setup.resolved;
    let options = ReferenceOptions {
        tolerance: args.reference_tolerance,
        ..ReferenceOptions::default()
    };
    let reference = converged_reference(
        &resolved.series,
        step,
        &resolved.field,
        resolved.cluster,
        &setup.settings,
        &options,
    )?;
    say_reference(step, &reference);
    bar.inc(1);
    Ok(Rendered {
        image: reference.image().clone(),
        step_size: Some(reference.step_size),
        spp: reference.spp,
    })
}

/// Says how converged the reference of step `step` is, and at what step and samples.
pub(super) fn say_reference(step: usize, reference: &Reference) {
    tracing::info!(
        "reference of step {step}: step size {:.4e}, {} spp; doubling the samples changes it by {:.2e}, halving the step by {} (tolerance {:.1e}, {}){}",
        reference.step_size,
        reference.spp,
        reference.spp_change,
        reference
            .step_change
            .map_or("(not tried: the sample bound)".into(), |c| format!(
                "{c:.2e}"
            )),
        reference.tolerance,
        if reference.converged {
            "converged"
        } else {
            "NOT converged"
        },
        if reference.from_cache {
            ", from the cache"
        } else {
            ""
        },
    );
}

/// An image rendered to a target error or within a time budget, with its estimate said.
fn targeted(
    session: &mut RenderSession,
    setup: &Setup,
    target: &Target,
    step: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Rendered> {
    let done = render_to_target(session, &setup.settings, target)?;
    say_targeted(step, target, &done);
    bar.inc(1);
    Ok(Rendered {
        image: done.image,
        step_size: Some(done.step_size),
        spp: done.spp,
    })
}

/// The log line of a targeted render of step `step`: its estimate, and how it got there.
pub(super) fn say_targeted(step: usize, target: &Target, done: &Targeted) {
    tracing::info!(
        "step {step}: estimated error {:.3e} ({}{}) at step size {:.4e} and {} spp, in {:.2} s ({:.2} s calibrating; step bias {:.2e} {}, order {:.2}); noise {:.2e}",
        done.estimate,
        target.metric.name(),
        match (done.met, target.error) {
            (true, Some(e)) => format!(", target {e:.3e} met"),
            (false, Some(e)) => format!(", target {e:.3e} NOT met"),
            (_, None) => String::new(),
        },
        done.step_size,
        done.spp,
        done.elapsed.as_secs_f64(),
        done.calibration.as_secs_f64(),
        done.bias.at(done.step_size),
        if done.bias.resolved {
            "measured"
        } else {
            "bounded by the noise"
        },
        done.bias.order,
        done.noise_rmse,
    );
}

/// The voxel baseline: the backend's own voxel path, the session splatting the particles into
/// the backend's grid with the first frame, then marching the grid.
fn voxel(
    session: &mut RenderSession,
    setup: &Setup,
    step: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Image> {
    let settings = &setup.settings;
    let n = settings.voxel_grid.expect("set for the voxel baseline");
    for _ in 0..setup.spp {
        session.accumulate(settings, 1)?;
        bar.inc(1);
    }
    let box_of = session.frame_params(settings, 0)?;
    let geometry = VoxelGeometry::new(
        session.backend().capabilities().name,
        box_of.box_min,
        box_of.box_max,
        n,
    )?;
    tracing::info!(
        "voxelised step {step} on {} into {:?} cells ({:.1} MiB of sums, {:.1} MiB held) in {:.3} s",
        session.backend().capabilities().name,
        geometry.dims,
        geometry.bytes() as f64 / 1048576.0,
        session.backend().memory().voxel_bytes as f64 / 1048576.0,
        session.backend().timings().voxelize.as_secs_f64()
    );
    Ok(session.image()?)
}

/// The splatter baseline, with the hits its slab buffers lost said where the backend counts
/// them.
fn splat(
    session: &mut RenderSession,
    setup: &Setup,
    step: usize,
    bar: &ProgressBar,
) -> anyhow::Result<Image> {
    let settings = &setup.settings;
    session.backend_mut().reset();
    let k = settings.splat_k.expect("set for the splatter");
    let mut counts = Some(crate::field::splat::SplatCounts::default());
    for f in 0..setup.spp {
        let frame = session.frame_params(settings, f)?;
        let frame_counts = session.backend_mut().render_splat(&frame, k)?;
        counts = counts.zip(frame_counts).map(|(a, b)| a + b);
        bar.inc(1);
    }
    match counts {
        Some(counts) => tracing::info!(
            "splatted step {step}: {} hits composited, {} ({:.2}%) lost to full {}-entry slab buffers",
            counts.kept,
            counts.lost,
            100.0 * counts.lost_fraction(),
            k
        ),
        None => tracing::info!(
            "splatted step {step} with {}-entry slab buffers (this backend does not count lost hits)",
            k
        ),
    }
    Ok(session.backend_mut().image()?)
}
