//! `aarbf bench radius | cluster | traversal | noise | scaling | baselines | accuracy | extremes
//! | all`: the paper's studies and ours
//! (`crate::study`), each writing `OUT/<study>/<study>.{csv,md,png}`.

use std::path::PathBuf;

use clap::Args;

use super::parse_size;
use crate::backend::BackendKind;
use crate::study::{self, DataSpec, Options, Study};
use crate::values::Integrator;

#[derive(Debug, Args)]
pub struct StudyArgs {
    /// A data set: uniform, random, clusters, dambreak-demo (generated in memory) or a path
    /// (file, directory or glob). Repeat for several (default: the study's own: uniform, random
    /// and dambreak-demo for traversal, uniform for scaling, dambreak-demo otherwise).
    #[arg(long, value_parser = clap::value_parser!(DataSpec))]
    pub data: Vec<DataSpec>,
    /// A backend to measure (cpu, wgpu, ash); repeat for several (default: every one this
    /// machine has).
    #[arg(long, value_enum)]
    pub backend: Vec<BackendKind>,
    /// Results go to OUT/<study>/ (created if missing).
    #[arg(long, default_value = "studies")]
    pub out: PathBuf,
    /// Overwrite earlier results.
    #[arg(long)]
    pub force: bool,
    /// Particles of a generated data set (default: the generator's: 60K uniform and random,
    /// 20K dambreak-demo; 4000 in each of the extremes study's cases).
    #[arg(long)]
    pub count: Option<usize>,
    /// The step of the series (default: the last).
    #[arg(long)]
    pub step: Option<usize>,
    /// The attribute (default: the generator's, or the data's first).
    #[arg(long)]
    pub attribute: Option<String>,
    /// The global radius, as `aarbf render --radius` reads it: a length, or a percentage of
    /// the series' bounding-box diagonal ("1.5%"). Default: ~30 particles per point for
    /// uniform and random, 1.5% otherwise.
    #[arg(long)]
    pub radius: Option<crate::scene_file::RadiusSpec>,
    /// Timed frames' size, WxH.
    #[arg(long, default_value = "256x256", value_parser = parse_size)]
    pub size: (u32, u32),
    /// Cameras on the benchmark orbit (the paper: 50).
    #[arg(long, default_value_t = 50)]
    pub cameras: usize,
    /// Timed repetitions of each measurement (after one untimed warm-up).
    #[arg(long, default_value_t = 3)]
    pub repetitions: usize,
    /// The integrator of timed frames (the paper times frames with shadows: marching).
    #[arg(long, value_enum, default_value = "marching")]
    pub integrator: Integrator,
    /// radius: the radii, as multiples of the data set's radius.
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.75,1,1.5,2")]
    pub radii: Vec<f64>,
    /// cluster: the cluster sizes.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16")]
    pub clusters: Vec<u32>,
    /// noise: the samples per pixel at which the error is measured.
    #[arg(long, value_delimiter = ',', default_value = "1,4,16,64,1024")]
    pub spp: Vec<u32>,
    /// noise: samples per pixel of the converged reference.
    #[arg(long, default_value_t = 4096)]
    pub reference_spp: u32,
    /// noise, baselines: seeds whose images' error is measured (each renders up to the
    /// largest --spp).
    #[arg(long, default_value_t = 2)]
    pub seeds: u32,
    /// noise: the size of the error images, WxH.
    #[arg(long, default_value = "64x64", value_parser = parse_size)]
    pub noise_size: (u32, u32),
    /// scaling: the smallest particle count (then times 4 up to --max-n).
    #[arg(long, default_value_t = 10_000)]
    pub min_n: usize,
    /// scaling: the largest particle count (with --data PATH: at most the data's largest step,
    /// whose nested random subsets are measured up to the whole step).
    #[arg(long, default_value_t = 1_000_000)]
    pub max_n: usize,
    /// scaling: query points per timed query.
    #[arg(long, default_value_t = 100_000)]
    pub queries: usize,
    /// baselines and accuracy: the voxel grids, cells along the longest side (the paper: 512).
    #[arg(long, value_delimiter = ',', default_value = "64,128,256,512")]
    pub voxel_grids: Vec<usize>,
    /// baselines and accuracy (emission–absorption only): the splatter's hits per slab (the RBF
    /// paper's port: 15; Knoll et al.'s book chapter: 31).
    #[arg(long, value_delimiter = ',', default_value = "4,15,31")]
    pub splat_ks: Vec<usize>,
    /// accuracy: the march steps, as multiples of the default step (1 must be among them).
    #[arg(long, value_delimiter = ',', default_value = "0.5,1,2,4")]
    pub step_factors: Vec<f64>,
    /// accuracy: the reference's tolerance: the most doubling its samples or halving its step
    /// may change it (RMSE over linear RGB).
    #[arg(long, default_value_t = 1e-4)]
    pub reference_tolerance: f64,
    /// extremes: the radii, as fractions of the domain (a unit box).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1e-6,1e-5,1e-4,1e-3,1e-2,1e-1,1,1e1,1e2"
    )]
    pub radius_fractions: Vec<f64>,
    /// extremes: the coordinate offsets, in domains, added on every axis.
    #[arg(long, value_delimiter = ',', default_value = "0,1e2,1e4,1e6")]
    pub offsets: Vec<f64>,
    /// extremes: the density weights w (Phi ~ w), down to f32's denormals.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "1e-30,1e-34,1e-36,1e-38,1e-40,1e-42,1e-44"
    )]
    pub weights: Vec<f64>,
}

