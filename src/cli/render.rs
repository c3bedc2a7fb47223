//! `aarbf render`: images of one step or a range of steps.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use glam::DVec3;

use super::settings::{DataArgs, FieldOptions, resolve};
use crate::backend::{self, BackendKind};
use crate::render::{RenderSession, RenderSettings};
use crate::scene::Camera;
use crate::values::{Integrator, Light, NoiseKind};

#[derive(Debug, Args)]
pub struct RenderArgs {
    #[command(flatten)]
    pub data: DataArgs,
    #[command(flatten)]
    pub field: FieldOptions,
    /// A range of steps, `a..b` (b excluded) or `a..=b`: writes OUT_<step>.png for each.
    #[arg(long, conflicts_with = "step")]
    pub steps: Option<String>,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendKind,
    /// How a GPU backend holds positions: `auto` (f32 where the scene's radii allow a Phi
    /// error below 1e-3, double-single pairs otherwise; the default), `auto:TOLERANCE`, `f32`
    /// or `ds`.
    #[arg(long)]
    pub precision: Option<String>,
    /// Also write a scene file (TOML) holding every setting the image used, the automatic
    /// ones resolved (Phi_ref, step size, density scale, radius, camera): `aarbf render
    /// --scene` of it renders the same image (for a sequence: its first step).
    #[arg(long)]
    pub save_scene: Option<PathBuf>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Samples (frames) per pixel.
    #[arg(long)]
    pub spp: Option<u32>,
    #[arg(long, value_enum)]
    pub integrator: Option<Integrator>,
    #[arg(long, value_enum)]
    pub noise: Option<NoiseKind>,
    /// Seed of the random numbers: the same seed gives the same image on the same backend.
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
    /// Light: azimuth,elevation,intensity (degrees, degrees, scale) for single scattering.
    #[arg(long, value_name = "AZ,EL,I")]
    pub light: Option<String>,
    #[arg(long)]
    pub ambient: Option<f64>,
    /// Background colour r,g,b (linear, 0..1).
    #[arg(long, value_name = "R,G,B")]
    pub background: Option<String>,
    /// Output PNG (for a step range: the prefix of the sequence).
    #[arg(long)]
    pub out: PathBuf,
    /// Overwrite existing outputs.
    #[arg(long)]
    pub force: bool,
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
pub(super) fn step_range(text: &str, len: usize) -> anyhow::Result<std::ops::Range<usize>> {
    let (a, b, inclusive) = if let Some((a, b)) = text.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = text.split_once("..") {
        (a, b, false)
    } else {
        bail!("--steps '{text}': expected a..b or a..=b");
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
    Ok(a..b)
}

fn parse_orbit(text: &str) -> anyhow::Result<(usize, usize)> {
    let (i, n) = text
        .split_once('/')
        .with_context(|| format!("orbit '{text}': expected i/n"))?;
    let (i, n): (usize, usize) = (i.trim().parse()?, n.trim().parse()?);
    if n == 0 || i >= n {
        bail!("orbit '{text}': need 0 <= i < n");
    }
    Ok((i, n))
}

fn set_or_auto(set: bool) -> &'static str {
    if set { "set" } else { "automatic" }
}

/// Writes a scene file that renders the same image: every section filled, the automatic
/// values as resolved.
fn save_scene(
    path: &Path,
    resolved: &super::settings::Resolved,
    settings: &RenderSettings,
    used: &crate::render::Resolved,
    camera: Camera,
    spp: u32,
    precision: &str,
) -> anyhow::Result<()> {
    use crate::scene_file::{CameraSection, MapSpec, RenderSection, SceneFile};
    let (data, field) = resolved.scene_sections();
    let scene = SceneFile {
        data,
        field,
        camera: CameraSection {
            eye: Some(camera.eye.to_array()),
            at: Some(camera.at.to_array()),
            up: Some(camera.up.to_array()),
            fovy: Some(camera.fovy),
            orbit: None,
        },
        render: RenderSection {
            width: Some(settings.width),
            height: Some(settings.height),
            spp: Some(spp),
            integrator: Some(settings.integrator),
            noise: Some(settings.noise),
            seed: Some(settings.seed),
            step_size: Some(used.step_size),
            density_scale: Some(used.density_scale),
            phi_ref: Some(used.phi_ref),
            optical_map: Some(MapSpec::Points(settings.optical.map().points().to_vec())),
            color_by_density: Some(settings.colour_by_density),
            background: Some(settings.background),
            opacity_threshold: Some(settings.opacity_threshold),
            light: Some(settings.light),
            precision: Some(precision.to_owned()),
        },
    };
    scene.save(path, true)?;
    Ok(())
}

pub fn run(args: RenderArgs) -> anyhow::Result<()> {
    let resolved = resolve(&args.data, &args.field)?;
    let scene = &resolved.scene;
    let r = &scene.render;
    let mut settings = RenderSettings::default();
    settings.width = args.width.or(r.width).unwrap_or(settings.width);
    settings.height = args.height.or(r.height).unwrap_or(settings.height);
    settings.integrator = args.integrator.or(r.integrator).unwrap_or_default();
    settings.noise = args.noise.or(r.noise).unwrap_or_default();
    settings.seed = args.seed.or(r.seed).unwrap_or(settings.seed);
    settings.step_size = args.step_size.or(r.step_size);

    settings.phi_ref = args.phi_ref.or(r.phi_ref);
    settings.colour_by_density = args.color_by_density || r.color_by_density.unwrap_or(false);
    settings.opacity_threshold = r.opacity_threshold.unwrap_or(settings.opacity_threshold);
    let optical_map = match (&args.optical_map, &r.optical_map) {
        (Some(text), _) => text.parse()?,
        (None, Some(spec)) => spec.to_map()?,
        (None, None) => crate::scene::maps::PiecewiseLinear::ramp(0.0, 1.0),
    };
    settings.optical = crate::scene::maps::OpticalDensityMap::new(
        optical_map,
        args.density_scale.or(r.density_scale),
    )?;
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
    settings.light = light;
    if let Some(text) = &args.background {
        settings.background = numbers::<3>("background", text)?;
    } else if let Some(bg) = r.background {
        settings.background = bg;
    }
    let bounds = resolved.series.bounds();
    let c = &scene.camera;
    settings.camera = if let Some(camera) = args.camera {
        Some(camera)
    } else if let Some(orbit) = args.orbit.as_ref().or(c.orbit.as_ref()) {
        let (i, n) = parse_orbit(orbit)?;
        Some(Camera::benchmark_orbit(
            bounds,
            i,
            n,
            c.fovy.unwrap_or(40.0),
        ))
    } else if let (Some(eye), Some(at)) = (c.eye, c.at) {
        Some(Camera {
            eye: DVec3::from(eye),
            at: DVec3::from(at),
            up: DVec3::from(c.up.unwrap_or([0.0, 1.0, 0.0])),
            fovy: c.fovy.unwrap_or(40.0),
        })
    } else {
        None
    };
    let spp = args.spp.or(r.spp).unwrap_or(16);
    anyhow::ensure!(spp > 0, "--spp must be at least 1");

    let steps = match &args.steps {
        Some(text) => step_range(text, resolved.series.len())?,
        None => resolved.step..resolved.step + 1,
    };
    let sequence = args.steps.is_some();
    let out_for = |step: usize| -> PathBuf {
        if !sequence {
            return args.out.clone();
        }
        let stem = args
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "frame".into());
        let dir = args.out.parent().unwrap_or(Path::new(""));
        dir.join(format!("{stem}_{step:04}.png"))
    };
    // Check every output before rendering any, so a sequence never stops half way.
    for step in steps.clone() {
        crate::io::output::check_writable(&out_for(step), args.force)?;
    }
    if let Some(path) = &args.save_scene {
        crate::io::output::check_writable(path, args.force)?;
    }
    let precision_text = args
        .precision
        .clone()
        .or(r.precision.clone())
        .unwrap_or_else(|| "auto".into());
    let precision = backend::parse_precision(&precision_text, backend::Precision::RENDER)
        .map_err(anyhow::Error::msg)?;
    let backend = backend::create(args.backend)?;
    tracing::info!(
        "backend: {} ({})",
        backend.capabilities().name,
        backend.capabilities().device
    );
    let mut session = RenderSession::new(backend, &resolved.series);
    session.set_precision(precision);
    let bar = crate::progress::bar(
        (steps.len() as u64) * u64::from(spp),
        if sequence {
            "rendering steps"
        } else {
            "rendering"
        },
    );
    let first = steps.start;
    for step in steps {
        let started = Instant::now();
        session.show(&resolved.series, step, &resolved.field, resolved.cluster)?;
        if step == first {
            // Series-wide values: the same for every step, so printed (and saved) once.
            let used = session.resolve(&settings)?;
            tracing::info!(
                "settings used: phi_ref {} ({}), step size {} ({}), density scale {} ({}), radius {}, march box margin {}",
                used.phi_ref,
                set_or_auto(settings.phi_ref.is_some()),
                used.step_size,
                set_or_auto(settings.step_size.is_some()),
                used.density_scale,
                set_or_auto(settings.optical.scale().is_some()),
                resolved.field.radius,
                used.margin
            );
            if let Some(path) = &args.save_scene {
                let camera = settings
                    .camera
                    .unwrap_or_else(|| Camera::default_for(bounds));
                save_scene(
                    path,
                    &resolved,
                    &settings,
                    &used,
                    camera,
                    spp,
                    &precision_text,
                )?;
                tracing::info!("wrote {}", path.display());
            }
        }
        for _ in 0..spp {
            session.accumulate(&settings, 1)?;
            bar.inc(1);
        }
        let path = out_for(step);
        // Checked before rendering; a sequence's own earlier frames are not "existing" outputs.
        crate::io::output::write_png(&path, &session.image()?, true)?;
        let t = session.backend().timings();
        tracing::info!(
            "step {step}: {} ({}x{}, {spp} spp, {:?}): build {:.3} s, last frame {:.3} s, total {:.1} s",
            path.display(),
            settings.width,
            settings.height,
            settings.integrator,
            t.build.as_secs_f64(),
            t.frame.as_secs_f64(),
            started.elapsed().as_secs_f64()
        );
    }
    bar.finish_and_clear();
    Ok(())
}
