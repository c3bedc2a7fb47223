//! `aarbf render`: images of one step or a range of steps.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, bail, ensure};
use clap::Args;

mod dist;
mod image;
mod plan;

use super::output_format::OutputFormat;
use plan::{Frame, plan_frames};

use crate::backend::{self, BackendKind};
use crate::dist::Balance;
use crate::render::converged::reference_settings;
use crate::render::legend::Legend;
use crate::render::target::{ErrorMetric, Target};
use crate::render::{Method, RenderSession, RenderSettings, SPLAT_K};
use crate::scene::Camera;
use crate::scene_file::resolve::{
    DataArgs, FieldOptions, Resolved, ViewFlags, resolve, resolve_for_images, resolve_with_reads,
};
use crate::scene_file::{CameraSection, MapSpec, SceneFile};
use crate::values::{Integrator, Light, NoiseKind};

/// The arguments of `aarbf render`: the data, field and camera as the scene file states them, the
/// steps to render, the output file, and the renderer's settings.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Where the data comes from (a scene file, or the data path and format), the step, and how
    /// it is read (particle type, units, smoothing, periodic box, cache).
    #[command(flatten)]
    pub data: DataArgs,
    /// How the field is defined: attribute and range, radii, maps, classification, cluster size,
    /// kernel.
    #[command(flatten)]
    pub field: FieldOptions,
    /// The camera: the up axis and where it looks from (over the scene file's `[camera]`).
    #[command(flatten)]
    pub view: ViewFlags,
    /// A range of steps, `a..b` (b excluded) or `a..=b`, optionally every n-th (`0..48:4`):
    /// writes OUT_<step>.<ext> for each. Frames already written are kept (a sequence resumes
    /// where it stopped) unless --force.
    #[arg(long, conflicts_with = "step")]
    pub steps: Option<String>,
    /// N frames with the camera turned once around the data (about the view's up axis through
    /// its focal point): writes OUT_<frame>.<ext>; with --steps the steps advance with the
    /// frames (frame k shows the k-th step of the range, cycling).
    #[arg(long)]
    pub orbit_sequence: Option<usize>,
    /// Bits per channel of a PNG: 8 (sRGB, opaque) or 16 (sRGB with alpha, for compositing).
    /// An .exr output is always linear 32-bit float RGBA with premultiplied alpha.
    #[arg(long, default_value_t = 8)]
    pub bit_depth: u8,
    /// Which backend queries the field (`auto`: ash on a GPU with ray tracing, else wgpu on a
    /// hardware GPU, else cpu).
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendKind,
    /// How the image is made: `rbf`, the paper's method (every sample queries the particles);
    /// `voxel`, a Table 3 baseline (the particles splatted into a grid with the same kernel,
    /// then the grid ray-marched with the same integrator, noise and transfer functions, both
    /// by the backend: on the GPU backends with atomics on the device; re-voxelised for every
    /// step); or `splat`, the other Table 3 baseline, Knoll et al.'s RT splatter (slabs one
    /// march step long, at most --splat-k particles each, sorted and composited front to back;
    /// emission-absorption).
    #[arg(long, value_enum, default_value = "rbf")]
    pub method: Method,
    /// For `--method voxel`: cells along the grid's longest side (cubic cells over the march
    /// box; the paper's baseline is 512).
    #[arg(long, default_value_t = crate::render::VOXEL_GRID)]
    pub voxel_grid: usize,
    /// For `--method splat`: hits each slab's buffer holds (more are lost, by design).
    #[arg(long, default_value_t = SPLAT_K)]
    pub splat_k: usize,
    /// Precision of positions and arithmetic: `auto` (the cheapest representation whose whole
    /// error bound keeps Phi within 1e-3: f32, then compensated sums or double-single pairs on
    /// the GPU backends, the f64 reference on the CPU; the default), `auto:TOLERANCE`, `f32`,
    /// `f32c` (compensated sums), `ds` (double-single, compensated) or `f64` (the CPU's
    /// reference; `ds` on the GPU backends).
    #[arg(long)]
    pub precision: Option<String>,
    /// Also write a scene file (TOML) holding every setting the image used, the automatic
    /// ones resolved (Phi_ref, step size, density scale, radius, camera): `aarbf render
    /// --scene` of it renders the same image (for a sequence: its first step).
    #[arg(long)]
    pub save_scene: Option<PathBuf>,
    /// Image width in pixels [default: 512].
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels [default: 512].
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples (frames) per pixel [default: 16].
    #[arg(long)]
    pub spp: Option<u32>,
    /// How a pixel's light is computed [default: ea].
    #[arg(long, value_enum)]
    pub integrator: Option<Integrator>,
    /// Where the random numbers come from [default: stbn].
    #[arg(long, value_enum)]
    pub noise: Option<NoiseKind>,
    /// Seed of the random numbers: the same seed gives the same image on the same backend
    /// [default: 1].
    #[arg(long)]
    pub seed: Option<u32>,
    /// Camera: ex,ey,ez,ax,ay,az,ux,uy,uz,fovy (eye, target, up, vertical FOV in degrees).
    #[arg(long, conflicts_with = "orbit")]
    pub camera: Option<Camera>,
    /// Camera i of the paper's n-camera benchmark orbit, as i/n (e.g. 3/50).
    #[arg(long)]
    pub orbit: Option<String>,
    /// Ray-marching step in data units (default: from the radius and particle spacing).
    #[arg(long)]
    pub step_size: Option<f64>,
    /// Extinction per unit length where the optical-density map is 1 (default 0.4 / radius).
    #[arg(long)]
    pub density_scale: Option<f64>,
    /// The density that maps to 1 for colour and extinction (default: estimated).
    #[arg(long)]
    pub phi_ref: Option<f64>,
    /// Optical-density map over Phi / Phi_ref, spelled like --radius-map (default "ramp").
    #[arg(long)]
    pub optical_map: Option<String>,
    /// Colour by density (C(Phi / Phi_ref)) instead of the attribute.
    #[arg(long)]
    pub color_by_density: bool,
    /// Light: azimuth,elevation,intensity (degrees, degrees, scale) for single scattering
    /// [default: 45,60,1].
    #[arg(long, value_name = "AZ,EL,I")]
    pub light: Option<String>,
    /// Light reaching every shaded sample whatever the shadows, as a fraction of the light's
    /// intensity, for single scattering [default: 0.25].
    #[arg(long)]
    pub ambient: Option<f64>,
    /// Background colour r,g,b (linear, 0..1) [default: 0,0,0].
    #[arg(long, value_name = "R,G,B")]
    pub background: Option<String>,
    /// Render until the estimated error against the converged reference is at most E (in
    /// --error-metric): the step and the samples per pixel are chosen (--spp is ignored; a set
    /// --step-size is kept) and the estimate is printed with the time it took.
    #[arg(long, value_name = "E")]
    pub target_error: Option<f64>,
    /// Render for S seconds (calibration included) at the step with the least estimated error,
    /// and print the estimate; with --target-error, stop at whichever comes first.
    #[arg(long, value_name = "S")]
    pub time_budget: Option<f64>,
    /// The measure of --target-error: `rmse` (linear RGB) or `flip` (perceptual, 0 to 1).
    #[arg(long, value_enum)]
    pub error_metric: Option<ErrorMetric>,
    /// Render the converged reference instead: the CPU backend in f64 with a step and samples
    /// fine enough that halving the step and doubling the samples each change the image by at
    /// most --reference-tolerance (both printed); cached per scene in
    /// $XDG_CACHE_HOME/aarbf/references.
    #[arg(long, conflicts_with_all = ["target_error", "time_budget"])]
    pub reference: bool,
    /// The reference's convergence tolerance (RMSE over linear RGB).
    #[arg(long, default_value_t = 1e-3, requires = "reference")]
    pub reference_tolerance: f64,
    /// Output image, .png or .exr (for a sequence: the prefix of its frames).
    #[arg(long)]
    pub out: PathBuf,
    /// Overwrite existing outputs.
    #[arg(long)]
    pub force: bool,
    /// Draw the colour legend over the image's bottom-left corner (the colour map as a bar,
    /// the attribute and the range it spans, or the density, and the values at its ends), and
    /// fail where it cannot be drawn. Without --legend or --no-legend it is drawn on 8-bit PNG
    /// images of at least 120x64 pixels (16-bit and .exr outputs are for compositing).
    #[arg(long)]
    pub legend: bool,
    /// Draw no colour legend.
    #[arg(long, conflicts_with = "legend")]
    pub no_legend: bool,
    /// Render with N ranks: threads of this process, each holding one k-d brick of the step
    /// (its particles and their ghosts) and rendering its samples, composited by direct send;
    /// the code path an MPI launch will take. Every integrator, on every backend (each rank
    /// its own; docs/distributed.md).
    #[arg(long, value_name = "N")]
    pub ranks: Option<usize>,
    /// What a distributed render's bricks are balanced by: `count` (equal particles) or
    /// `cost` (equal measured render time: two pilot images at a quarter of the size measure
    /// each brick, the second balanced by the first, and each image of a sequence corrects
    /// the balance by what the one before it measured).
    #[arg(long, value_enum, default_value_t = Balance::Count)]
    pub balance: Balance,
    /// How a distributed render's shadow rays (single scattering) cross bricks: `prefix-map`
    /// (through every brick: each brick marches a light map through its own samples, and a
    /// scan from the light gives each brick the depth nearer the light; default) or `local`
    /// (through the ray's own brick only, as OSPRay's distributed renderer shadows).
    #[arg(long, value_enum, value_name = "HOW")]
    pub dist_shadows: Option<dist::ShadowsAcross>,
    /// The light map's texels a side for --dist-shadows prefix-map (default: half the image's
    /// longer side, 64 to 512): finer follows the shadows' edges across the light more
    /// closely and costs M² rays a light.
    #[arg(long, value_name = "M")]
    pub shadow_map: Option<u32>,
}

