//! Data and field options shared by the commands and the viewer, merged with a scene file
//! (flags win), and resolved into an open series and its field.

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{Context, bail};
use clap::Args;

use super::{DataSection, FieldSection, MapSpec, RadiusSpec, RangeSpec, SceneFile};
use crate::accel::ClusterSize;
use crate::field::{Classification, FieldSettings, Kernel, PerParticle};
use crate::io::{AttributeSelection, Format, ParticleType, ReadOptions};
use crate::scene::maps::{ColorMap, DensityMap, PiecewiseLinear, RadiusMap};
use crate::scene::{OpenOptions, TimeSeries};
use crate::values::Step;

/// Where the data comes from.
#[derive(Debug, Clone, Args)]
pub struct DataArgs {
    /// A scene file (TOML) with data and field settings; flags override it.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// The data: a file, a directory or a glob (a time series sorted naturally).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The file format, when the extension does not tell.
    #[arg(long, value_enum)]
    pub format: Option<Format>,
    /// The time step to use (0-based).
    #[arg(long, conflicts_with = "time")]
    pub step: Option<usize>,
    /// The step whose time is nearest T: the `timestep` of a `.pvd` collection, an HDF5
    /// snapshot's `Time`; where the data records no times, a step's time is its index.
    #[arg(long, value_name = "T")]
    pub time: Option<f64>,
    /// The particle type of an HDF5 snapshot: 0..5 or gas, dm, disk, bulge, stars, bh
    /// (default gas).
    #[arg(long, value_name = "TYPE")]
    pub particle_type: Option<ParticleType>,
    /// Read an HDF5 snapshot's comoving positions, smoothing lengths and densities in
    /// physical units (times the scale factor's power each has).
    #[arg(long)]
    pub physical: bool,
    /// Smoothing lengths from neighbours for data without one: `knn:K` (K = 32 by default)
    /// gives each particle h = the distance to its K-th nearest neighbour, as the attribute
    /// `h_knnK`, the per-particle radius unless --radius-attribute names another. Cached in
    /// `.aarbf-smoothing/` beside the data.
    #[arg(long, value_name = "knn:K")]
    pub smoothing: Option<crate::scene::smoothing::Smoothing>,
    /// Wrap the field at the faces of a periodic box: particles near one face are felt across
    /// it, so slices and renders of the box have no seam. `--periodic` alone takes the box an
    /// HDF5 snapshot's header states; `--periodic L` or `LX,LY,LZ` gives the box [0, L) for
    /// any format. Default: on where a snapshot's header says its box is periodic.
    #[arg(long, value_name = "L|LX,LY,LZ", num_args = 0..=1, default_missing_value = "header")]
    pub periodic: Option<super::periodic::PeriodicSpec>,
    /// Treat the data's box as open, even where the snapshot says it is periodic.
    #[arg(long, conflicts_with = "periodic")]
    pub no_periodic: bool,
    /// The most memory, in MiB, that steps read from disk are kept in (the least recently
    /// used go first; a series larger than this plays with memory bounded by it).
    #[arg(long, default_value_t = 2048)]
    pub cache_mib: usize,
    /// Read every step again for the series' bounds and ranges, whatever the index beside the
    /// data says (for files rewritten within the file system's time resolution with the same
    /// size); the index is rewritten.
    #[arg(long)]
    pub rescan: bool,
}

impl DataArgs {
    /// What to read from files that hold a choice: the flags over the scene file's.
    pub fn read_options(&self, scene: &DataSection) -> ReadOptions {
        ReadOptions {
            particle_type: self
                .particle_type
                .or(scene.particle_type)
                .unwrap_or_default(),
            physical: self.physical || scene.physical.unwrap_or(false),
        }
    }
}

/// Where the view stands, for the commands that make images (render, view).
#[derive(Debug, Clone, Default, Args)]
pub struct ViewFlags {
    /// The axis pointing up in the image: x, y, z, -x, -y or -z. Default: z (simulation data
    /// is z-up, gravity along -z); planar (2D) data is viewed face on.
    #[arg(long, value_name = "AXIS")]
    pub up: Option<crate::scene::UpAxis>,
    /// The camera at azimuth and elevation (degrees, about the up axis; 0,0 looks from -y with
    /// z up) around the data's centre, and optionally its distance in data units (default:
    /// the data fills the view).
    #[arg(long, value_name = "AZ,EL[,DIST]")]
    pub camera_from: Option<String>,
}

