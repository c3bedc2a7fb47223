//! `aarbf field`: the density and attribute fields at query points.

use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use glam::DVec3;

use crate::backend::{self, BackendKind, Precision, StepInput, parse_precision};
use crate::field::{Classification, RegularGrid, finish_sums};
use crate::io::{At, npy};
use crate::scene_file::resolve::{DataArgs, FieldOptions, Resolved, resolve};

/// The arguments of `aarbf field`: the data and field as every command takes them, where to
/// evaluate (query points or a grid), the output file, the backend and the precision.
#[derive(Debug, Args)]
#[command(group(clap::ArgGroup::new("where").required(true).args(["queries", "grid"])))]
pub struct FieldArgs {
    /// Where the data comes from (a scene file, or the data path and format), the step, and how
    /// it is read (particle type, units, smoothing, periodic box, cache).
    #[command(flatten)]
    pub data: DataArgs,
    /// How the field is defined: attribute and range, radii, maps, classification, cluster size,
    /// kernel.
    #[command(flatten)]
    pub field: FieldOptions,
    /// Query points: an M x 3 .npy array (float32 or float64).
    #[arg(long)]
    pub queries: Option<PathBuf>,
    /// Instead of query points, a regular grid over the series' bounds: `NXxNYxNZ` (or `N` for
    /// N^3) cell-centred points, x fastest (NumPy: `reshape(NZ, NY, NX, -1)`), as yt's covering
    /// grids sample. The CPU backend scatters each particle onto the points it reaches rather
    /// than querying point by point.
    #[arg(long, value_parser = parse_grid)]
    pub grid: Option<[usize; 3]>,
    /// Output .npy, float64: M x 2 (Phi, Theta) for post-classification, M x 4 (Phi, r, g, b)
    /// for pre-classification. Theta is in the attribute's units; 0 where Phi is 0.
    #[arg(long)]
    pub out: PathBuf,
    /// `cpu` is the f64 reference; `wgpu` (LBVH compute) and `ash` (Vulkan ray-tracing
    /// pipeline) evaluate in f32 on a GPU (or lavapipe); `auto` picks the best.
    #[arg(long, value_enum, default_value = "cpu")]
    pub backend: BackendKind,
    /// Precision of positions and arithmetic: `auto` (the cheapest representation whose whole
    /// error bound, printed, keeps Phi within 1e-5: f32, then compensated sums or double-single
    /// pairs on the GPU backends, the f64 reference on the CPU), `auto:TOLERANCE`, `f32`,
    /// `f32c` (compensated sums), `ds` (double-single, compensated) or `f64` (the CPU's
    /// reference, exact to rounding; `ds` on the GPU backends).
    #[arg(long, default_value = "auto")]
    pub precision: String,
    /// Overwrite an existing output.
    #[arg(long)]
    pub force: bool,
}

