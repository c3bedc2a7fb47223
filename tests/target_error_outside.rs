//! Error-targeted rendering on data from outside the estimator's own test scenes (issue 45).

use std::path::{Path, PathBuf};

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::converged::{ReferenceOptions, converged_reference};
use aarbf::render::target::{ErrorMetric, Target, render_to_target};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::{OpenOptions, TimeSeries, UpAxis};
use aarbf::values::{Image, Integrator};

struct Scene {
    name: &'static str,
    _dir: tempfile::TempDir,
    series: TimeSeries,
    step: usize,
    field: FieldSettings,
}

fn copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        if entry.file_type().unwrap().is_file() {
            std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
        }
    }
}

/// The PySPH dam break's last step, as `aarbf render --data FOLDER` takes it: coloured by
/// `rho`, the data's first attribute, radius 2 h.
fn pysph() -> Scene {
    let dir = tempfile::tempdir().unwrap();
    let folder = dir.path().join("pysph_dam_break");
    copy(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs/pysph_dam_break"),
        &folder,
    );
    let series = TimeSeries::open(&folder, &OpenOptions::default()).unwrap();
    let step = series.len() - 1;
    Scene {
        name: "pysph",
        _dir: dir,
        series,
        step,
        field: FieldSettings::new(Some("rho"), 2.0 * 0.052),
    }
}

/// A thin dense sheet and a dense ball with a steep edge inside a sparse halo, written as a
/// simulation writes its output: f64 text with 17 significant digits, a smoothing length per
/// particle (small where the particles are dense), 5003 particles.
fn sharp() -> Scene {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(45);
    let mut rows: Vec<[f64; 5]> = Vec::new();
    let n = [0.3_f64, 0.5, 0.81];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let n = n.map(|c| c / len);
    // In the sheet: two directions perpendicular to n.
    let u = {
        let a = [n[1], -n[0], 0.0];
        let l = (a[0] * a[0] + a[1] * a[1]).sqrt();
        a.map(|c| c / l)
    };
    let v = [
        n[1] * u[2] - n[2] * u[1],
        n[2] * u[0] - n[0] * u[2],
        n[0] * u[1] - n[1] * u[0],
    ];
    for _ in 0..2600 {
        let (s, t): (f64, f64) = (rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
        let w: f64 = rng.random_range(-0.004..0.004);
        let p: [f64; 3] = std::array::from_fn(|k| 0.5 + s * u[k] + t * v[k] + w * n[k]);
        rows.push([p[0], p[1], p[2], 1000.0 + 50.0 * s, 0.006]);
    }
    // A ball of radius 0.12 about (0.72, 0.3, 0.3), uniformly filled: a steep edge.
    while rows.len() < 2600 + 1500 {
        let p: [f64; 3] = std::array::from_fn(|_| rng.random_range(-0.12..0.12));
        if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 0.0144 {
            rows.push([0.72 + p[0], 0.3 + p[1], 0.3 + p[2], 800.0, 0.01]);
        }
    }
    // The halo.
    while rows.len() < 5003 {
        let p: [f64; 3] = std::array::from_fn(|_| rng.random_range(0.0..1.0));
        rows.push([p[0], p[1], p[2], 1.0 + 10.0 * p[2], 0.05]);
    }
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("snapshot_0000.csv");
    let mut text = String::from("x,y,z,Density,SmoothingLength\n");
    for r in &rows {
        let cells: Vec<String> = r.iter().map(|v| format!("{v:.16e}")).collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    std::fs::write(&file, text).unwrap();
    let series = TimeSeries::open(&file, &OpenOptions::default()).unwrap();
    Scene {
        name: "sharp",
        _dir: dir,
        series,
        step: 0,
        // The CLI's default: twice the median smoothing length (the sheet's).
        field: FieldSettings::new(Some("Density"), 2.0 * 0.006),
    }
}

fn settings(size: u32) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        integrator: Integrator::Ea,
        up_axis: UpAxis::Z,
        ..RenderSettings::default()
    }
}

fn k1() -> ClusterSize {
    ClusterSize::new(1).unwrap()
}

fn cache() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("accuracy-outside-references")
}

fn session(scene: &Scene) -> RenderSession {
    let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &scene.series);
    s.show(&scene.series, scene.step, &scene.field, k1())
        .unwrap();
    s
}

fn reference(scene: &Scene, s: &RenderSettings, tolerance: f64) -> Image {
    let r = converged_reference(
        &scene.series,
        scene.step,
        &scene.field,
        k1(),
        s,
        &ReferenceOptions {
            tolerance,
            cache: Some(cache()),
            ..ReferenceOptions::default()
        },
    )
    .unwrap();
    eprintln!(
        "{}: reference step {:.3e}, {} spp, spp change {:.2e}, step change {:?}, converged {}",
        scene.name, r.step_size, r.spp, r.spp_change, r.step_change, r.converged
    );
    r.image().clone()
}

/// The default density scale times `factor`: an opaque look, whose bias sits at the surfaces.
fn opaque(scene: &Scene, size: u32, factor: f64) -> RenderSettings {
    let mut s = settings(size);
    let r = session(scene).resolve(&s).unwrap();
    s.optical = aarbf::scene::maps::OpticalDensityMap::new(
        aarbf::scene::maps::PiecewiseLinear::ramp(0.0, 1.0),
        Some(r.density_scale * factor),
    )
    .unwrap();
    s
}