impl ViewFlags {
    /// Writes these flags over a scene file's `[camera]` (flags win).
    pub fn apply(&self, camera: &mut super::CameraSection) -> anyhow::Result<()> {
        if let Some(up) = self.up {
            camera.up = Some(up.vector().to_array());
            camera.up_axis = Some(up);
        }
        if let Some(from) = &self.camera_from {
            super::parse_camera_from(from).map_err(anyhow::Error::msg)?;
            camera.from = Some(from.clone());
            // The flag places the camera: a scene file's eye and target give way to it.
            camera.eye = None;
            camera.at = None;
            camera.orbit = None;
        }
        Ok(())
    }
}

/// How the field is defined.
#[derive(Debug, Clone, Default, Args)]
pub struct FieldOptions {
    /// The attribute the field carries (its colour).
    #[arg(long)]
    pub attribute: Option<String>,
    /// The range the colour map spans: LO,HI; `series` (the least to the largest value over
    /// the series, the default); `robust` (the series' 1st to 99th percentile: outliers do not
    /// wash the rest into one colour); `step` or `robust-step` (the same over the step shown,
    /// each frame of a sequence its own).
    #[arg(long, value_name = "LO,HI|series|robust|step|robust-step")]
    pub attribute_range: Option<RangeSpec>,
    /// Global RBF radius: a length, or a percentage of the series' bounding-box diagonal
    /// ("1.5%"). Default: twice the median smoothing length (h, hsml, SmoothingLength) of the
    /// first step where the data has one, else twice the particles' spacing (the median
    /// nearest-neighbour distance in the first step); 2 with --radius-attribute (radius 2h,
    /// the SPH kernel's support).
    #[arg(long)]
    pub radius: Option<RadiusSpec>,
    /// A per-particle radius (smoothing length) attribute, multiplied by the global radius.
    #[arg(long)]
    pub radius_attribute: Option<String>,
    /// Radius map m(t) in [0, 1]: a number, "ramp", "ramp:a:b" or points "x:y,x:y,...".
    #[arg(long)]
    pub radius_map: Option<String>,
    /// Density map w(t) >= 0, spelled like --radius-map.
    #[arg(long)]
    pub density_map: Option<String>,
    /// Colour map: a preset (viridis, plasma, inferno, magma, turbo, cool-warm, grayscale)
    /// or a ParaView colour-map .json file.
    #[arg(long)]
    pub colormap: Option<String>,
    /// post: average the attribute, then colour it; pre: colour each particle, then average.
    #[arg(long, value_enum)]
    pub classification: Option<Classification>,
    /// Particles per cluster box (1, 2, 4, 8, 16), Hilbert-sorted. Unset: 16 where particles
    /// overlap (4 or more reach a particle centre on average), 4 where they barely do.
    #[arg(long)]
    pub cluster: Option<ClusterSize>,
    /// The kernel: the paper's Gaussian RBF (unnormalised, the default), or an SPH kernel
    /// normalised in 3D and weighted by each particle's volume m/rho, so the field is the SPH
    /// interpolant sarracen and yt compute (support 2h; 3h for the quintic).
    #[arg(long, value_enum)]
    pub kernel: Option<Kernel>,
    /// An SPH kernel's masses: an attribute, or one value for every particle. Default: the
    /// data's Masses, mass or m.
    #[arg(long, value_name = "ATTRIBUTE|VALUE")]
    pub mass: Option<PerParticle>,
    /// An SPH kernel's densities: an attribute, or one value for every particle (1 makes
    /// Phi the SPH density estimate, the sum of m W). Default: the data's Densities, Density
    /// or rho.
    #[arg(long, value_name = "ATTRIBUTE|VALUE")]
    pub density: Option<PerParticle>,
}

/// The default global radius over the particles' spacing: twice the median nearest-neighbour
/// distance joins neighbours (the particle's Gaussian then has a standard deviation of 2/3 of
/// the spacing), as SPH users expect of a kernel.
pub const RADIUS_PER_SPACING: f64 = 2.0;

/// The default global radius with a per-particle smoothing length h: radius 2 h, the support
/// of the cubic-spline SPH kernel as SWIFT and sarracen define h.
pub const RADIUS_PER_SMOOTHING_LENGTH: f64 = 2.0;

