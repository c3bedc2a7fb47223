//! `aarbf generate`: write a synthetic data set.

use std::path::PathBuf;

use clap::Args;

use crate::io::{self, Format};
use crate::scene::synth::Generator;

/// The arguments of `aarbf generate`: which synthetic data set, its size, seed and output format.
#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// Which data set.
    #[arg(value_enum)]
    pub name: Generator,
    /// The directory to write into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Particles per step (default: 60K for uniform/random, 100K clusters, 20K dambreak-demo;
    /// a dam break above 100K simulates 100K and the rest ride with them).
    #[arg(long)]
    pub count: Option<usize>,
    /// Time steps (default: 48 for dambreak-demo, 1 otherwise).
    #[arg(long)]
    pub steps: Option<usize>,
    /// Random seed; the same seed gives the same data.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output format: particles, vtk-xml (.vtp), csv, ply, raw or npy.
    #[arg(long, value_enum, default_value = "particles")]
    pub format: Format,
    /// Overwrite an earlier output of the same data set in the directory.
    #[arg(long)]
    pub force: bool,
}

pub(super) fn run(args: GenerateArgs) -> anyhow::Result<()> {
    let count = args.count.unwrap_or(args.name.default_count());
    let steps = args.steps.unwrap_or(args.name.default_steps());
    anyhow::ensure!(count > 0, "--count must be at least 1");
    anyhow::ensure!(steps > 0, "--steps must be at least 1");
    tracing::info!(
        "generating {} ({count} particles, {steps} steps, seed {})",
        args.name,
        args.seed
    );
    // A step above the simulated count is written a run of particles at a time where the
    // format allows, never whole in memory.
    let series = args.name.series(count, steps, args.seed);
    let path = io::write_series_from(
        &args.out,
        &args.name.to_string(),
        &series,
        args.format,
        args.name.main_attribute(),
    )?;
    println!("{}", path.display());
    Ok(())
}
