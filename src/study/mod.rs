//! The paper's studies (method.md §6), each from one call, as a CSV of every measurement, a
//! Markdown page with the table and a PNG figure (`aarbf bench <study>`):
//!
//! - [`radius`]: frame time vs the global radius at K = 1 and K = 16 (Fig. 9, blue);
//! - [`cluster`]: frame, build and refit time and structure bytes vs K (Fig. 9 red, Tables 1–2);
//! - [`traversal`]: the RT pipeline vs the LBVH traversal on one device, and the wgpu LBVH
//!   (Fig. 10a);
//! - [`noise`]: blue (STBN) vs white noise, frame time and error vs spp (Fig. 10b);
//! - [`scaling`]: build, refit, query and frame time vs N, with fitted exponents;
//! - [`baselines`]: our method against the voxel grid and Knoll et al.'s splatter, rebuilt every frame (Table 3);
//! - [`accuracy`]: every knob's time and error against a converged reference, the Pareto
//!   front, the defaults and `--target-error` against it.
//! - [`extremes`]: the f32 and double-single field error against the f64 reference at extreme
//!   radii, offsets and densities (not the paper's).
//!
//! Every study drives backends through [`RenderSession`] as the CLI and viewer do, warms each
//! configuration up with one untimed launch (lavapipe compiles a pipeline on first use), times
//! several repetitions, and appends each measurement to its CSV as soon as it is taken
//! ([`record::Recorder`]): an interrupted study keeps what it measured, and a study that fails
//! still writes its table and figure of the rows it has.

pub mod accuracy;
pub mod baselines;
pub mod cluster;
pub mod data;
pub mod extremes;
mod harness;
pub mod noise;
pub mod plot;
pub mod radius;
pub mod record;
pub mod report;
pub mod scaling;
pub mod traversal;

use std::path::{Path, PathBuf};

use crate::backend::{BackendError, BackendKind};
use crate::io::DataError;
use crate::io::output::OutputError;
use crate::render::RenderError;
use crate::values::{Bounds, Integrator};

pub use data::{DataSpec, Dataset};
pub(crate) use harness::frame_columns;
pub use harness::{
    Ctx, Measurement, backends, build_and_refit_times, cameras, device_of, frame_times, ms,
    session, timer, with_frame_settings,
};
pub use record::{Device, Machine, Recorder, Row};

/// Why a study could not run or finish.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// A render failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A backend could not be made or failed.
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// The data could not be read.
    #[error(transparent)]
    Data(#[from] DataError),
    /// An output file could not be written.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// A file or directory could not be created or written.
    #[error("{path}: {error}")]
    Io {
        /// The file or directory.
        path: String,
        /// What failed.
        error: std::io::Error,
    },
    /// The figure could not be drawn.
    #[error("drawing the figure: {0}")]
    Plot(String),
    /// The options are invalid; the message names the one.
    #[error("{0}")]
    Invalid(String),
}

impl StudyError {
    /// The I/O error `error` on `path`.
    pub fn io(path: &Path, error: std::io::Error) -> StudyError {
        StudyError::Io {
            path: path.display().to_string(),
            error,
        }
    }
}

/// The studies.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Study {
    /// Frame time vs the global radius at K = 1 and K = 16 (Fig. 9, blue).
    Radius,
    /// Frame, build and refit time and structure bytes vs K (Fig. 9 red, Tables 1–2).
    Cluster,
    /// The RT pipeline vs the LBVH traversal on one device, and the wgpu LBVH (Fig. 10a).
    Traversal,
    /// Blue vs white noise: frame time and error vs spp (Fig. 10b).
    Noise,
    /// Build, refit, query and frame time vs N, with fitted exponents.
    Scaling,
    /// Our method against the voxel grid and the splatter, rebuilt every frame (Table 3).
    Baselines,
    /// Every knob's time and error against a converged reference.
    Accuracy,
    /// The f32 and double-single field error against the f64 reference at extreme radii, offsets
    /// and densities.
    Extremes,
}

impl Study {
    /// Every study, in the order `run_all` runs them.
    pub const ALL: [Study; 8] = [
        Study::Radius,
        Study::Cluster,
        Study::Traversal,
        Study::Noise,
        Study::Scaling,
        Study::Baselines,
        Study::Accuracy,
        Study::Extremes,
    ];