/// Names smoothing-length arrays go by in SPH codes' output (compared ignoring case).
const SMOOTHING_LENGTH_NAMES: [&str; 6] = [
    "h",
    "hsml",
    "smoothinglength",
    "smoothinglengths",
    "smoothing_length",
    "smoothing_lengths",
];

/// The global radius when none is given, derived from the data as the other automatic values
/// are, from the series' first step (so every step and command agrees), with a sentence saying
/// how (for the log and `aarbf info`). `first_in_full` is that step with every attribute its
/// file holds (to find a smoothing length the field does not use).
pub fn default_radius(
    series: &TimeSeries,
    radius_attribute: Option<&str>,
    first_in_full: Option<&Step>,
    kernel: Kernel,
) -> anyhow::Result<(f64, String)> {
    if let Some(h) = radius_attribute {
        if kernel.is_sph() {
            let s = kernel.support();
            return Ok((
                s,
                format!(
                    "{s} x '{h}' for each particle (the {kernel} kernel's support, {s}h; \
                     --radius scales it, and h with it)"
                ),
            ));
        }
        return Ok((
            RADIUS_PER_SMOOTHING_LENGTH,
            format!(
                "{RADIUS_PER_SMOOTHING_LENGTH} x '{h}' for each particle (the SPH kernel's \
                 support, 2h; --radius sets the factor)"
            ),
        ));
    }
    // A smoothing length in the data: its median sets the radius (2h, the kernel's support).
    let smoothing_length = first_in_full.and_then(|step| {
        step.attributes
            .iter()
            .find(|a| SMOOTHING_LENGTH_NAMES.contains(&a.name.to_ascii_lowercase().as_str()))
    });
    if let Some(h) = smoothing_length {
        let mut positive: Vec<f64> = h
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        if !positive.is_empty() {
            let middle = positive.len() / 2;
            let (_, &mut median, _) = positive.select_nth_unstable_by(middle, f64::total_cmp);
            let r = RADIUS_PER_SMOOTHING_LENGTH * median;
            let name = &h.name;
            return Ok((
                r,
                format!(
                    "{r:.6e}, {RADIUS_PER_SMOOTHING_LENGTH} x the median smoothing length \
                     '{name}' in step 0 ({median:.6e}); --radius-attribute {name} gives each \
                     particle its own, --radius sets a length or a percentage of the diagonal \
                     (\"1.5%\")"
                ),
            ));
        }
    }
    let spacing = if series.is_empty() {
        None
    } else {
        crate::accel::spacing::median_nearest_distance(&series.step(0)?.positions)
    };
    Ok(match spacing {
        Some(d) => {
            let r = RADIUS_PER_SPACING * d;
            (
                r,
                format!(
                    "{r:.6e}, {RADIUS_PER_SPACING} x the particles' spacing in step 0 (median \
                     nearest-neighbour distance {d:.6e}); --radius sets a length or a \
                     percentage of the diagonal (\"1.5%\")"
                ),
            )
        }
        None => {
            let r = RadiusSpec::DEFAULT.resolve(series.bounds().diagonal());
            (
                r,
                format!(
                    "{r:.6e}, {} of the bounding-box diagonal (step 0 has no two particles \
                     apart to measure a spacing); --radius sets it",
                    RadiusSpec::DEFAULT
                ),
            )
        }
    })
}

/// The names of a step's attributes (none without a step).
fn names_of(step: Option<&Step>) -> Vec<String> {
    step.map(|s| s.attribute_names().iter().map(|n| n.to_string()).collect())
        .unwrap_or_default()
}

/// Data and field settings after merging flags over the scene file.
pub struct Resolved {
    /// The scene file (or an empty one), for the sections a command reads itself.
    pub scene: SceneFile,
    pub series: TimeSeries,
    pub step: usize,
    pub field: FieldSettings,
    pub cluster: ClusterSize,
    /// Where the data came from, and how it was spelled, for writing a scene file back.
    pub data_path: PathBuf,
    pub format: Option<Format>,
    /// What was read of files that hold a choice (an HDF5 snapshot's particle type).
    pub read: ReadOptions,
    pub colormap: Option<String>,
    /// How long opening the series took, and the steps it decoded: the rest of resolving is
    /// the settings taken from the data (the cluster size, ranges), which `bench playback`
    /// reports apart.
    pub opened_in: std::time::Duration,
    pub decoded_at_open: usize,
    /// How the attribute's range was chosen: a per-step range is chosen again for each step
    /// shown ([`Resolved::range_for_step`]).
    pub range: RangeSpec,
    /// The periodic box the field wraps at ([`super::periodic::choose`]), if any.
    pub periodic: Option<crate::field::PeriodicBox>,
}

