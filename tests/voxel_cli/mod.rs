//! `aarbf render --method voxel` as a user runs it, on each backend of a list: shared by the
//! GPU backends' voxel tests (`tests/voxel_wgpu.rs`, `tests/voxel_ash.rs`).

use std::path::Path;
use std::process::Command;

fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "aarbf {args:?} failed:\n{stderr}");
    assert!(
        !stderr.contains("VALIDATION") && !stderr.contains("Validation Error"),
        "aarbf {args:?}: validation messages:\n{stderr}"
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The dam break's first step drawn with a 64-cell grid (radius 0.03: a few cells) at 2
/// spp on each of `backends`.
pub(crate) fn render_voxels_on(dir: &Path, backends: &[&str]) -> Vec<image::RgbaImage> {
    let data = run(&[
        "generate",
        "dambreak-demo",
        "--out",
        dir.to_str().unwrap(),
        "--count",
        "1500",
        "--steps",
        "2",
    ]);
    backends
        .iter()
        .map(|backend| {
            let out = dir.join(format!("voxel-{backend}.png"));
            run(&[
                "render",
                "--data",
                data.trim(),
                "--backend",
                backend,
                "--width",
                "32",
                "--height",
                "24",
                "--spp",
                "2",
                "--method",
                "voxel",
                "--voxel-grid",
                "64",
                "--radius",
                "0.03",
                "--out",
                out.to_str().unwrap(),
            ]);
            image::open(&out).unwrap().to_rgba8()
        })
        .collect()
}

pub(crate) fn largest_byte_difference(a: &image::RgbaImage, b: &image::RgbaImage) -> u8 {
    assert_eq!(a.dimensions(), b.dimensions());
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap()
}