    /// The name the command line, the output directory and the files use.
    pub fn name(self) -> &'static str {
        match self {
            Study::Radius => "radius",
            Study::Cluster => "cluster",
            Study::Traversal => "traversal",
            Study::Noise => "noise",
            Study::Scaling => "scaling",
            Study::Baselines => "baselines",
            Study::Accuracy => "accuracy",
            Study::Extremes => "extremes",
        }
    }

    /// The data sets a study runs on when `--data` is not given.
    fn default_data(self) -> Vec<DataSpec> {
        use crate::scene::synth::Generator::*;
        match self {
            Study::Traversal => vec![
                DataSpec::Generated(Uniform),
                DataSpec::Generated(Random),
                DataSpec::Generated(DambreakDemo),
            ],
            Study::Scaling => vec![DataSpec::Generated(Uniform)],
            // It generates its own cases.
            Study::Extremes => Vec::new(),
            _ => vec![DataSpec::Generated(DambreakDemo)],
        }
    }
}

impl std::fmt::Display for Study {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a study runs; [`Options::default`] is the paper's set-up where this machine allows it.
#[derive(Clone, Debug)]
pub struct Options {
    /// The data sets (empty: the study's own, e.g. uniform, random and the dam break for
    /// `traversal`).
    pub data: Vec<DataSpec>,
    /// Particles of a generated data set (default: the generator's).
    pub count: Option<usize>,
    /// The step of the series (default: the last).
    pub step: Option<usize>,
    /// The attribute to colour by (default: the generator's main one, or the data's first).
    pub attribute: Option<String>,
    /// The radius as a percentage of the step's diagonal (default: [`data::default_radius`]).
    pub radius: Option<crate::scene_file::RadiusSpec>,
    /// The backends (empty: every backend this machine has).
    pub backends: Vec<BackendKind>,
    /// Results go to `out/<study>/`.
    pub out: PathBuf,
    /// Overwrite existing results.
    pub force: bool,
    /// Image width and height in pixels of timed frames.
    pub image: (u32, u32),
    /// Benchmark-orbit cameras (the paper: 50).
    pub cameras: usize,
    /// Timed repetitions of each configuration.
    pub repetitions: usize,
    /// The integrator of timed frames (the paper times frames with shadows).
    pub integrator: Integrator,
    /// Cluster sizes of the `cluster` study.
    pub clusters: Vec<u32>,
    /// Radii of the `radius` study, as multiples of the data set's radius.
    pub radius_factors: Vec<f64>,
    /// Samples per pixel at which the `noise` study measures the error.
    pub spps: Vec<u32>,
    /// Samples per pixel of the `noise` study's reference.
    pub reference_spp: u32,
    /// Seeds whose images' errors are measured (`noise`, `baselines`): each renders up to the
    /// largest spp, so they are counted apart from the timing repetitions.
    pub seeds: u32,
    /// The `noise` study's image size (its error images).
    pub noise_image: (u32, u32),
    /// The `scaling` study's sizes: from `min_n`, times 4, up to `max_n`.
    pub min_n: usize,
    /// The `scaling` study's largest size.
    pub max_n: usize,
    /// Query points per timed query in the `scaling` study.
    pub queries: usize,
    /// Grid sizes (cells along the longest side) of the `baselines` and `accuracy` studies'
    /// voxel grids.
    pub voxel_grids: Vec<usize>,
    /// The `baselines` and `accuracy` studies' splatter buffer sizes (hits per slab).
    pub splat_ks: Vec<usize>,
    /// The `accuracy` study's march steps, as multiples of the default step.
    pub step_factors: Vec<f64>,
    /// The `accuracy` study's reference: the most doubling the samples or halving the step
    /// may change it (RMSE over linear RGB).
    pub reference_tolerance: f64,
    /// The `extremes` study's radii, as fractions of its domain (a unit box).
    pub radius_fractions: Vec<f64>,
    /// The `extremes` study's coordinate offsets, in domains, on every axis.
    pub offsets: Vec<f64>,
    /// The `extremes` study's density weights (Phi scales with them, down to f32's denormals).
    pub phi_weights: Vec<f64>,
    /// The command line, as the pages show it.
    pub command: String,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            data: Vec::new(),
            count: None,
            step: None,
            attribute: None,
            radius: None,
            backends: Vec::new(),
            out: PathBuf::from("studies"),
            force: false,
            image: (256, 256),
            cameras: 50,
            repetitions: 3,
            integrator: Integrator::Marching,
            clusters: vec![1, 2, 4, 8, 16],
            radius_factors: vec![0.5, 0.75, 1.0, 1.5, 2.0],
            spps: vec![1, 4, 16, 64, 1024],
            reference_spp: 4096,
            seeds: 2,
            noise_image: (64, 64),
            min_n: 10_000,
            max_n: 1_000_000,
            queries: 100_000,
            voxel_grids: vec![64, 128, 256, 512],
            splat_ks: vec![4, 15, 31],
            step_factors: vec![0.5, 1.0, 2.0, 4.0],
            reference_tolerance: 1e-4,
            radius_fractions: vec![1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2],
            offsets: vec![0.0, 1e2, 1e4, 1e6],
            phi_weights: vec![1e-30, 1e-34, 1e-36, 1e-38, 1e-40, 1e-42, 1e-44],
            command: String::new(),
        }
    }
}