impl Resolved {
    /// The domain an image or grid of the field covers: the periodic box where there is one,
    /// else the series' bounds.
    pub fn domain(&self) -> crate::values::Bounds {
        self.periodic
            .map_or_else(|| self.series.bounds(), |b| b.bounds())
    }

    /// The data and field sections of a scene file that reproduces these settings.
    pub fn scene_sections(&self) -> (DataSection, FieldSection) {
        scene_sections(
            &self.data_path,
            self.format,
            self.read,
            self.step,
            &self.field,
            self.cluster,
            self.colormap.as_deref(),
            self.periodic,
        )
    }
}

/// The data and field sections of a scene file that reproduces a field of the data at
/// `data_path`: the path absolute, the radius in data units, the maps as their control points.
#[allow(clippy::too_many_arguments)] // one per section entry; a struct would only rename them
pub fn scene_sections(
    data_path: &std::path::Path,
    format: Option<Format>,
    read: ReadOptions,
    step: usize,
    f: &FieldSettings,
    cluster: ClusterSize,
    colormap: Option<&str>,
    periodic: Option<crate::field::PeriodicBox>,
) -> (DataSection, FieldSection) {
    let absolute = |p: &std::path::Path| std::path::absolute(p).unwrap_or(p.to_path_buf());
    (
        DataSection {
            path: Some(absolute(data_path)),
            format,
            step: Some(step),
            attribute: f.attribute.clone(),
            attribute_range: f.attribute_range.map(|(a, b)| RangeSpec::Fixed(a, b)),
            radius_attribute: f.radius_attribute.clone(),
            particle_type: (read.particle_type != ParticleType::GAS).then_some(read.particle_type),
            physical: read.physical.then_some(true),
            smoothing: f
                .radius_attribute
                .as_deref()
                .and_then(crate::scene::smoothing::Smoothing::of_attribute),
            periodic: Some(super::periodic::PeriodicSetting::of(periodic)),
        },
        FieldSection {
            radius: Some(RadiusSpec::Absolute(f.radius)),
            radius_map: Some(MapSpec::Points(f.radius_map.0.points().to_vec())),
            density_map: Some(MapSpec::Points(f.density_map.0.points().to_vec())),
            colormap: colormap.map(|c| {
                if c.ends_with(".json") {
                    absolute(std::path::Path::new(c))
                        .to_string_lossy()
                        .into_owned()
                } else {
                    c.to_owned()
                }
            }),
            classification: Some(f.classification),
            cluster: Some(cluster),
            kernel: f.kernel.is_sph().then_some(f.kernel),
            mass: f.mass.clone(),
            density: f.density.clone(),
        },
    )
}

impl Resolved {
    /// Sets the field's range for step `step` where the range is per step (`--attribute-range
    /// step` or `robust-step`); other ranges are the series' and stay.
    pub fn range_for_step(&mut self, step: usize) -> anyhow::Result<()> {
        if self.range.per_step() {
            self.field.attribute_range = self
                .range
                .resolve(&self.series, self.field.attribute.as_deref(), step)?
                .0;
        }
        Ok(())
    }

    /// The series-wide range of the field's attribute.
    pub fn series_range(&self) -> Option<(f64, f64)> {
        let name = self.field.attribute.as_deref()?;
        let a = self.series.attribute(name)?;
        Some((a.min, a.max))
    }
}

/// Resolves the data and the field as [`resolve`] does, for a command that makes an image:
/// without an attribute (flag or scene file), the image is coloured by the data's first
/// attribute, which is said with the others (`--color-by-density` colours by density).
pub fn resolve_for_images(data: &DataArgs, options: &FieldOptions) -> anyhow::Result<Resolved> {
    resolve_choosing(data, options, true)
}

/// Resolves the data and the field: flags over the scene file, the series opened with the
/// attributes the field uses, and the automatic values of the data (radius, cluster size,
/// range) chosen and said. Without an attribute the field carries none (density only).
pub fn resolve(data: &DataArgs, options: &FieldOptions) -> anyhow::Result<Resolved> {
    resolve_choosing(data, options, false)
}

