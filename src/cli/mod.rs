//! The `aarbf` command line: argument definitions and the commands behind them.

mod bench;
pub mod field;
mod generate;
mod info;
pub mod output_format;
mod render;
mod slice;
mod stbn;
mod view;

use clap::{Parser, Subcommand};

pub use bench::BenchArgs;
pub use field::FieldArgs;
pub use generate::GenerateArgs;
pub use info::InfoArgs;
pub use render::RenderArgs;
pub use slice::SliceArgs;
pub use stbn::StbnArgs;
pub use view::ViewArgs;

/// The parsed command line: one [`Command`] (clap takes the help texts from the attributes, not
/// from this comment).
#[derive(Debug, Parser)]
#[command(
    name = "aarbf",
    version,
    about = "Attribute-aware RBF volume rendering of time-series particle data",
    long_about = "Attribute-aware RBF volume rendering of time-series particle data \
                  (Morrical et al., IEEE VIS 2023).\n\nData: .particles, .vtp/.vtu/.vts, .vtk, \
                  .csv, .ply, .raw, .npy, HDF5 snapshots (.hdf5, .h5: SWIFT, GADGET, AREPO, GIZMO); a file, \
                  a directory or a glob is a time series."
)]
pub struct Cli {
    /// The subcommand given.
    #[command(subcommand)]
    pub command: Command,
}

// Parsed once per process: the size difference between variants costs nothing.
/// The subcommands of `aarbf`; each variant's doc comment is its help text.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Describe a data set: steps, counts, bounds, attributes with ranges, memory per step.
    Info(InfoArgs),
    /// Evaluate the density and attribute fields at query points (M x 3 .npy in, .npy out).
    Field(FieldArgs),
    /// Render one step or a range of steps to PNG images.
    Render(RenderArgs),
    /// Show the fields on an axis-aligned plane through the data, as a PNG.
    Slice(SliceArgs),
    /// Generate a spatiotemporal blue-noise mask (the renderer ships one: assets/).
    Stbn(StbnArgs),
    /// Write a synthetic data set (uniform, random, clusters, dambreak-demo).
    Generate(GenerateArgs),
    /// The interactive viewer: orbit, play the series, edit the maps, switch backends, save
    /// the state as a scene file `aarbf render --scene` renders to the same image.
    View(ViewArgs),
    /// Measure this machine on your data: `aarbf bench playback` plays a series and says where
    /// each step's time goes; `aarbf bench radius|cluster|traversal|noise|scaling|all` run the
    /// paper's studies (CSV, Markdown table and PNG figure each).
    Bench(BenchArgs),
}

impl Cli {
    /// The command line as typed, or the process exits with clap's message. Every option that
    /// takes a value accepts a negative number, so `--radius -1` reaches the option's own
    /// check (which says what a valid value is) instead of clap's "unexpected argument".
    pub fn parse_args() -> Cli {
        use clap::{CommandFactory, FromArgMatches};
        fn negatives(command: clap::Command) -> clap::Command {
            command
                .mut_args(|arg| {
                    if arg.get_action().takes_values() {
                        arg.allow_negative_numbers(true)
                    } else {
                        arg
                    }
                })
                .mut_subcommands(negatives)
        }
        let mut command = negatives(Cli::command()).mut_subcommand("bench", bench::tailor_help);
        let mut matches = command.get_matches_mut();
        bench::warn_of_other_studies_options(&matches);
        Cli::from_arg_matches_mut(&mut matches).unwrap_or_else(|e| e.exit())
    }
}

/// Runs the subcommand `cli` names, to completion.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Field(a) => field::run(a),
        Command::Render(a) => render::run(a),
        Command::Slice(a) => slice::run(a),
        Command::Stbn(a) => stbn::run(a),
        Command::Generate(a) => generate::run(a),
        Command::Bench(a) => bench::run(a),
        Command::View(a) => view::run(a),
    }
}
