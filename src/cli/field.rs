//! `aarbf field`: the density and attribute fields at query points.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use glam::DVec3;

use super::settings::{DataArgs, FieldOptions, resolve};
use crate::field::{Classification, ReferenceField};
use crate::io::{At, npy};

/// Which implementation evaluates the field.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FieldBackend {
    /// The f64 CPU reference: rayon over queries, a BVH (obvhs) over cluster boxes.
    #[default]
    Cpu,
}

#[derive(Debug, Args)]
pub struct FieldArgs {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub field: FieldOptions,
    /// Query points: an M x 3 .npy array (float32 or float64).
    #[arg(long)]
    pub queries: PathBuf,
    /// Output .npy, float64: M x 2 (Phi, Theta) for post-classification, M x 4 (Phi, r, g, b)
    /// for pre-classification. Theta is in the attribute's units; 0 where Phi is 0.
    #[arg(long)]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value = "cpu")]
    pub backend: FieldBackend,
}

pub fn run(args: FieldArgs) -> anyhow::Result<()> {
    let resolved = resolve(&args.data, &args.field)?;
    anyhow::ensure!(
        resolved.field.attribute.is_some(),
        "--attribute is required: the field carries an attribute (the data has: {})",
        resolved
            .series
            .attributes()
            .iter()
            .map(|a| a.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let queries = npy::read_matrix(At::new(&args.queries, None))?;
    anyhow::ensure!(
        queries.cols == 3,
        "{}: queries must be an M x 3 array, found {} columns",
        args.queries.display(),
        queries.cols
    );
    let points: Vec<DVec3> = (0..queries.rows)
        .map(|i| DVec3::from_slice(queries.row(i)))
        .collect();
    if let Some(i) = points.iter().position(|p| !p.is_finite()) {
        anyhow::bail!(
            "{}: query {i} is not finite: {}",
            args.queries.display(),
            points[i]
        );
    }

    let step = resolved.series.step(resolved.step)?;
    let built = Instant::now();
    let field = ReferenceField::of_step(
        &step,
        &resolved.field,
        resolved.cluster,
        resolved.series.bounds(),
        resolved.series_range(),
    )?;
    let build_time = built.elapsed();
    let started = Instant::now();
    let samples = match args.backend {
        FieldBackend::Cpu => field.eval_many(&points),
    };
    let eval_time = started.elapsed();
    let pre = resolved.field.classification == Classification::Pre;
    let cols = if pre { 4 } else { 2 };
    let mut out = Vec::with_capacity(samples.len() * cols);
    for s in &samples {
        out.push(s.phi);
        out.extend_from_slice(&s.theta[..cols - 1]);
    }
    npy::write_matrix(&args.out, samples.len(), cols, &out)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    tracing::info!(
        "{} particles (K = {}, radius {:.6}), {} queries: build {:.3} s, evaluation {:.3} s ({:.3} M queries/s)",
        step.len(),
        resolved.cluster,
        resolved.field.radius,
        points.len(),
        build_time.as_secs_f64(),
        eval_time.as_secs_f64(),
        points.len() as f64 / eval_time.as_secs_f64().max(1e-9) / 1e6
    );
    Ok(())
}