impl Options {
    fn check(&self) -> Result<(), StudyError> {
        let bad = |m: &str| Err(StudyError::Invalid(m.to_owned()));
        if self.cameras == 0 {
            return bad("--cameras must be at least 1");
        }
        if self.repetitions == 0 {
            return bad("--repetitions must be at least 1");
        }
        if self.clusters.is_empty() || self.radius_factors.is_empty() || self.spps.is_empty() {
            return bad("--clusters, --radii and --spp need at least one value");
        }
        for &k in &self.clusters {
            crate::accel::ClusterSize::new(k).map_err(StudyError::Invalid)?;
        }
        if self
            .radius_factors
            .iter()
            .any(|f| !(f.is_finite() && *f > 0.0))
        {
            return bad("--radii: every factor must be positive");
        }
        if self.spps.contains(&0) || self.reference_spp == 0 || self.seeds == 0 {
            return bad("--spp, --reference-spp and --seeds must be at least 1");
        }
        if self.min_n == 0 || self.max_n < self.min_n {
            return bad("--min-n must be at least 1 and at most --max-n");
        }
        if self
            .voxel_grids
            .iter()
            .any(|&n| n == 0 || n > crate::backend::voxel::MAX_GRID)
        {
            return bad("--voxel-grids: each grid must have 1..=1024 cells along its longest side");
        }
        if self.splat_ks.contains(&0) {
            return bad("--splat-ks: each buffer must hold at least 1 hit");
        }
        if !self.step_factors.contains(&1.0)
            || self
                .step_factors
                .iter()
                .any(|f| !(f.is_finite() && *f > 0.0))
        {
            return bad("--step-factors: positive multiples of the default step, 1 among them");
        }
        if !(self.reference_tolerance.is_finite() && self.reference_tolerance > 0.0) {
            return bad("--reference-tolerance must be a positive number");
        }
        if self.queries == 0 {
            return bad("--queries must be at least 1");
        }
        extremes::check_sweeps(self).map_err(StudyError::Invalid)
    }
}

/// What a finished study wrote.
#[derive(Debug)]
pub struct Written {
    /// The CSV of every measurement.
    pub csv: PathBuf,
    /// The Markdown page.
    pub markdown: PathBuf,
    /// The PNG figure.
    pub png: PathBuf,
    /// Rows measured.
    pub rows: usize,
}

/// What a study module provides besides measuring: its page and figure from its rows.
pub struct Description {
    /// The page's and the figure's title.
    pub title: &'static str,
    /// What the paper measures and found (the caption's first line, the page's preface).
    pub paper: &'static str,
    /// The names of the study's own CSV columns, in order (the frame settings among them).
    pub settings: &'static [&'static str],
}

