//! `--backend wgpu` in `aarbf field` and `aarbf render`, and `aarbf info --devices`, as a user
//! runs them. Without a wgpu adapter: fails.

use std::path::Path;
use std::process::{Command, Output};

use aarbf::io::{At, npy};

use crate::common;

fn aarbf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("the binary runs")
}

/// Runs a command that must succeed and, with the validation layers on (debug assertions, as in
/// the `checked` profile, when the layers are installed), print no validation message.
fn ok(args: &[&str]) -> String {
    let out = aarbf(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "aarbf {args:?} failed:\n{stderr}");
    assert!(
        !stderr.contains("VALIDATION") && !stderr.contains("Validation Error"),
        "aarbf {args:?}: validation messages:\n{stderr}"
    );
    String::from_utf8(out.stdout).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether a wgpu adapter exists; the test fails without one.
fn have_adapter() -> bool {
    common::require(
        "a wgpu adapter",
        aarbf::backend::wgpu_lbvh::GpuContext::shared(),
    );
    true
}

#[test]
fn field_and_render_run_on_wgpu_and_agree_with_cpu() {
    if !have_adapter() {
        return;
    }
    let devices = ok(&["info", "--devices"]);
    assert!(
        devices.contains("adapter 0:")
            && devices.contains("storage buffers per stage")
            && devices.contains("features"),
        "{devices}"
    );

    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("db")),
        "--count",
        "2000",
        "--steps",
        "2",
        "--seed",
        "3",
    ]);
    let header = header.trim();
    let queries: Vec<f32> = (0..500)
        .flat_map(|i| [(i % 50) as f32 / 50.0, 0.08, 0.05 + (i / 50) as f32 / 40.0])
        .collect();
    let q = d.join("q.npy");
    npy::write_matrix(&q, 500, 3, &queries).unwrap();
    for classification in ["post", "pre"] {
        let run = |backend: &str| {
            let out = d.join(format!("f_{classification}_{backend}.npy"));
            ok(&[
                "field",
                "--data",
                header,
                "--step",
                "1",
                "--attribute",
                "attribute",
                "--radius",
                "3%",
                "--radius-map",
                "0:0.5,1:1",
                "--classification",
                classification,
                "--cluster",
                "4",
                "--queries",
                s(&q),
                "--out",
                s(&out),
                "--backend",
                backend,
            ]);
            npy::read_matrix(At::new(&out, None)).unwrap()
        };
        let (cpu, gpu) = (run("cpu"), run("wgpu"));
        assert_eq!((cpu.rows, cpu.cols), (gpu.rows, gpu.cols));
        let mut seen = 0;
        for i in 0..cpu.rows {
            let (a, b) = (cpu.row(i), gpu.row(i));
            // Phi relative 3e-4; Theta where Phi is not tiny (the ratio amplifies rounding).
            assert!(
                (a[0] - b[0]).abs() <= 3e-4 * a[0] + 1e-6,
                "{classification} row {i}: {a:?} vs {b:?}"
            );
            if a[0] > 1e-3 {
                seen += 1;
                for c in 1..cpu.cols {
                    assert!(
                        (a[c] - b[c]).abs() <= 1e-3 * (1.0 + a[c].abs()),
                        "{classification} row {i}: {a:?} vs {b:?}"
                    );
                }
            }
        }
        assert!(
            seen > 50,
            "{classification}: {seen} queries inside the fluid"
        );
    }

    let png = d.join("frame.png");
    ok(&[
        "render",
        "--data",
        header,
        "--step",
        "1",
        "--attribute",
        "attribute",
        "--width",
        "40",
        "--height",
        "30",
        "--spp",
        "2",
        "--backend",
        "wgpu",
        "--out",
        s(&png),
    ]);
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (40, 30));
    assert!(
        img.pixels().any(|p| p.0.iter().any(|&c| c > 30)),
        "the fluid shows"
    );
}

/// `aarbf field --grid` (a volume export): the CPU backend scatters particles onto the grid,
/// wgpu queries each point; the two agree as point queries do.
#[test]
fn a_grid_export_agrees_between_cpu_and_wgpu() {
    if !have_adapter() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = ok(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&d.join("db")),
        "--count",
        "3001",
        "--steps",
        "2",
    ]);
    let run = |backend: &str| {
        let out = d.join(format!("grid_{backend}.npy"));
        ok(&[
            "field",
            "--data",
            header.trim(),
            "--step",
            "1",
            "--attribute",
            "attribute",
            "--radius",
            "3%",
            "--grid",
            "23x13x7",
            "--out",
            s(&out),
            "--backend",
            backend,
        ]);
        npy::read_matrix(At::new(&out, None)).unwrap()
    };
    let (cpu, gpu) = (run("cpu"), run("wgpu"));
    assert_eq!((cpu.rows, cpu.cols), (23 * 13 * 7, 2));
    assert_eq!((gpu.rows, gpu.cols), (cpu.rows, cpu.cols));
    let mut inside = 0;
    for i in 0..cpu.rows {
        let (a, b) = (cpu.row(i), gpu.row(i));
        assert!(
            (a[0] - b[0]).abs() <= 3e-4 * a[0] + 1e-6,
            "point {i}: {a:?} vs {b:?}"
        );
        if a[0] > 1e-3 {
            inside += 1;
            assert!(
                (a[1] - b[1]).abs() <= 1e-3 * (1.0 + a[1].abs()),
                "point {i}: {a:?} vs {b:?}"
            );
        }
    }
    assert!(inside > 100, "{inside} grid points inside the fluid");
}
