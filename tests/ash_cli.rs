//! `aarbf render --backend ash` and `aarbf field --backend ash` as a user runs them, against
//! the same commands on the CPU backend.

use std::path::Path;
use std::process::{Command, Output};

use aarbf::io::{At, npy};
use aarbf::scene::{OpenOptions, TimeSeries};

use crate::common;

fn aarbf(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .env("AARBF_LOG", "warn")
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("the binary runs")
}

fn ok(args: &[&str]) -> String {
    let out = aarbf(args);
    assert!(
        out.status.success(),
        "aarbf {args:?} failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("Vulkan validation"),
        "aarbf {args:?}: validation messages:\n{stderr}"
    );
    String::from_utf8(out.stdout).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Whether the ray-tracing device exists; the test fails without one.
fn available() -> bool {
    common::require(
        "a Vulkan device with ray-tracing pipelines",
        aarbf::backend::ash_rt::available(),
    );
    true
}

#[test]
fn render_and_field_with_the_ash_backend_match_the_cpu_backend() {
    if !available() {
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
        "1500",
        "--steps",
        "4",
    ]);
    let header = header.trim();
    let render = |backend: &str| {
        let png = d.join(format!("{backend}.png"));
        ok(&[
            "render",
            "--data",
            header,
            "--step",
            "3",
            "--attribute",
            "attribute",
            "--radius",
            "2%",
            "--width",
            "40",
            "--height",
            "30",
            "--spp",
            "2",
            "--backend",
            backend,
            "--out",
            s(&png),
        ]);
        image::open(&png).unwrap().to_rgb8()
    };
    let (cpu, ash) = (render("cpu"), render("ash"));
    let worst = cpu
        .as_raw()
        .iter()
        .zip(ash.as_raw())
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    assert!(worst <= 2, "8-bit images differ by up to {worst}");
    assert!(
        cpu.pixels().any(|p| p.0.iter().any(|&c| c > 30)),
        "the fluid shows"
    );

    // Field queries: every 5th particle of step 2, and the same points shifted a little.
    let series = TimeSeries::open(Path::new(header), &OpenOptions::default()).unwrap();
    let step = series.step(2).unwrap();
    let q: Vec<f64> = step
        .positions
        .iter()
        .step_by(5)
        .flat_map(|p| [p.x, p.y, p.z, p.x + 0.003, p.y - 0.002, p.z + 0.001])
        .collect();
    let rows = q.len() / 3;
    let queries = d.join("q.npy");
    npy::write_matrix(&queries, rows, 3, &q).unwrap();
    let field = |backend: &str| {
        let out = d.join(format!("{backend}.npy"));
        ok(&[
            "field",
            "--data",
            header,
            "--step",
            "2",
            "--attribute",
            "attribute",
            "--radius",
            "3%",
            "--cluster",
            "4",
            "--queries",
            s(&queries),
            "--out",
            s(&out),
            "--backend",
            backend,
        ]);
        npy::read_matrix(At::new(&out, None)).unwrap()
    };
    let (cpu, ash) = (field("cpu"), field("ash"));
    assert_eq!((cpu.rows, cpu.cols), (ash.rows, ash.cols));
    let mut non_zero = 0;
    for i in 0..cpu.rows {
        let (a, b) = (cpu.row(i), ash.row(i));
        if a[0] > 0.0 {
            non_zero += 1;
        }
        // Phi relative, Theta (attribute units, scaled by its range) absolute.
        assert!(
            (a[0] - b[0]).abs() <= 1e-4 * a[0] + 1e-6,
            "row {i}: {a:?} vs {b:?}"
        );
        assert!(
            (a[1] - b[1]).abs() <= 1e-3 * (1.0 + a[1].abs()),
            "row {i}: {a:?} vs {b:?}"
        );
    }
    assert!(
        non_zero * 2 > cpu.rows,
        "{non_zero} of {} queries see the fluid",
        cpu.rows
    );
}