/// Runs `aarbf field`: evaluates the fields at the query points or grid and writes them as an
/// `.npy` array to `--out`, then reports the times.
pub fn run(args: FieldArgs) -> anyhow::Result<()> {
    crate::io::output::check_writable(&args.out, args.force)?;
    let resolved = resolve(&args.data, &args.field)?;
    if resolved.field.attribute.is_none() {
        anyhow::bail!(
            "--attribute is required: the field carries an attribute (the data has: {})",
            resolved.series.attributes_in_data()?.join(", ")
        );
    }
    let queries = match (&args.queries, args.grid) {
        // The periodic field at a point outside the box is the field at its wrapped point.
        (Some(path), _) => Queries::Points(match resolved.periodic {
            Some(b) => read_queries(path)?.into_iter().map(|q| b.wrap(q)).collect(),
            None => read_queries(path)?,
        }),
        (None, Some(dims)) => {
            let b = resolved.domain();
            tracing::info!(
                "grid of {}x{}x{} cell-centred points over {:?}..{:?}",
                dims[0],
                dims[1],
                dims[2],
                b.min.to_array(),
                b.max.to_array()
            );
            Queries::Grid(RegularGrid::cell_centred(b.min, b.max, dims))
        }
        (None, None) => anyhow::bail!("--queries or --grid is required"),
    };

    let bar = crate::progress::bar(queries.len() as u64, "evaluating");
    let evaluated = evaluate(&resolved, &queries, args.backend, &args.precision, |n| {
        bar.inc(n as u64)
    })?;
    bar.finish_and_clear();
    let Evaluated {
        samples,
        pre,
        build_time,
        eval_time,
        count,
        backend_name,
    } = evaluated;
    let cols = if pre { 4 } else { 2 };
    let mut out = Vec::with_capacity(samples.len() * cols);
    for s in &samples {
        out.extend_from_slice(&s[..cols]);
    }
    crate::io::output::write_atomically(&args.out, args.force, |tmp| {
        npy::write_matrix(tmp, samples.len(), cols, &out)
    })?;
    tracing::info!(
        "{} particles ({} backend, K = {}, radius {:.6}), {} queries: build {:.3} s, evaluation {:.3} s ({:.3} M queries/s)",
        count,
        backend_name,
        resolved.cluster,
        resolved.field.radius,
        queries.len(),
        build_time.as_secs_f64(),
        eval_time.as_secs_f64(),
        queries.len() as f64 / eval_time.as_secs_f64().max(1e-9) / 1e6
    );
    Ok(())
}

/// The fields [`evaluate`] computed, as `aarbf field` writes them.
pub struct Evaluated {
    /// Per query: (Phi, Theta, 0, 0) for post-classification, (Phi, r, g, b) for pre.
    pub samples: Vec<[f64; 4]>,
    /// Whether the field is pre-classified (four columns, not two).
    pub pre: bool,
    /// Uploading the step to the backend and building its structure (none when the backend scatters
    /// onto a grid).
    pub build_time: std::time::Duration,
    /// Evaluating the fields at every query.
    pub eval_time: std::time::Duration,
    /// The step's particles.
    pub count: usize,
    /// The backend that evaluated (`cpu`, `wgpu` or `ash`).
    pub backend_name: &'static str,
}