fn numbers<const N: usize>(flag: &str, text: &str) -> anyhow::Result<[f64; N]> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--{flag} '{text}': not {N} comma-separated numbers"))?;
    v.try_into()
        .map_err(|_| anyhow::anyhow!("--{flag} '{text}': expected {N} comma-separated numbers"))
}

/// Parses `a..b` / `a..=b`.
/// Parses `a..b`, `a..=b` and either with `:stride` (`0..48:4`).
pub(super) fn step_range(
    text: &str,
    len: usize,
) -> anyhow::Result<std::iter::StepBy<std::ops::Range<usize>>> {
    let (range, stride) = match text.rsplit_once(':') {
        Some((range, stride)) => {
            let stride: usize =
                stride
                    .trim()
                    .parse()
                    .ok()
                    .filter(|&s| s > 0)
                    .with_context(|| {
                        format!("--steps '{text}': the stride must be a positive whole number")
                    })?;
            (range, stride)
        }
        None => (text, 1),
    };
    let (a, b, inclusive) = if let Some((a, b)) = range.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = range.split_once("..") {
        (a, b, false)
    } else {
        bail!("--steps '{text}': expected a..b or a..=b, optionally with :stride");
    };
    let a: usize = if a.is_empty() {
        0
    } else {
        a.parse().with_context(|| format!("--steps '{text}'"))?
    };
    let b: usize = if b.is_empty() {
        len
    } else {
        b.parse::<usize>()
            .with_context(|| format!("--steps '{text}'"))?
            + usize::from(inclusive)
    };
    if a >= b || b > len {
        bail!("--steps '{text}' is empty or beyond the series' {len} steps");
    }
    Ok((a..b).step_by(stride))
}