/// The options only some studies read, and which studies: `aarbf bench STUDY --help` lists a
/// study's own (and the options every study reads), and another study's is refused.
const STUDY_OPTIONS: &[(&str, &[&str])] = &[
    ("radius", &["radii"]),
    ("cluster", &["clusters"]),
    ("traversal", &[]),
    ("noise", &["spp", "reference_spp", "seeds", "noise_size"]),
    ("scaling", &["min_n", "max_n", "queries"]),
    (
        "baselines",
        &[
            "voxel_grids",
            "splat_ks",
            "reference_spp",
            "seeds",
            "noise_size",
        ],
    ),
    (
        "accuracy",
        &[
            "voxel_grids",
            "splat_ks",
            "step_factors",
            "reference_tolerance",
            "spp",
            "seeds",
            "noise_size",
        ],
    ),
    ("extremes", &["radius_fractions", "offsets", "weights"]),
];

fn study_specific(id: &str) -> bool {
    STUDY_OPTIONS.iter().any(|(_, own)| own.contains(&id))
}

/// `aarbf bench` with each study's help listing its own options (`all` lists every one).
pub(in crate::cli) fn tailor_help(bench: clap::Command) -> clap::Command {
    STUDY_OPTIONS.iter().fold(bench, |bench, (study, own)| {
        bench.mut_subcommand(study, |command| {
            command.mut_args(|arg| {
                let id = arg.get_id().as_str();
                if study_specific(id) && !own.contains(&id) {
                    arg.hide(true)
                } else {
                    arg
                }
            })
        })
    })
}

/// Says which options given are another study's, which this one does not read (`aarbf bench
/// noise --voxel-grids 64`): a script may pass one list of options to every study, so they are
/// ignored with a warning rather than refused.
pub(in crate::cli) fn warn_of_other_studies_options(matches: &clap::ArgMatches) {
    let Some(("bench", bench)) = matches.subcommand() else {
        return;
    };
    let Some((study, given)) = bench.subcommand() else {
        return;
    };
    let Some((_, own)) = STUDY_OPTIONS.iter().find(|(s, _)| *s == study) else {
        return;
    };
    let mut ignored = Vec::new();
    let specific: std::collections::BTreeSet<&str> = STUDY_OPTIONS
        .iter()
        .flat_map(|(_, options)| options.iter().copied())
        .collect();
    for id in specific {
        if !own.contains(&id)
            && given.value_source(id) == Some(clap::parser::ValueSource::CommandLine)
        {
            let users: Vec<&str> = STUDY_OPTIONS
                .iter()
                .filter(|(_, o)| o.contains(&id))
                .map(|(s, _)| *s)
                .collect();
            ignored.push(format!(
                "--{} ({}'s)",
                id.replace('_', "-"),
                users.join(" and ")
            ));
        }
    }
    if !ignored.is_empty() {
        tracing::warn!(
            "`aarbf bench {study}` does not read {}: ignored (`aarbf bench {study} --help` lists \
             its options)",
            ignored.join(", ")
        );
    }
}

impl StudyArgs {
    fn options(&self, command: String) -> Options {
        Options {
            data: self.data.clone(),
            count: self.count,
            step: self.step,
            attribute: self.attribute.clone(),
            radius: self.radius,
            backends: self.backend.clone(),
            out: self.out.clone(),
            force: self.force,
            image: self.size,
            cameras: self.cameras,
            repetitions: self.repetitions,
            integrator: self.integrator,
            clusters: self.clusters.clone(),
            radius_factors: self.radii.clone(),
            spps: self.spp.clone(),
            reference_spp: self.reference_spp,
            seeds: self.seeds,
            noise_image: self.noise_size,
            min_n: self.min_n,
            max_n: self.max_n,
            queries: self.queries,
            voxel_grids: self.voxel_grids.clone(),
            splat_ks: self.splat_ks.clone(),
            step_factors: self.step_factors.clone(),
            reference_tolerance: self.reference_tolerance,
            radius_fractions: self.radius_fractions.clone(),
            offsets: self.offsets.clone(),
            phi_weights: self.weights.clone(),
            command,
        }
    }
}

/// The command line as typed, for the pages (`aarbf` for the binary's path).
fn command_line() -> String {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    args.insert(0, "aarbf".into());
    args.iter()
        .map(|a| {
            if a.contains([' ', '"', '\'']) {
                format!("'{a}'")
            } else {
                a.clone()
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// Runs one study (`Some`) or all of them.
pub(super) fn run(which: Option<Study>, args: &StudyArgs) -> anyhow::Result<()> {
    let options = args.options(command_line());
    let written = match which {
        Some(s) => vec![study::run(s, &options)?],
        None => study::run_all(&options)?,
    };
    for w in written {
        println!(
            "{} ({} rows), {}, {}",
            w.csv.display(),
            w.rows,
            w.markdown.display(),
            w.png.display()
        );
    }
    Ok(())
}
