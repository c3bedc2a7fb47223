//! `aarbf stbn`: generate a spatiotemporal blue-noise mask (the shipped asset's command).

use std::path::PathBuf;

use clap::Args;

use crate::noise::stbn;

/// The arguments of `aarbf stbn`: the mask's size, the energy's sigma, the seed and the output
/// file.
#[derive(Debug, Args)]
pub struct StbnArgs {
    /// Width of the mask in pixels (1..=4096).
    #[arg(long, default_value_t = 128)]
    pub width: u32,
    /// Height of the mask in pixels (1..=4096).
    #[arg(long, default_value_t = 128)]
    pub height: u32,
    /// Slices (frames) of the mask.
    #[arg(long, default_value_t = 64)]
    pub depth: u32,
    /// Standard deviation of the energy's Gaussians, in pixels (and frames).
    #[arg(long, default_value_t = stbn::DEFAULT_SIGMA)]
    pub sigma: f64,
    /// Random seed; the same seed gives the same mask.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The mask file to write (the STBN asset format).
    #[arg(long)]
    pub out: PathBuf,
    /// Overwrite an existing output.
    #[arg(long)]
    pub force: bool,
}

pub(super) fn run(args: StbnArgs) -> anyhow::Result<()> {
    for (name, v) in [
        ("width", args.width),
        ("height", args.height),
        ("depth", args.depth),
    ] {
        anyhow::ensure!(
            (1..=4096).contains(&v),
            "--{name} must lie in 1..=4096, got {v}"
        );
    }
    anyhow::ensure!(
        u64::from(args.width) * u64::from(args.height) * u64::from(args.depth) < 1 << 32,
        "the mask must hold fewer than 2^32 values"
    );
    anyhow::ensure!(
        args.sigma.is_finite() && args.sigma > 0.0,
        "--sigma must be positive, got {}",
        args.sigma
    );
    let total = u64::from(args.width) * u64::from(args.height) * u64::from(args.depth);
    let bar = crate::progress::bar(total, "ranking");
    let mask = stbn::generate_with_progress(
        args.width,
        args.height,
        args.depth,
        args.sigma,
        args.seed,
        |done, _| {
            bar.set_position(done as u64);
        },
    );
    bar.finish_and_clear();
    crate::io::output::write_atomically(&args.out, args.force, |tmp| {
        mask.write(tmp).map_err(std::io::Error::other)
    })?;
    println!("{}", args.out.display());
    Ok(())
}
