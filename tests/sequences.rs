//! A frame does not depend on its neighbours: a step rendered inside a sequence, in a sequence
//! that starts elsewhere, or alone gives the same image bit for bit on the same backend and
//! seed. Every automatic setting (Phi_ref, the radii behind the march box and the default step)
//! is a property of the series and the field (`render::auto`); before, they came from the
//! first step a session rendered.

use std::path::Path;
use std::process::Command;

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Image, Integrator};

use crate::common;

fn frames(kind: BackendKind, series: &TimeSeries, steps: &[usize]) -> Vec<Image> {
    let mut field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    field.radius_attribute = None;
    let settings = RenderSettings {
        width: 32,
        height: 24,
        integrator: Integrator::Marching,
        seed: 9,
        ..RenderSettings::default()
    };
    let b = common::require(&format!("the {kind} backend"), backend::create(kind));
    let mut session = RenderSession::new(b, series);
    steps
        .iter()
        .map(|&step| {
            session
                .show(series, step, &field, ClusterSize::new(2).unwrap())
                .unwrap();
            session.render(&settings, 3).unwrap()
        })
        .collect()
}

#[test]
fn a_step_renders_the_same_alone_and_anywhere_in_a_sequence_on_every_backend() {
    common::capture_driver_messages();
    // The dam break spreads out over time: the first step is far denser than the last, which
    // is what made a sequence's first step set Phi_ref for all the others.
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(2500, 12, 4));
    for kind in [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash] {
        let sequence = frames(kind, &series, &[6, 7, 8, 9]);
        let later = frames(kind, &series, &[8, 9]);
        let alone = frames(kind, &series, &[9]);
        assert!(
            sequence[3] == alone[0] && later[1] == alone[0],
            "{kind}: step 9 differs between a sequence from step 6, one from step 8 and alone \
             (RMSE {:.3e}, {:.3e})",
            sequence[3].rmse(&alone[0]),
            later[1].rmse(&alone[0])
        );
        assert!(sequence[0] != sequence[3], "{kind}: the steps differ");
    }
    common::assert_no_driver_messages();
}

fn aarbf(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "aarbf {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `aarbf render` as a user runs it: a sequence rendered whole and in two chunks, and one step
/// alone, write byte-identical PNGs, and the values used are printed and saved in a scene file
/// that reproduces the frame.
#[test]
fn render_sequences_in_chunks_and_alone_write_the_same_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = d.join("db");
    aarbf(&[
        "generate",
        "dambreak-demo",
        "--out",
        s(&data),
        "--count",
        "1500",
        "--steps",
        "8",
    ]);
    let header = data.join("dambreak-demo.particles");
    let common = [
        "--data",
        s(&header),
        "--attribute",
        "attribute",
        "--backend",
        "cpu",
        "--width",
        "24",
        "--height",
        "20",
        "--spp",
        "2",
        "--integrator",
        "marching",
    ];
    let render = |extra: &[&str]| {
        let mut args = vec!["render"];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        aarbf(&args)
    };
    render(&["--steps", "2..7", "--out", s(&d.join("whole.png"))]);
    render(&["--steps", "2..5", "--out", s(&d.join("chunk.png"))]);
    render(&["--steps", "5..7", "--out", s(&d.join("chunk.png"))]);
    let log = render(&[
        "--step",
        "5",
        "--out",
        s(&d.join("alone.png")),
        "--save-scene",
        s(&d.join("alone.toml")),
    ]);
    let bytes = |name: &str| std::fs::read(d.join(name)).unwrap();
    assert_eq!(
        bytes("whole_0005.png"),
        bytes("alone.png"),
        "whole vs alone"
    );
    assert_eq!(
        bytes("chunk_0005.png"),
        bytes("alone.png"),
        "chunked vs alone"
    );
    assert_eq!(
        bytes("chunk_0004.png"),
        bytes("whole_0004.png"),
        "at the seam"
    );
    assert!(
        log.contains("phi_ref")
            && log.contains("step size")
            && log.contains("density scale")
            && log.contains("cluster size K = "),
        "the values used are printed: {log}"
    );
    // The saved scene holds every value the frame used; rendering it gives the same file.
    let scene = std::fs::read_to_string(d.join("alone.toml")).unwrap();
    for key in [
        "phi_ref",
        "step_size",
        "density_scale",
        "radius",
        "step = 5",
        "seed",
        "cluster = ",
    ] {
        assert!(
            scene.contains(key),
            "the scene file records {key}:\n{scene}"
        );
    }
    aarbf(&[
        "render",
        "--scene",
        s(&d.join("alone.toml")),
        "--backend",
        "cpu",
        "--out",
        s(&d.join("again.png")),
    ]);
    assert_eq!(
        bytes("again.png"),
        bytes("alone.png"),
        "the saved scene reproduces it"
    );
}

/// The cluster size a user leaves unset comes from the data: a jittered lattice (as a CSV with
/// 17 significant digits, an awkward 9 x 7 x 5 count) whose particles barely reach each other
/// gets K = 4, the same lattice with a radius reaching dozens of neighbours K = 16, and
/// `--cluster` overrides either; the choice is printed and saved in the scene file.
#[test]
fn the_cluster_size_follows_the_particles_overlap() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut csv = String::from("x,y,z,temperature\n");
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut jitter = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.2
    };
    for k in 0..5 {
        for j in 0..7 {
            for i in 0..9 {
                let p = [i, j, k].map(|v| 1e3 + 0.1 * (f64::from(v) + jitter()));
                let t = 250.0 + f64::from(i * j) / 7.0;
                csv += &format!("{:.17e},{:.17e},{:.17e},{t:.17e}\n", p[0], p[1], p[2]);
            }
        }
    }
    std::fs::write(d.join("lattice.csv"), csv).unwrap();
    let (data, out) = (d.join("lattice.csv"), d.join("out.png"));
    let render = |radius: &str, extra: &[&str]| -> (String, String) {
        let scene = d.join(format!("scene-{radius}-{}.toml", extra.len()));
        let mut args = vec![
            "render",
            "--data",
            s(&data),
            "--attribute",
            "temperature",
            "--radius",
            radius,
            "--backend",
            "cpu",
            "--width",
            "8",
            "--height",
            "8",
            "--spp",
            "1",
            "--out",
            s(&out),
            "--force",
            "--save-scene",
            s(&scene),
        ];
        args.extend_from_slice(extra);
        let log = aarbf(&args);
        (log, std::fs::read_to_string(&scene).unwrap())
    };
    // Spacing 0.1: radius 0.05 reaches no neighbour, 0.25 reaches dozens.
    let (log, scene) = render("0.05", &[]);
    assert!(log.contains("cluster size K = 4 (1.0 particles"), "{log}");
    assert!(scene.contains("cluster = 4"), "{scene}");
    let (log, scene) = render("0.25", &[]);
    assert!(log.contains("cluster size K = 16"), "{log}");
    assert!(scene.contains("cluster = 16"), "{scene}");
    let (log, scene) = render("0.25", &["--cluster", "2"]);
    assert!(!log.contains("cluster size K ="), "{log}");
    assert!(scene.contains("cluster = 2"), "{scene}");
}
