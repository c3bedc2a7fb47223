//! Knoll et al.'s splatter (`aarbf render --method splat`), the paper's other Table 3
//! baseline: particles that do not overlap splat to exactly what the RBF renderer integrates
//! (their optical depth along the ray is the chord integral, for an optical map linear in
//! Phi); where particles overlap, ordering and per-particle colour make it differ, and a
//! buffer too small for a slab's hits loses them, which its image error shows.

use std::process::Command;

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind, Precision};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, Image, Integrator, NoiseKind, Step};
use glam::DVec3;

fn splat(session: &mut RenderSession, settings: &RenderSettings, k: usize) -> (Image, f64) {
    let frame = session.frame_params(settings, 0).unwrap();
    let backend = session.backend_mut();
    backend.reset();
    let counts = backend
        .render_splat(&frame, k)
        .unwrap()
        .expect("the cpu counts hits");
    (backend.image().unwrap(), counts.lost_fraction())
}

#[test]
fn particles_apart_splat_to_the_rbf_image() {
    // Seven particles far apart, in double precision off the origin, attributes 0..6 in the
    // data's units: no two overlap, so each pixel sees one particle at most.
    let offset = DVec3::new(1.0e4 + 0.123_456_789_012_345_6, -2.5e3, 7.0 / 3.0);
    let positions: Vec<DVec3> = (0..7)
        .map(|i| offset + DVec3::new(0.3 * i as f64, 0.07 * (i % 3) as f64, 0.05 * i as f64))
        .collect();
    let step = Step {
        name: "apart".into(),
        positions,
        attributes: vec![Attribute {
            name: "a".into(),
            values: vec![3.0, -1.5, 0.25, 7.0, 2.0, 5.5, 0.0],
        }],
    };
    let series = TimeSeries::from_steps(vec![step]);
    let radius = 0.1;
    let field = FieldSettings::new(Some("a"), radius);
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session.set_precision(Precision::F64);
    session
        .show(&series, 0, &field, ClusterSize::new(1).unwrap())
        .unwrap();
    let base = RenderSettings {
        width: 40,
        height: 40,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        // Phi stays in the optical map's linear range (a lone particle's Phi is at most 1).
        phi_ref: Some(2.0),
        ..RenderSettings::default()
    };
    // The RBF image marched finely enough that its step's error is below the tolerance.
    let rbf = session
        .render(
            &RenderSettings {
                step_size: Some(radius / 100.0),
                ..base.clone()
            },
            8,
        )
        .unwrap();
    assert!(
        rbf.pixels.iter().filter(|p| p[3] > 0.05).count() > 20,
        "the particles are visible"
    );
    let (splatted, lost) = splat(&mut session, &base, 15);
    assert_eq!(lost, 0.0);
    let error = splatted.rmse(&rbf);
    eprintln!("particles apart: RMSE splat vs RBF {error:.3e}");
    assert!(error < 1e-5, "RMSE splat vs RBF {error}");
    let worst = splatted
        .pixels
        .iter()
        .zip(&rbf.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "largest pixel difference {worst}");
}

#[test]
fn overlapping_particles_differ_and_a_small_buffer_loses_hits() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session.set_precision(Precision::F64);
    session
        .show(&series, 7, &field, ClusterSize::new(1).unwrap())
        .unwrap();
    let settings = RenderSettings {
        width: 48,
        height: 48,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    let reference = session.render(&settings, 64).unwrap();
    assert!(reference.pixels.iter().any(|p| p[3] > 0.3));
    let (all, lost_none) = splat(&mut session, &settings, 4096);
    let (fifteen, lost_fifteen) = splat(&mut session, &settings, 15);
    let (one, lost_one) = splat(&mut session, &settings, 1);
    assert_eq!(lost_none, 0.0);
    assert!(
        lost_one > 0.05 && lost_one > lost_fifteen,
        "lost: k = 1 {lost_one}, k = 15 {lost_fifteen}"
    );
    let errors = [all, fifteen, one].map(|i| i.rmse(&reference));
    eprintln!(
        "dam break: lost k = 1 {lost_one:.3}, k = 15 {lost_fifteen:.3}; RMSE k = 4096, 15, 1: {errors:?}"
    );
    // The splatter is close to the RBF image but not equal to it (overlapping particles are
    // composited one after another), and losing hits moves it further away.
    assert!(errors[0] > 1e-4 && errors[0] < 0.05, "{errors:?}");
    assert!(errors[2] > 1.5 * errors[0], "{errors:?}");
    assert!(errors[1] <= errors[2], "{errors:?}");
}

#[test]
fn aarbf_render_splats_text_data_and_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A lattice far from the origin, written with 17 significant digits as NumPy's savetxt
    // ("%.17g") writes it.
    let mut csv = String::from("x,y,z,temperature\n");
    for i in 0..6 {
        for j in 0..5 {
            for k in 0..3 {
                let p = [
                    -3.0e5 + 0.1 * i as f64 + 1.0 / 3.0,
                    1.0e5 + 0.1 * j as f64,
                    0.1 * k as f64 + 2.0 / 7.0,
                ];
                csv += &format!(
                    "{:.17e},{:.17e},{:.17e},{:.17e}\n",
                    p[0],
                    p[1],
                    p[2],
                    300.0 + (i * j + k) as f64 / 7.0
                );
            }
        }
    }
    let data = d.join("lattice.csv");
    std::fs::write(&data, csv).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(args)
            .env("AARBF_LOG", "info")
            .output()
            .unwrap()
    };
    let out = d.join("splat.png");
    let common = [
        "render",
        "--data",
        data.to_str().unwrap(),
        "--attribute",
        "temperature",
        "--radius",
        "0.12",
        "--width",
        "32",
        "--height",
        "24",
        "--method",
        "splat",
        "--out",
        out.to_str().unwrap(),
    ];
    let ok = run(&[&common[..], &["--backend", "cpu", "--splat-k", "2"]].concat());
    let stderr = String::from_utf8_lossy(&ok.stderr);
    assert!(ok.status.success(), "{stderr}");
    assert!(
        stderr.contains("lost to full 2-entry slab buffers"),
        "{stderr}"
    );
    let image = image::open(&out).unwrap().to_rgb8();
    assert_eq!((image.width(), image.height()), (32, 24));
    assert!(
        image.pixels().any(|p| p.0 != image.get_pixel(0, 0).0),
        "the lattice is drawn"
    );
    for (extra, says) in [
        (
            &["--backend", "cpu", "--integrator", "marching", "--force"][..],
            "--integrator ea",
        ),
        (
            &["--backend", "cpu", "--splat-k", "0", "--force"][..],
            "--splat-k must be at least 1",
        ),
        (
            &["--backend", "wgpu", "--splat-k", "65", "--force"][..],
            "the GPU splatter's slab buffer holds 1..=64 hits",
        ),
    ] {
        let bad = run(&[&common[..], extra].concat());
        let stderr = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && stderr.contains(says),
            "{extra:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
