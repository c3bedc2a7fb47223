//! `aarbf info`: what a data set holds.

use std::path::PathBuf;

use clap::Args;

use crate::io::Format;
use crate::scene::{OpenOptions, TimeSeries};

#[derive(Debug, Args)]
pub struct InfoArgs {
    /// The data: a file, a directory or a glob.
    pub data: PathBuf,
    /// The file format, when the extension does not tell.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
}

pub fn run(args: InfoArgs) -> anyhow::Result<()> {
    let series = TimeSeries::open(
        &args.data,
        &OpenOptions {
            format: args.format,
            ..OpenOptions::default()
        },
    )?;
    print!("{}", describe(&args.data, &series));
    Ok(())
}

fn mib(bytes: usize) -> String {
    format!("{:.2} MiB", bytes as f64 / (1 << 20) as f64)
}

pub fn describe(path: &std::path::Path, series: &TimeSeries) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let b = series.bounds();
    let _ = writeln!(out, "data:       {}", path.display());
    let _ = writeln!(out, "steps:      {}", series.len());
    let _ = writeln!(out, "particles:  {} at most per step", series.max_count());
    let _ = writeln!(
        out,
        "bounds:     [{}, {}, {}] .. [{}, {}, {}] (diagonal {:.6})",
        b.min.x,
        b.min.y,
        b.min.z,
        b.max.x,
        b.max.y,
        b.max.z,
        b.diagonal()
    );
    let _ = writeln!(out, "attributes:");
    if series.attributes().is_empty() {
        let _ = writeln!(out, "  (none)");
    }
    for a in series.attributes() {
        let _ = writeln!(out, "  {:<24} {} .. {}", a.name, a.min, a.max);
    }
    let _ = writeln!(out, "steps:");
    let _ = writeln!(
        out,
        "  {:>5}  {:<20} {:>12} {:>12}",
        "index", "name", "particles", "memory"
    );
    for (i, s) in series.steps().iter().enumerate() {
        let _ = writeln!(
            out,
            "  {:>5}  {:<20} {:>12} {:>12}",
            i,
            s.name,
            s.count,
            mib(s.bytes)
        );
    }
    out
}