/// The density and attribute fields of `resolved`'s step at `queries` on backend `kind` at
/// `precision` (spelled as `--precision`): what `aarbf field` writes, and what the Python
/// package's `Scene.field` and `Scene.grid` return. `progress` is told of queries done.
pub fn evaluate(
    resolved: &Resolved,
    queries: &Queries,
    kind: BackendKind,
    precision: &str,
    progress: impl Fn(usize),
) -> anyhow::Result<Evaluated> {
    let step = resolved.series.step(resolved.step)?;
    // In a periodic box the step goes to the backend with its images near the faces.
    let images = match resolved.periodic {
        Some(b) => Some(b.images(&step, &resolved.field, resolved.series_range())?),
        None => None,
    };
    let (step_data, step_bounds) = match (&images, resolved.periodic) {
        (Some(images), Some(b)) => (&images.step, b.bounds().grown(images.largest_reach)),
        _ => (&step, resolved.series.bounds()),
    };
    if let Some(images) = &images {
        tracing::info!(
            "periodic: {} images of particles near the box's faces{}",
            images.step.len() - images.originals,
            if images.wrapped > 0 {
                format!(
                    ", {} particles outside the box wrapped into it",
                    images.wrapped
                )
            } else {
                String::new()
            }
        );
    }
    let mut backend = backend::create(kind)?;
    let built = Instant::now();
    backend.upload(&StepInput {
        step: step_data,
        field: &resolved.field,
        cluster: resolved.cluster,
        series_bounds: step_bounds,
        series_range: resolved.series_range(),
        precision: parse_precision(precision, Precision::FIELD).map_err(anyhow::Error::msg)?,
    })?;
    // A backend that scatters particles onto a grid builds no tree for one.
    if !(matches!(queries, Queries::Grid(_)) && backend.capabilities().scatters_grids) {
        backend.build()?;
    }
    let build_time = built.elapsed();
    if let Some(r) = backend.representation() {
        let name = backend.capabilities().name;
        if r.meets_tolerance() {
            tracing::info!("{name}: {r}");
        } else {
            tracing::warn!(
                "{name}: {r}. This backend's f32 arithmetic cannot promise that tolerance for this scene: --backend cpu computes in f64, or --precision auto:TOL states a looser one"
            );
        }
    }
    // The attribute's normalisation range, as the backends use it (Particles::prepare).
    let range = resolved
        .field
        .attribute_range
        .or_else(|| resolved.series_range())
        .or_else(|| {
            let a = step.attribute(resolved.field.attribute.as_deref()?)?;
            crate::values::value_range(&a.values)
        })
        .unwrap_or((0.0, 0.0));
    let pre = resolved.field.classification == Classification::Pre;

    let started = Instant::now();
    let mut samples = vec![[0.0; 4]; queries.len()];
    let sums = match queries {
        Queries::Points(points) => {
            backend::query_in_hilbert_order(backend.as_mut(), points, progress)?
        }
        Queries::Grid(grid) => backend.query_grid(grid)?,
    };
    samples
        .par_iter_mut()
        .zip(sums.into_par_iter())
        .for_each(|(s, (phi, num))| {
            let f = finish_sums(phi, num, !pre, range);
            *s = [f.phi, f.theta[0], f.theta[1], f.theta[2]];
        });
    let eval_time = started.elapsed();
    Ok(Evaluated {
        samples,
        pre,
        build_time,
        eval_time,
        count: step.len(),
        backend_name: backend.capabilities().name,
    })
}

/// Where the field is evaluated.
pub enum Queries {
    /// Arbitrary points in data coordinates, one sample each, in the given order.
    Points(Vec<DVec3>),
    /// The points of a regular grid, i fastest; a backend that scatters grids (the CPU) splats each
    /// particle onto the points it reaches.
    Grid(RegularGrid),
}

impl Queries {
    /// The number of query points.
    pub fn len(&self) -> usize {
        match self {
            Queries::Points(p) => p.len(),
            Queries::Grid(g) => g.len(),
        }
    }

    /// Whether there are no query points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The query points of an M x 3 `.npy` file, checked finite.
fn read_queries(path: &std::path::Path) -> anyhow::Result<Vec<DVec3>> {
    let queries = npy::read_matrix(At::new(path, None))?;
    anyhow::ensure!(
        queries.cols == 3,
        "{}: queries must be an M x 3 array, found {} columns",
        path.display(),
        queries.cols
    );
    let points: Vec<DVec3> = (0..queries.rows)
        .map(|i| DVec3::from_slice(queries.row(i)))
        .collect();
    if let Some(i) = points.iter().position(|p| !p.is_finite()) {
        anyhow::bail!("{}: query {i} is not finite: {}", path.display(), points[i]);
    }
    Ok(points)
}

/// `NXxNYxNZ` or `N` (a cube), each from 1 to 4096.
fn parse_grid(text: &str) -> Result<[usize; 3], String> {
    let parts: Vec<&str> = text.split(['x', 'X']).collect();
    let numbers: Vec<usize> = parts
        .iter()
        .map(|p| p.trim().parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{text}' is not NXxNYxNZ or N (positive integers)"))?;
    let dims = match numbers[..] {
        [n] => [n; 3],
        [x, y, z] => [x, y, z],
        _ => return Err(format!("'{text}' is not NXxNYxNZ or N")),
    };
    if dims.iter().any(|&d| !(1..=4096).contains(&d)) {
        return Err(format!(
            "grid dimensions must lie in 1..=4096, got '{text}'"
        ));
    }
    Ok(dims)
}