fn set_or_auto(set: bool) -> &'static str {
    if set { "set" } else { "automatic" }
}

/// Writes the flags over the scene file's `[render]` and `[camera]` sections (flags win), so
/// one reading of the scene ([`SceneFile::render_settings`]) serves flags and files alike.
fn apply_flags(args: &RenderArgs, scene: &mut SceneFile) -> anyhow::Result<()> {
    fn over<T: Clone>(file: &mut Option<T>, flag: &Option<T>) {
        if flag.is_some() {
            file.clone_from(flag);
        }
    }
    let r = &mut scene.render;
    over(&mut r.width, &args.width);
    over(&mut r.height, &args.height);
    over(&mut r.spp, &args.spp);
    over(&mut r.integrator, &args.integrator);
    over(&mut r.noise, &args.noise);
    over(&mut r.seed, &args.seed);
    over(&mut r.step_size, &args.step_size);
    over(&mut r.phi_ref, &args.phi_ref);
    over(&mut r.density_scale, &args.density_scale);
    over(&mut r.precision, &args.precision);
    over(&mut r.target_error, &args.target_error);
    over(&mut r.time_budget, &args.time_budget);
    over(&mut r.error_metric, &args.error_metric);
    if let Some(text) = &args.optical_map {
        r.optical_map = Some(MapSpec::Text(text.clone()));
    }
    if args.color_by_density {
        r.color_by_density = Some(true);
    }
    let mut light = r.light.unwrap_or_default();
    if let Some(text) = &args.light {
        let [az, el, i] = numbers::<3>("light", text)?;
        light = Light {
            azimuth: az,
            elevation: el,
            intensity: i,
            ..light
        };
    }
    light.ambient = args.ambient.unwrap_or(light.ambient);
    r.light = Some(light);
    if let Some(text) = &args.background {
        r.background = Some(numbers::<3>("background", text)?);
    }
    if args.camera.is_some() as u8
        + args.orbit.is_some() as u8
        + args.view.camera_from.is_some() as u8
        > 1
    {
        bail!("--camera, --orbit and --camera-from each place the camera: give one");
    }
    if let Some(camera) = args.camera {
        ensure!(
            args.view.up.is_none(),
            "--camera gives its own up vector; drop --up"
        );
        scene.camera = CameraSection::of(camera);
    } else if let Some(orbit) = &args.orbit {
        scene.camera.orbit = Some(orbit.clone());
    }
    args.view.apply(&mut scene.camera)?;
    Ok(())
}

