//! The images one `aarbf render` writes: which step each shows, from where, into which file.

use std::path::{Path, PathBuf};

use anyhow::bail;

use super::{RenderArgs, step_range};
use crate::cli::output_format::OutputFormat;
use crate::scene::Camera;
use crate::scene_file::resolve::Resolved;

/// One image of a render: which step, from where, into which file.
pub(super) struct Frame {
    pub(super) step: usize,
    pub(super) camera: Camera,
    pub(super) path: PathBuf,
}

/// `camera` turned by `degrees` about its up axis through its focal point.
fn turned(camera: Camera, degrees: f64) -> Camera {
    let turn = glam::DQuat::from_axis_angle(camera.up.normalize(), degrees.to_radians());
    Camera {
        eye: camera.at + turn * (camera.eye - camera.at),
        ..camera
    }
}

/// The images a render writes: one step, a range of steps, or an orbit, each with its camera
/// and file; and whether they are a sequence (frames numbered in their names).
pub(super) fn plan_frames(
    args: &RenderArgs,
    resolved: &Resolved,
    start_camera: Camera,
    format: OutputFormat,
) -> anyhow::Result<(Vec<Frame>, bool)> {
    let steps: Vec<usize> = match &args.steps {
        Some(text) => step_range(text, resolved.series.len())?.collect(),
        None => vec![resolved.step],
    };
    let sequence = args.steps.is_some() || args.orbit_sequence.is_some();
    let frame_path = |index: usize| -> PathBuf {
        if !sequence {
            return args.out.clone();
        }
        let stem = args
            .out
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "frame".into());
        let dir = args.out.parent().unwrap_or(Path::new(""));
        dir.join(format!("{stem}_{index:04}.{}", format.extension()))
    };
    let frames = match args.orbit_sequence {
        Some(0) => bail!("--orbit-sequence needs at least 1 frame"),
        Some(n) => (0..n)
            .map(|k| Frame {
                step: steps[k % steps.len()],
                camera: turned(start_camera, 360.0 * k as f64 / n as f64),
                path: frame_path(k),
            })
            .collect(),
        None => steps
            .iter()
            .map(|&step| Frame {
                step,
                camera: start_camera,
                path: frame_path(step),
            })
            .collect(),
    };
    Ok((frames, sequence))
}
