//! The commands a user runs with `--backend ash` or `--backend wgpu` (`aarbf render`, `aarbf
//! field` at points and on a grid) against the same commands on the CPU backend, and `aarbf
//! info --devices`. Without a backend's device its tests fail.

use std::path::Path;

use aarbf::io::{At, npy};
use aarbf::scene::{OpenOptions, TimeSeries};

use crate::common::{self, Gpu, aarbf_ok as ok, on_every_gpu};

on_every_gpu!(
    render_and_field_at_particles_match_the_cpu_backend,
    field_with_a_radius_map_matches_the_cpu_backend_in_either_classification,
    a_grid_export_matches_the_cpu_backend,
);

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn render_and_field_at_particles_match_the_cpu_backend(gpu: Gpu) {
    gpu.require();
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
    let (cpu, device) = (render("cpu"), render(&gpu.to_string()));
    let worst = cpu
        .as_raw()
        .iter()
        .zip(device.as_raw())
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
    let (cpu, device) = (field("cpu"), field(&gpu.to_string()));
    assert_eq!((cpu.rows, cpu.cols), (device.rows, device.cols));
    let mut non_zero = 0;
    for i in 0..cpu.rows {
        let (a, b) = (cpu.row(i), device.row(i));
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

/// Field queries on a lattice through the fluid with a radius map, post- and pre-classified;
/// then a frame of the same data.
fn field_with_a_radius_map_matches_the_cpu_backend_in_either_classification(gpu: Gpu) {
    gpu.require();
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
        let (cpu, device) = (run("cpu"), run(&gpu.to_string()));
        assert_eq!((cpu.rows, cpu.cols), (device.rows, device.cols));
        let mut seen = 0;
        for i in 0..cpu.rows {
            let (a, b) = (cpu.row(i), device.row(i));
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
        &gpu.to_string(),
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
/// a GPU backend queries each point; the two agree as point queries do.
fn a_grid_export_matches_the_cpu_backend(gpu: Gpu) {
    gpu.require();
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
    let (cpu, device) = (run("cpu"), run(&gpu.to_string()));
    assert_eq!((cpu.rows, cpu.cols), (23 * 13 * 7, 2));
    assert_eq!((device.rows, device.cols), (cpu.rows, cpu.cols));
    let mut inside = 0;
    for i in 0..cpu.rows {
        let (a, b) = (cpu.row(i), device.row(i));
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

/// `aarbf info --devices` lists the adapters wgpu finds, with what the backends depend on.
#[test]
fn aarbf_info_lists_the_wgpu_adapters() {
    common::wgpu_context();
    let devices = ok(&["info", "--devices"]);
    assert!(
        devices.contains("adapter 0:")
            && devices.contains("storage buffers per stage")
            && devices.contains("features"),
        "{devices}"
    );
}