/// Checks the flags before the data is opened or a device is probed, and decides whether a
/// legend is drawn (on 8-bit PNG images that hold it, unless --no-legend).
fn check_flags(args: &RenderArgs) -> anyhow::Result<bool> {
    let mut flags = match &args.data.scene {
        Some(path) => SceneFile::load(path)?,
        None => SceneFile::default(),
    };
    apply_flags(args, &mut flags)?;
    let unit = crate::values::Bounds::of_points(&[glam::DVec3::ZERO, glam::DVec3::ONE]);
    let settings = flags.render_settings(unit).map_err(anyhow::Error::msg)?;
    ensure!(flags.spp() > 0, "--spp must be at least 1");
    let format = OutputFormat::of(&args.out, args.bit_depth)?;
    ensure!(
        !args.legend || format == OutputFormat::Png8,
        "--legend draws on 8-bit PNG images only (16-bit and .exr outputs are for compositing)"
    );
    let (w, h) = crate::render::legend::MIN_SIZE;
    let fits = settings.width >= w && settings.height >= h;
    ensure!(
        !args.legend || fits,
        "--legend needs an image of at least {w}x{h} pixels, not {}x{}",
        settings.width,
        settings.height
    );
    Ok(!args.no_legend && format == OutputFormat::Png8 && fits)
}

/// A render's settings, settled from the flags over the scene file and the data.
struct Setup {
    resolved: Resolved,
    settings: RenderSettings,
    method: Method,
    spp: u32,
    /// The error or time a targeted render stops at.
    target: Option<Target>,
}

impl Setup {
    /// The precision as the scene spells it, for the log and a saved scene.
    fn precision_text(&self) -> String {
        self.resolved
            .scene
            .render
            .precision
            .clone()
            .unwrap_or_else(|| "auto".into())
    }
}

pub(super) fn run(args: RenderArgs) -> anyhow::Result<()> {
    let ranks = dist::ranks(&args)?;
    anyhow::ensure!(
        ranks.is_some() || args.balance == Balance::Count,
        "--balance {} balances the bricks of a distributed render: add --ranks N, or run \
         under mpirun",
        args.balance
    );
    anyhow::ensure!(
        ranks.is_some() || (args.dist_shadows.is_none() && args.shadow_map.is_none()),
        "--dist-shadows and --shadow-map say how shadows cross the bricks of a distributed \
         render: add --ranks N, or run under mpirun (a single rank's shadows are exact)"
    );
    let draw_legend = check_flags(&args)?;
    let setup = settle(&args, ranks.as_ref())?;
    let format = OutputFormat::of(&args.out, args.bit_depth)?;
    let start_camera = setup
        .settings
        .camera
        .unwrap_or_else(|| Camera::default_for(setup.resolved.domain()));
    let (frames, sequence) = plan_frames(&args, &setup.resolved, start_camera, format)?;
    let frames = frames_to_render(&args, frames, sequence)?;
    if frames.is_empty() {
        return Ok(());
    }
    if let Some(path) = &args.save_scene {
        crate::io::output::check_writable(path, args.force)?;
    }
    let precision = backend::parse_precision(&setup.precision_text(), backend::Precision::RENDER)
        .map_err(anyhow::Error::msg)?;
    if let Some(ranks) = ranks {
        return dist::run(
            &args,
            setup.resolved,
            setup.settings,
            &frames,
            format,
            draw_legend,
            precision,
            ranks,
        );
    }
    let session = open_session(&args, &setup, precision)?;
    render_frames(
        &args,
        setup,
        session,
        &frames,
        sequence,
        format,
        draw_legend,
    )
}