/// Runs `study` with `options`, writing `out/<study>/<study>.{csv,md,png}`.
pub fn run(study: Study, options: &Options) -> Result<Written, StudyError> {
    options.check()?;
    let dir = options.out.join(study.name());
    std::fs::create_dir_all(&dir).map_err(|e| StudyError::io(&dir, e))?;
    let csv = dir.join(format!("{study}.csv"));
    let markdown = dir.join(format!("{study}.md"));
    let png = dir.join(format!("{study}.png"));
    for p in [&csv, &markdown, &png] {
        crate::io::output::check_writable(p, options.force)?;
    }
    let description = match study {
        Study::Radius => radius::DESCRIPTION,
        Study::Cluster => cluster::DESCRIPTION,
        Study::Traversal => traversal::DESCRIPTION,
        Study::Noise => noise::DESCRIPTION,
        Study::Scaling => scaling::DESCRIPTION,
        Study::Baselines => baselines::DESCRIPTION,
        Study::Accuracy => accuracy::DESCRIPTION,
        Study::Extremes => extremes::DESCRIPTION,
    };
    let mut recorder = Recorder::create(&csv, Machine::this(), description.settings)?;
    let data = if options.data.is_empty() {
        study.default_data()
    } else {
        options.data.clone()
    };
    let backends = backends(&options.backends)?;
    tracing::info!(
        "{study}: data {}; backends {}",
        data.iter()
            .map(|d| d.to_string())
            .collect::<Vec<_>>()
            .join(", "),
        backends
            .iter()
            .map(|b| b.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut ctx = Ctx {
        options,
        recorder: &mut recorder,
        data: &data,
        backends: &backends,
    };
    let measured = match study {
        Study::Radius => radius::measure(&mut ctx),
        Study::Cluster => cluster::measure(&mut ctx),
        Study::Traversal => traversal::measure(&mut ctx),
        Study::Noise => noise::measure(&mut ctx),
        Study::Scaling => scaling::measure(&mut ctx),
        Study::Baselines => baselines::measure(&mut ctx),
        Study::Accuracy => accuracy::measure(&mut ctx),
        Study::Extremes => extremes::measure(&mut ctx),
    };
    let failure = measured.as_ref().err().map(|e| e.to_string());
    // The page and figure of what was measured, also when the study stopped early.
    let (notes, figure) = match study {
        Study::Radius => radius::summarise(recorder.rows(), options),
        Study::Cluster => cluster::summarise(recorder.rows(), options),
        Study::Traversal => traversal::summarise(recorder.rows(), options),
        Study::Noise => noise::summarise(recorder.rows(), options),
        Study::Scaling => scaling::summarise(recorder.rows(), options),
        Study::Baselines => baselines::summarise(recorder.rows(), options),
        Study::Accuracy => accuracy::summarise(recorder.rows(), options),
        Study::Extremes => extremes::summarise(recorder.rows(), options),
    };
    // A table of the study's own shape beside the table of every row.
    let extra = match study {
        Study::Extremes => extremes::table(recorder.rows()),
        _ => String::new(),
    };
    let page = report::markdown(
        &report::Page {
            study: study.name(),
            title: description.title,
            paper: description.paper,
            command: &options.command,
            notes: &notes,
            extra: &extra,
            failure: failure.as_deref(),
        },
        &recorder,
    );
    let written =
        crate::io::output::write_atomically(&markdown, true, |p| std::fs::write(p, &page))
            .map_err(StudyError::from)
            .and_then(|()| plot::write_png(&png, &figure, true));
    measured?;
    written?;
    tracing::info!(
        "{study}: {} rows in {}",
        recorder.rows().len(),
        csv.display()
    );
    Ok(Written {
        csv,
        markdown,
        png,
        rows: recorder.rows().len(),
    })
}

/// Runs every study in turn with the same options; stops at the first that fails.
pub fn run_all(options: &Options) -> Result<Vec<Written>, StudyError> {
    Study::ALL.iter().map(|&s| run(s, options)).collect()
}

/// The least-squares slope of log y over log x: the exponent of a power law y ∝ x^e.
pub fn fitted_exponent(points: &[(f64, f64)]) -> Option<f64> {
    let p: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if p.len() < 2 {
        return None;
    }
    let n = p.len() as f64;
    let (mx, my) = (
        p.iter().map(|q| q.0).sum::<f64>() / n,
        p.iter().map(|q| q.1).sum::<f64>() / n,
    );
    let sxx: f64 = p.iter().map(|q| (q.0 - mx).powi(2)).sum();
    let sxy: f64 = p.iter().map(|q| (q.0 - mx) * (q.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

/// `m` uniform random points in `bounds` from `seed`, in Hilbert order (as `aarbf field`
/// queries them: neighbouring queries share tree nodes).
pub fn query_points(m: usize, bounds: Bounds, seed: u64) -> Vec<glam::DVec3> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let (lo, hi) = (bounds.min, bounds.max);
    let points: Vec<glam::DVec3> = (0..m)
        .map(|_| lo + glam::DVec3::new(rng.random(), rng.random(), rng.random()) * (hi - lo))
        .collect();
    crate::accel::hilbert_order(&points, bounds)
        .iter()
        .map(|&i| points[i as usize])
        .collect()
}

/// A setting's text for a float (enough digits to tell sweeps apart).
pub fn value(v: f64) -> String {
    format!("{v:.6e}")
}

/// A plot line's name: the backend and variant, and the data set where there are several.
pub fn line_name(row: &Row, rows: &[Row]) -> String {
    let several = rows.iter().any(|r| r.data != row.data);
    if several {
        format!("{} ({})", row.series(), row.data)
    } else {
        row.series()
    }
}

/// The caption line stating how the frames were timed.
pub fn timing_caption(options: &Options) -> String {
    format!(
        "{}x{} px, 1 spp, {:?} integrator, mean over {} benchmark-orbit cameras; median of {} \
         repetitions, whiskers min to max.",
        options.image.0, options.image.1, options.integrator, options.cameras, options.repetitions
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponents_of_power_laws() {
        let p: Vec<(f64, f64)> = [1e4, 4e4, 1.6e5].iter().map(|&x| (x, 3.0 * x)).collect();
        assert!((fitted_exponent(&p).unwrap() - 1.0).abs() < 1e-12);
        let p: Vec<(f64, f64)> = [1.0, 2.0, 4.0].iter().map(|&x| (x, x * x)).collect();
        assert!((fitted_exponent(&p).unwrap() - 2.0).abs() < 1e-12);
        assert!(fitted_exponent(&[(1.0, 1.0)]).is_none());
    }
}
