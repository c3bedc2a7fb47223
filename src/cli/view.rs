//! `aarbf view`: the interactive viewer on a data set or a scene file.

use std::path::PathBuf;

use clap::Args;

use crate::backend::BackendKind;
use crate::scene_file::resolve::{DataArgs, FieldOptions, ViewFlags, resolve_for_images};
use crate::viewer::{ViewOptions, WindowOptions};

/// The arguments of `aarbf view`: the data, field and view to start with, and the window.
#[derive(Debug, Args)]
pub struct ViewArgs {
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
    /// The backend to start with (switchable in the window). `auto` picks the CPU backend
    /// where the only GPU is a software one, as `aarbf render` does.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendKind,
    /// Samples per pixel to accumulate once the view stops changing (default: the scene's,
    /// else 16).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Window size in points, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x800", value_parser = parse_size)]
    pub window: [f32; 2],
    /// Write a screenshot of the whole window to this PNG once the image has converged, then
    /// close the window.
    #[arg(long)]
    pub window_screenshot: Option<PathBuf>,
}

fn parse_size(text: &str) -> Result<[f32; 2], String> {
    let (w, h) = text
        .split_once('x')
        .ok_or_else(|| format!("'{text}' is not WIDTHxHEIGHT"))?;
    let parse = |v: &str| -> Result<f32, String> {
        match v.trim().parse::<f32>() {
            Ok(x) if (64.0..=16384.0).contains(&x) => Ok(x),
            _ => Err(format!(
                "'{text}': each side must be a number in 64..=16384"
            )),
        }
    };
    Ok([parse(w)?, parse(h)?])
}

pub(super) fn run(args: ViewArgs) -> anyhow::Result<()> {
    let mut loaded = resolve_for_images(&args.data, &args.field)?;
    args.view.apply(&mut loaded.scene.camera)?;
    if let Some(spp) = args.spp {
        anyhow::ensure!(spp > 0, "--spp must be at least 1");
        loaded.scene.render.spp = Some(spp);
    }
    crate::viewer::run(
        loaded,
        args.backend,
        ViewOptions {
            cache_mib: args.data.cache_mib,
        },
        WindowOptions {
            size: args.window,
            screenshot: args.window_screenshot,
        },
    )?;
    Ok(())
}