/// Resolves the data and the field, writes the flags over the scene file, and settles the
/// method, refusing the combinations it does not render. A distributed render's `ranks`
/// compute the mean overlap that chooses the cluster size from their parts of the first step.
fn settle(args: &RenderArgs, ranks: Option<&dist::Ranks>) -> anyhow::Result<Setup> {
    let first_attribute_by_default = !args.color_by_density;
    let mut resolved = match ranks {
        Some(ranks) => {
            resolve_with_reads(&args.data, &args.field, first_attribute_by_default, ranks)?
        }
        None if args.color_by_density => resolve(&args.data, &args.field)?,
        None => resolve_for_images(&args.data, &args.field)?,
    };
    apply_flags(args, &mut resolved.scene)?;
    match args.method {
        Method::Splat => {
            resolved.scene.render.splat_k = Some(args.splat_k);
            resolved.scene.render.voxel_grid = None;
        }
        Method::Voxel => {
            resolved.scene.render.voxel_grid = Some(args.voxel_grid);
            resolved.scene.render.splat_k = None;
        }
        Method::Rbf => {}
    }
    let settings = resolved
        .scene
        .render_settings(resolved.domain())
        .map_err(anyhow::Error::msg)?;
    // A scene file's `splat_k` or `voxel_grid` asks for its baseline as --method does.
    let method = match (settings.splat_k, settings.voxel_grid) {
        (Some(_), _) => Method::Splat,
        (None, Some(_)) => Method::Voxel,
        (None, None) => Method::Rbf,
    };
    let spp = resolved.scene.spp();
    anyhow::ensure!(spp > 0, "--spp must be at least 1");
    let target = resolved.scene.target().map_err(anyhow::Error::msg)?;
    if (target.is_some() || args.reference) && method != Method::Rbf {
        bail!("--target-error, --time-budget and --reference render with --method rbf");
    }
    if method != Method::Rbf && resolved.field.kernel.is_sph() {
        bail!(
            "--method {} is a baseline of the paper's Table 3, which splats its Gaussian RBF; \
             --kernel {} renders with --method rbf",
            if method == Method::Splat {
                "splat"
            } else {
                "voxel"
            },
            resolved.field.kernel
        );
    }
    if let Some(k) = settings.splat_k {
        ensure!(
            settings.integrator == Integrator::Ea,
            "--method splat composites emission-absorption (as Knoll et al.'s splatter): use --integrator ea, not {:?}",
            settings.integrator
        );
        ensure!(k > 0, "--splat-k must be at least 1");
    }
    Ok(Setup {
        resolved,
        settings,
        method,
        spp,
        target,
    })
}

/// The frames still to render. Every output is checked before any is rendered, so a sequence
/// never stops half way; a sequence's frames already written are kept (outputs are written
/// whole, atomically) unless --force.
fn frames_to_render(
    args: &RenderArgs,
    frames: Vec<Frame>,
    sequence: bool,
) -> anyhow::Result<Vec<Frame>> {
    let (done, frames): (Vec<Frame>, Vec<Frame>) = if sequence && !args.force {
        frames.into_iter().partition(|f| f.path.exists())
    } else {
        for f in &frames {
            crate::io::output::check_writable(&f.path, args.force)?;
        }
        (Vec::new(), frames)
    };
    if !done.is_empty() {
        tracing::info!(
            "resuming: {} of {} frames are already written (--force renders them again)",
            done.len(),
            done.len() + frames.len()
        );
    }
    Ok(frames)
}

/// A session on the backend the flags choose, said in the log.
fn open_session(
    args: &RenderArgs,
    setup: &Setup,
    precision: backend::Precision,
) -> anyhow::Result<RenderSession> {
    let backend = backend::create(args.backend)?;
    tracing::info!(
        "backend: {} ({})",
        backend.capabilities().name,
        backend.capabilities().device
    );
    let on_cpu = backend.capabilities().name == "cpu";
    let mut session = RenderSession::new(backend, &setup.resolved.series);
    session.set_periodic(setup.resolved.periodic);
    // The CPU splatter collects hits through the f64 BVH (the cpu backend's only tree); asking
    // for it up front spares building the f32 cells first.
    session.set_precision(if setup.method == Method::Splat && on_cpu {
        backend::Precision::F64
    } else {
        precision
    });
    Ok(session)
}