fn target(e: f64) -> Target {
    Target {
        error: Some(e),
        time_budget: None,
        metric: ErrorMetric::Rmse,
        max_spp: 4096,
    }
}

#[test]
fn an_opaque_pysph_step_estimates_its_step_bias() {
    // The PySPH step at 20 times the default density scale: the march's bias sits at the
    // fluid's surfaces and falls at order 0.6-0.8 with the step (against the reference:
    // 9.4e-4, 1.6e-3, 2.4e-3, 3.8e-3 at 0.5, 1, 2, 4 times the default step). A loose target
    // is decided from twice and four times the step, whose difference was taken as the bias
    // at twice the step (order 1): the estimate was 0.51 of the true error (2.5e-3).
    let scene = pysph();
    let s = opaque(&scene, 64, 20.0);
    // Converged to 4e-4: a sixth of the true errors it is held against (2.5e-3), so it moves
    // their ratio by under 2% (in quadrature), at a ninth of a 1e-4 reference's samples.
    let truth = reference(&scene, &s, 4e-4);
    let mut session = session(&scene);
    for e in [0.01, 0.005, 0.0025] {
        let done = render_to_target(&mut session, &s, &target(e)).unwrap();
        let true_error = done.image.rmse(&truth);
        let ratio = done.estimate / true_error;
        eprintln!(
            "pysph x20, E {e}: estimate {:.3e} (noise {:.3e}, bias {:.3e}), true {true_error:.3e} (x{ratio:.2}), step {:.3e}, {} spp",
            done.estimate,
            done.noise_rmse,
            done.bias.at(done.step_size),
            done.step_size,
            done.spp
        );
        assert!(done.met && true_error <= e, "E {e}: true {true_error:.3e}");
        // At 0.0025 the full calibration chooses the default step, and its 2-frame images
        // left the difference from twice the step (8.7e-4) within its noise (8.5e-4): taken
        // at order 2, the estimate was 0.38 of the truth (1.47e-3). It grows them until the
        // difference is resolved (docs/notes/2026-12-07-target-error.md).
        assert!(
            (0.7..=2.0).contains(&ratio),
            "E {e}: estimate {:.3e}, true {true_error:.3e}",
            done.estimate
        );
    }
}

#[test]
fn noise_held_by_a_few_pixels_is_measured_on_the_whole_image() {
    // The sharp scene at 20 times the default density: the sheet and the ball's edge are
    // opaque and the halo's particles are smaller than a pixel, so a few pixels hold most of
    // the noise (the lattice's estimate rested on 10-13 of its 1024 pixels and was 0.63-0.66
    // of the true noise). The noise estimate of the targeted render against its true noise
    // (its image against a converged image at the step it chose).
    let scene = sharp();
    let s = opaque(&scene, 64, 20.0);
    let mut session = session(&scene);
    let done = render_to_target(&mut session, &s, &target(0.005)).unwrap();
    let converged = session
        .render_frames(
            &RenderSettings {
                step_size: Some(done.step_size),
                seed: 1234,
                ..s.clone()
            },
            0,
            256,
        )
        .unwrap();
    let true_noise = done.image.rmse(&converged);
    let ratio = done.noise_rmse / true_noise;
    eprintln!(
        "sharp x20: noise estimate {:.3e}, true noise {true_noise:.3e} (x{ratio:.2}), step {:.3e}, {} spp",
        done.noise_rmse, done.step_size, done.spp
    );
    assert!((0.8..=1.25).contains(&ratio), "noise estimate x{ratio:.2}");
}

#[test]
fn a_bias_hidden_in_a_coarse_steps_noise_is_measured() {
    // The sharp scene at 20 times the default density, E = 0.005: four times the step is
    // far too coarse for the sheet and the halo's sub-step particles (its noise 8.8 times
    // twice the step's at as many frames), and the loose path took the difference between
    // twice and four times the step, hidden in that noise, as no bias: the estimate was 0.53
    // of the true error (3.1e-4 against 5.8e-4; the bias at twice the step is 5.3e-4).
    let scene = sharp();
    let s = opaque(&scene, 64, 20.0);
    // 1e-4: under a third of the true error, 13 s here.
    let truth = reference(&scene, &s, 1e-4);
    let mut session = session(&scene);
    let e = 0.005;
    let done = render_to_target(&mut session, &s, &target(e)).unwrap();
    let true_error = done.image.rmse(&truth);
    let ratio = done.estimate / true_error;
    eprintln!(
        "sharp x20, E {e}: estimate {:.3e} (noise {:.3e}, bias {:.3e}), true {true_error:.3e} (x{ratio:.2}), step {:.3e}, {} spp, work {:.1}",
        done.estimate,
        done.noise_rmse,
        done.bias.at(done.step_size),
        done.step_size,
        done.spp,
        done.work
    );
    assert!(done.met && true_error <= e, "true {true_error:.3e}");
    // Within 2x is the promise; 0.7 as for the PySPH step, where the estimate now lies
    // (0.53 before).
    assert!(
        (0.7..=2.0).contains(&ratio),
        "estimate {:.3e}, true {true_error:.3e}",
        done.estimate
    );
}
