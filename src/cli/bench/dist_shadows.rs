//! `aarbf bench distributed --integrator marching|delta|ss-reference`: how far shadows across
//! bricks fall from the single rank's, over the light map's side M and the rank count P, with
//! shadows from each ray's own brick only (`local`, OSPRay's distributed shadows) beside them.
//! FLIP and RMSE of the distributed image against the single rank's, both from the same
//! frames, so with stochastic marching (whose primary decisions the bricks make exactly as the
//! single rank) the difference is the shadows' alone.

use std::fmt::Write as _;
use std::sync::Arc;

use anyhow::Context;

use crate::backend::Backend;
use crate::backend::cpu::CpuBackend;
use crate::dist::{Comm, DistScene, DistShadows, render_distributed, run_local, slice_of};
use crate::values::{FrameParams, Step};

/// One distributed image against the single rank's.
pub(super) struct Compared {
    ranks: usize,
    shadows: DistShadows,
    flip: f64,
    rmse: f64,
    /// The largest light map bytes and CPU seconds of any rank.
    light_map_bytes: u64,
    light_map_seconds: f64,
}

/// Renders `frames` of `step` on one rank and at every count of `ranks` above 1 with every
/// light map side of `maps` and `local`, every rank with `scene`, and compares.
pub(super) fn compare(
    step: &Arc<Step>,
    scene: &DistScene<'_>,
    frames: &[FrameParams],
    ranks: &[usize],
    maps: &[u32],
) -> anyhow::Result<Vec<Compared>> {
    let single = {
        let mut backend = CpuBackend::new();
        backend.upload(&scene.step_input(step, scene.precision))?;
        backend.build()?;
        for f in frames {
            backend.render(f)?;
        }
        backend.image()?
    };
    let mut how: Vec<DistShadows> = vec![DistShadows::Local];
    how.extend(maps.iter().map(|&m| DistShadows::PrefixMap(m)));
    let ranks: Vec<usize> = ranks.iter().copied().filter(|&p| p > 1).collect();
    let bar = crate::progress::bar((ranks.len() * how.len()) as u64, "shadow comparisons");
    let mut out = Vec::new();
    for &p in &ranks {
        for &shadows in &how {
            let scene = DistScene { shadows, ..*scene };
            let image = run_local(p, |comm| {
                let local = slice_of(step, comm.rank(), comm.size());
                render_distributed(comm, &mut CpuBackend::new(), &local, &scene, frames)
            })
            .with_context(|| format!("{p} ranks, {shadows:?}"))?
            .swap_remove(0)
            .context("rank 0 returned no image")?;
            let got = image.image();
            out.push(Compared {
                ranks: p,
                shadows,
                flip: got.flip(&single),
                rmse: got.rmse(&single),
                light_map_bytes: image
                    .reports
                    .iter()
                    .map(|r| r.shadow_map_bytes)
                    .max()
                    .unwrap_or(0),
                light_map_seconds: image
                    .reports
                    .iter()
                    .map(|r| r.shadow_map_seconds)
                    .fold(0.0, f64::max),
            });
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    Ok(out)
}

fn label(shadows: DistShadows) -> String {
    match shadows {
        DistShadows::Local => "local".to_owned(),
        DistShadows::PrefixMap(m) => format!("prefix map {m}²"),
    }
}

pub(super) fn csv_rows(compared: &[Compared]) -> String {
    let mut out = String::from("ranks,shadows,map,flip,rmse,light_map_bytes,light_map_wall_s\n");
    for c in compared {
        let (how, map) = match c.shadows {
            DistShadows::Local => ("local", 0),
            DistShadows::PrefixMap(m) => ("prefix-map", m),
        };
        let _ = writeln!(
            out,
            "{},{how},{map},{:.6},{:.6},{},{:.6}",
            c.ranks, c.flip, c.rmse, c.light_map_bytes, c.light_map_seconds
        );
    }
    out
}

/// The comparison's section of the benchmark's summary; `what` says what was rendered.
pub(super) fn summarise(what: &str, compared: &[Compared]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n## Shadows across bricks against the single rank\n\n{what}, the distributed image against the single rank's \
         from the same frames: FLIP (0 identical) and RMSE of linear RGB. `local` shadows each \
         ray through its own brick only; the prefix map through every brick, by an M² light \
         map scanned from the light. Light map time: the slowest rank's wall time with every \
         rank's threads sharing this machine.\n\n| P | shadows | FLIP | RMSE | light map, largest rank (MiB sent, s) |\n|---|---|---|---|---|",
    );
    for c in compared {
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} | {:.5} | {:.2}, {:.2} |",
            c.ranks,
            label(c.shadows),
            c.flip,
            c.rmse,
            c.light_map_bytes as f64 / 1048576.0,
            c.light_map_seconds
        );
    }
    md
}
