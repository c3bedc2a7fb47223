//! The voxel-grid baseline (`aarbf render --method voxel`): the particles splatted into a grid
//! with the same kernel, ray-marched with the same integrator. Its image must converge to the
//! RBF image as the grid grows (same camera, noise and seed: only the field differs), and the
//! command must render it as a user asks.

use std::process::Command;

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Integrator, NoiseKind};

#[test]
fn the_voxel_image_converges_to_the_rbf_image_as_the_grid_grows() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.02 * series.bounds().diagonal());
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session
        .show(&series, 7, &field, ClusterSize::new(4).unwrap())
        .unwrap();
    let settings = RenderSettings {
        width: 48,
        height: 48,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    let spp = 4;
    let rbf = session.render(&settings, spp).unwrap();
    assert!(
        rbf.pixels.iter().any(|p| p[3] > 0.3),
        "the fluid is visible"
    );
    let frame0 = session.frame_params(&settings, 0).unwrap();
    let mut errors = Vec::new();
    for n in [8, 16, 32, 64, 128] {
        let backend = session.backend_mut();
        backend.voxelize(&frame0, n).unwrap();
        assert_eq!(
            backend.voxel_grid().unwrap().dims().into_iter().max(),
            Some(n)
        );
        backend.reset();
        for f in 0..spp {
            let frame = session.frame_params(&settings, f).unwrap();
            session.backend_mut().render_voxels(&frame).unwrap();
        }
        let image = session.backend_mut().image().unwrap();
        assert!(image.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())));
        errors.push(image.rmse(&rbf));
    }
    // Each doubling of the grid brings the image closer to the RBF image, and the finest grid
    // is close to it (quantisation is what remains).
    for w in errors.windows(2) {
        assert!(w[1] < w[0], "errors by grid 8..128: {errors:?}");
    }
    assert!(
        errors[4] < 0.25 * errors[0] && errors[4] < 0.02,
        "errors by grid 8..128: {errors:?}"
    );
}

#[test]
fn aarbf_render_draws_the_voxel_baseline_and_refuses_a_bad_grid() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(args)
            .env("AARBF_LOG", "warn")
            .output()
            .unwrap()
    };
    let generated = run(&[
        "generate",
        "dambreak-demo",
        "--out",
        d.to_str().unwrap(),
        "--count",
        "500",
        "--steps",
        "2",
    ]);
    assert!(generated.status.success());
    let data = String::from_utf8(generated.stdout).unwrap();
    let out = d.join("voxel.png");
    let common = [
        "render",
        "--data",
        data.trim(),
        "--backend",
        "cpu",
        "--width",
        "24",
        "--height",
        "24",
        "--spp",
        "2",
        "--method",
        "voxel",
        "--out",
        out.to_str().unwrap(),
    ];
    let scene = d.join("voxel.toml");
    let ok = run(&[
        &common[..],
        &[
            "--voxel-grid",
            "32",
            "--save-scene",
            scene.to_str().unwrap(),
        ],
    ]
    .concat());
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let image = image::open(&out).unwrap();
    assert_eq!((image.width(), image.height()), (24, 24));
    // The scene file carries the baseline: rendering it draws the same image.
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(text.contains("voxel_grid = 32"), "{text}");
    let again = d.join("again.png");
    let r = run(&[
        "render",
        "--scene",
        scene.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(
        image::open(&again).unwrap().to_rgba8().into_raw(),
        image.to_rgba8().into_raw(),
        "aarbf render --scene differs from the render that saved it"
    );
    // A scene asking for both baselines is refused, naming both.
    let both = d.join("both.toml");
    std::fs::write(
        &both,
        text.replace("voxel_grid = 32", "voxel_grid = 32\nsplat_k = 15"),
    )
    .unwrap();
    let r = run(&[
        "render",
        "--scene",
        both.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
        "--force",
    ]);
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(
        !r.status.success()
            && stderr.contains("splat_k = 15")
            && stderr.contains("voxel_grid = 32")
            && !stderr.contains("panicked"),
        "{stderr}"
    );
    let bad = run(&[&common[..], &["--voxel-grid", "0", "--force"]].concat());
    let stderr = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success() && stderr.contains("1..=1024"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"));
}