fn resolve_choosing(
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    let scene = match &data.scene {
        Some(path) => SceneFile::load(path)?,
        None => SceneFile::default(),
    };
    resolve_from(scene, None, data, options, first_attribute_by_default)
}

/// Resolves as [`resolve`] (or, with `first_attribute_by_default`, [`resolve_for_images`])
/// does, with the scene file given as a value instead of `data.scene`'s path (the Python
/// package builds one from its arguments).
pub fn resolve_scene(
    scene: SceneFile,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    resolve_from(scene, None, data, options, first_attribute_by_default)
}

/// Resolves the field over a series already in memory ([`TimeSeries::from_steps`]: arrays the
/// Python package was handed) exactly as [`resolve_scene`] does over data read from a path;
/// `name` stands for the data's path in messages and in `Resolved::data_path`.
pub fn resolve_in_memory(
    series: TimeSeries,
    name: &std::path::Path,
    scene: SceneFile,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    resolve_from(
        scene,
        Some((series, name.to_path_buf())),
        data,
        options,
        first_attribute_by_default,
    )
}

fn resolve_from(
    scene: SceneFile,
    memory: Option<(TimeSeries, PathBuf)>,
    data: &DataArgs,
    options: &FieldOptions,
    first_attribute_by_default: bool,
) -> anyhow::Result<Resolved> {
    let (memory, path) = match memory {
        Some((series, name)) => (Some(series), name),
        None => (
            None,
            data.data
                .clone()
                .or(scene.data.path.clone())
                .context("no data given: pass --data <path> or a --scene file with [data] path")?,
        ),
    };
    // The first step with every attribute it holds: from memory, or read from its file.
    let read_first_in_full = |read: ReadOptions| -> anyhow::Result<Option<Arc<Step>>> {
        if let Some(series) = &memory {
            return Ok(series.first_step_in_full()?);
        }
        let refs = crate::io::list_steps_reading(&path, data.format.or(scene.data.format), read)?;
        Ok(match refs.first() {
            Some(first) => Some(Arc::new(crate::io::read_step(
                first,
                &AttributeSelection::All,
            )?)),
            None => None,
        })
    };
    let read = data.read_options(&scene.data);
    let mut attribute = options.attribute.clone().or(scene.data.attribute.clone());
    // The first step with every attribute it holds, read where a default needs it.
    let mut first_in_full: Option<Arc<Step>> = None;
    if attribute.is_none() && first_attribute_by_default {
        first_in_full = read_first_in_full(read)?;
        let names = names_of(first_in_full.as_deref());
        attribute = names.first().cloned();
        match &attribute {
            Some(first) => tracing::info!(
                "colour: '{first}', the data's first attribute (no --attribute given); the \
                 others: {} (--attribute NAME picks one, --color-by-density colours by \
                 density)",
                if names.len() > 1 {
                    names[1..].join(", ")
                } else {
                    "none".to_owned()
                }
            ),
            None => tracing::info!("colour: by density (the data has no attributes)"),
        }
    }
    let smoothing = data.smoothing.or(scene.data.smoothing);
    let radius_attribute = options
        .radius_attribute
        .clone()
        .or(scene.data.radius_attribute.clone())
        .or(smoothing.map(|s| s.attribute()));
    let kernel = options.kernel.or(scene.field.kernel).unwrap_or_default();
    let (mut radius_attribute, mass, density) = if kernel.is_sph() {
        let mass = options.mass.clone().or(scene.field.mass.clone());
        let density = options.density.clone().or(scene.field.density.clone());
        if first_in_full.is_none()
            && (radius_attribute.is_none() || mass.is_none() || density.is_none())
        {
            first_in_full = read_first_in_full(read)?;
        }
        let sph = super::kernel::resolve(
            kernel,
            radius_attribute,
            mass,
            density,
            &names_of(first_in_full.as_deref()),
            &SMOOTHING_LENGTH_NAMES,
            options.radius.or(scene.field.radius).is_some(),
        )?;
        (sph.radius_attribute, Some(sph.mass), Some(sph.density))
    } else {
        (radius_attribute, None, None)
    };
    let attribute_of = |q: &Option<PerParticle>| match q {
        Some(PerParticle::Attribute(name)) => Some(name.clone()),
        _ => None,
    };
    let (mass_attribute, density_attribute) = (attribute_of(&mass), attribute_of(&density));
    let opening = std::time::Instant::now();
    let mut asked_step = data.step.or(scene.data.step).unwrap_or(0);
    let series = match memory {
        Some(series) => {
            // Held whole in memory: every attribute is there; check the ones asked for, a
            // name in the other number or case being the data's, as for a file.
            if let Some(first) = series.first_step_in_full()? {
                let names = names_of(Some(&first));
                for a in [&mut attribute, &mut radius_attribute] {
                    let Some(name) = a.clone() else { continue };
                    if first.attribute(&name).is_some() {
                        continue;
                    }
                    let found = super::names::other_spelling(&name, &names).with_context(|| {
                        format!(
                            "{}: no attribute '{name}'; the particles have: {}",
                            path.display(),
                            names.join(", ")
                        )
                    })?;
                    tracing::info!(
                        "attribute '{name}': the data has no attribute of that name, but has \
                         '{found}': using '{found}'"
                    );
                    *a = Some(found);
                }
                for name in mass_attribute.iter().chain(density_attribute.iter()) {
                    anyhow::ensure!(
                        first.attribute(name).is_some(),
                        "{}: no attribute '{name}'; the particles have: {}",
                        path.display(),
                        names.join(", ")
                    );
                }
            }
            series
        }
        None => {
            let open = |attribute: &Option<String>, radius_attribute: &Option<String>| {
                TimeSeries::open(
                    &path,
                    &OpenOptions {
                        format: data.format.or(scene.data.format),
                        read,
                        smoothing,
                        attributes: AttributeSelection::Only(
                            attribute
                                .iter()
                                .chain(radius_attribute.iter())
                                .chain(mass_attribute.iter())
                                .chain(density_attribute.iter())
                                .cloned()
                                .collect(),
                        ),
                        cache_bytes: data.cache_mib << 20,
                        // A batch frame uses the final series values, never provisional ones.
                        background_scan: false,
                        rescan: data.rescan,
                    },
                )
            };
            let mut opened = open(&attribute, &radius_attribute);
            // A name the data spells in the other number or case (SWIFT's `Temperatures` for
            // `Temperature`) is the data's, said in the log; at most the two names asked for.
            for _ in 0..2 {
                let Err(crate::io::DataError {
                    problem: crate::io::Problem::MissingAttribute { name, names, .. },
                    ..
                }) = &opened
                else {
                    break;
                };
                let Some(found) = super::names::other_spelling(name, names) else {
                    break;
                };
                let name = name.clone();
                tracing::info!(
                    "attribute '{name}': the data has no attribute of that name, but has '{found}': \
                 using '{found}'"
                );
                for a in [&mut attribute, &mut radius_attribute] {
                    if a.as_deref() == Some(name.as_str()) {
                        *a = Some(found.clone());
                    }
                }
                opened = open(&attribute, &radius_attribute);
            }
            opened.map_err(|e| {
                // The series' first step is checked when it opens, whichever step was asked for: say
                // so, or the message seems to be about the wrong step.
                let missing = matches!(e.problem, crate::io::Problem::MissingAttribute { .. });
                if missing && asked_step != 0 {
                    anyhow::Error::new(e).context(format!(
                    "the attributes asked for must be in every step of the series, and its first \
                     step lacks one (step {asked_step} was asked for)"
                ))
                } else {
                    e.into()
                }
            })?
        }
    };
    if let Some(time) = data.time {
        let (step, at) = series
            .step_at_time(time)
            .with_context(|| format!("--time {time}: the series has no steps"))?;
        tracing::info!("--time {time}: step {step} (time {at}), the nearest");
        asked_step = step;
    }
    let opened_in = opening.elapsed();
    let decoded_at_open = series.steps_decoded();
    let (periodic_spec, no_periodic) =
        super::periodic::merge(data.periodic, data.no_periodic, scene.data.periodic);
    let periodic = super::periodic::choose(&series, periodic_spec, no_periodic)?;
    let step = asked_step;
    if step >= series.len() {
        bail!(
            "{}: step {step} does not exist; the series has {} steps (0..{})",
            path.display(),
            series.len(),
            series.len() - 1
        );
    }
    let map = |flag: &Option<String>,
               file: &Option<MapSpec>|
     -> anyhow::Result<Option<PiecewiseLinear>> {
        Ok(match (flag, file) {
            (Some(text), _) => Some(text.parse()?),
            (None, Some(spec)) => Some(spec.to_map()?),
            (None, None) => None,
        })
    };
    let radius_map = map(&options.radius_map, &scene.field.radius_map)?
        .map(RadiusMap::new)
        .transpose()?
        .unwrap_or_default();
    let density_map = map(&options.density_map, &scene.field.density_map)?
        .map(DensityMap::new)
        .transpose()?
        .unwrap_or_default();
    let colormap = options.colormap.clone().or(scene.field.colormap.clone());
    let color_map = match &colormap {
        Some(spec) => ColorMap::from_name_or_file(spec)?,
        None => ColorMap::default(),
    };
    let radius_spec = options.radius.or(scene.field.radius);
    // The first step is read in full (every attribute its file holds) only where a message or
    // a default needs what the series did not select: the data's attributes when the field
    // carries none, a smoothing length for the default radius.
    let first_in_full = match first_in_full {
        Some(step) => Some(step),
        None if attribute.is_none() || (radius_spec.is_none() && radius_attribute.is_none()) => {
            series.first_step_in_full()?
        }
        None => None,
    };
    let names_in_data = names_of(first_in_full.as_deref());
    if attribute.is_none() && !first_attribute_by_default {
        tracing::info!(
            "colour: by density (no --attribute given); the data's attributes: {} (--attribute \
             NAME colours by one)",
            if names_in_data.is_empty() {
                "none".to_owned()
            } else {
                names_in_data.join(", ")
            }
        );
    }
    let radius = match radius_spec {
        Some(spec) => spec.resolve(series.bounds().diagonal()),
        None => {
            let (radius, how) = default_radius(
                &series,
                radius_attribute.as_deref(),
                first_in_full.as_deref(),
                kernel,
            )?;
            tracing::info!("radius: {how}");
            radius
        }
    };
    let range = options
        .attribute_range
        .or(scene.data.attribute_range)
        .unwrap_or(RangeSpec::Series);
    let (attribute_range, range_is) = range.resolve(&series, attribute.as_deref(), step)?;
    if let Some(name) = &attribute {
        let (lo, hi) = attribute_range
            .or_else(|| series.attribute(name).map(|a| (a.min, a.max)))
            .unwrap_or((0.0, 0.0));
        let over = if range.per_step() {
            format!("{range_is}, each step its own (step {step}: [{lo}, {hi}])")
        } else {
            format!("[{lo}, {hi}], {range_is}")
        };
        tracing::info!(
            "colour: '{name}' over {over} (--attribute-range LO,HI, series, robust, step or \
             robust-step)"
        );
    }
    let field = FieldSettings {
        attribute,
        attribute_range,
        radius,
        radius_attribute,
        radius_map,
        density_map,
        color_map,
        classification: options
            .classification
            .or(scene.field.classification)
            .unwrap_or_default(),
        kernel,
        mass,
        density,
    };
    let cluster = match options.cluster.or(scene.field.cluster) {
        Some(k) => k,
        None => {
            let overlap = crate::render::auto::mean_overlap(&series, &field)?;
            let k = ClusterSize::for_overlap(overlap);
            tracing::info!(
                "cluster size K = {k} ({overlap:.1} particles reach a particle centre on average; --cluster sets it)"
            );
            k
        }
    };
    // Every backend uses a map through its table; say so where that changes it visibly.
    for (what, map) in [
        ("radius map", &field.radius_map.0),
        ("density map", &field.density_map.0),
    ] {
        let e = map.table_error();
        if e > 1e-3 * map.max_value().abs().max(1e-300) {
            tracing::info!(
                "{what}: control points between the {}-sample table's points are rounded onto them; \
                 the map as used differs from them by up to {e:.2e} (points on multiples of 1/{} \
                 are exact)",
                crate::values::tables::TABLE_SIZE,
                crate::values::tables::TABLE_SIZE - 1
            );
        }
    }
    Ok(Resolved {
        format: data.format.or(scene.data.format),
        read,
        scene,
        series,
        step,
        field,
        cluster,
        data_path: path,
        colormap,
        opened_in,
        decoded_at_open,
        range,
        periodic,
    })
}