/// Renders and writes each frame, the settings the first used said (and saved) once.
fn render_frames(
    args: &RenderArgs,
    mut setup: Setup,
    mut session: RenderSession,
    frames: &[Frame],
    sequence: bool,
    format: OutputFormat,
    draw_legend: bool,
) -> anyhow::Result<()> {
    let chooses_step = setup.target.is_some() || args.reference;
    // A targeted or reference render does not know its samples in advance: the bar counts
    // images, and the render shows its own progress.
    let per_image = if chooses_step {
        1
    } else {
        u64::from(setup.spp)
    };
    let bar = crate::progress::bar(
        (frames.len() as u64) * per_image,
        if sequence {
            "rendering frames"
        } else {
            "rendering"
        },
    );
    let mut scene_used = None;
    let mut scene_used_phi_ref = None;
    for (k, frame) in frames.iter().enumerate() {
        let started = Instant::now();
        let step = frame.step;
        setup.settings.camera = Some(frame.camera);
        setup.resolved.range_for_step(step)?;
        let resolved = &setup.resolved;
        session.show(&resolved.series, step, &resolved.field, resolved.cluster)?;
        if k == 0 {
            // Series-wide values: the same for every step, so printed (and saved) once.
            let used = session.resolve(&setup.settings)?;
            say_settings_used(&used, &setup, chooses_step);
            scene_used_phi_ref = Some(used.phi_ref);
            scene_used = Some(used);
        }
        let rendered = image::render(&mut session, &setup, args, step, &bar)?;
        let (resolved, settings) = (&setup.resolved, &setup.settings);
        // Checked before rendering; a sequence's own earlier frames are not "existing" outputs.
        let legend = match (draw_legend, &scene_used_phi_ref) {
            (true, Some(phi_ref)) => Some(Legend::of_field(
                &resolved.field,
                resolved.series_range(),
                resolved.range.label(),
                settings.colour_by_density,
                *phi_ref,
            )),
            _ => None,
        };
        let path = &frame.path;
        format.write(path, &rendered.image, settings.background, legend.as_ref())?;
        if let (Some(path), Some(used)) = (&args.save_scene, scene_used.take()) {
            save_scene(path, args, &setup, used, &rendered, frame.camera)?;
        }
        let t = session.backend().timings();
        tracing::info!(
            "step {step}: {} ({}x{}, {} spp{}{}, {:?}): build {:.3} s, last frame {:.3} s, total {:.1} s",
            path.display(),
            settings.width,
            settings.height,
            rendered.spp,
            rendered
                .step_size
                .map_or(String::new(), |dt| format!(", step size {dt:.4e}")),
            match resolved.field.attribute_range {
                Some((lo, hi)) if resolved.range.per_step() => format!(", range [{lo}, {hi}]"),
                _ => String::new(),
            },
            settings.integrator,
            t.build.as_secs_f64(),
            t.frame.as_secs_f64(),
            started.elapsed().as_secs_f64()
        );
    }
    bar.finish_and_clear();
    Ok(())
}

/// Says the series-wide values the render used, each set or automatic; a targeted or
/// reference render (`chooses_step`) chooses its own step, said with each image.
fn say_settings_used(used: &crate::render::Resolved, setup: &Setup, chooses_step: bool) {
    let settings = &setup.settings;
    let step_size = if chooses_step && settings.step_size.is_none() {
        "chosen per image (below)".to_owned()
    } else {
        format!(
            "{} ({})",
            used.step_size,
            set_or_auto(settings.step_size.is_some())
        )
    };
    tracing::info!(
        "settings used: phi_ref {} ({}), step size {step_size}, density scale {} ({}), radius {}, march box margin {}",
        used.phi_ref,
        set_or_auto(settings.phi_ref.is_some()),
        used.density_scale,
        set_or_auto(settings.optical.scale().is_some()),
        setup.resolved.field.radius,
        used.margin
    );
}

/// Writes the scene file that renders `rendered` again (with the step and samples it chose).
fn save_scene(
    path: &std::path::Path,
    args: &RenderArgs,
    setup: &Setup,
    used: crate::render::Resolved,
    rendered: &image::Rendered,
    camera: Camera,
) -> anyhow::Result<()> {
    let (data, field) = setup.resolved.scene_sections();
    let used = crate::render::Resolved {
        step_size: rendered.step_size.unwrap_or(used.step_size),
        ..used
    };
    let precision = setup.precision_text();
    let saved = if args.reference {
        reference_settings(&setup.settings)
    } else {
        setup.settings.clone()
    };
    SceneFile::reproducing(
        data,
        field,
        &saved,
        Some(&used),
        camera,
        rendered.spp,
        if args.reference { "f64" } else { &precision },
    )
    .save(path, true)?;
    tracing::info!("wrote {}", path.display());
    Ok(())
}
