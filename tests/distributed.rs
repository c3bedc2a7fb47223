//! Distributed rendering against the single-rank render, on a dam break: the same frames
//! (every rank's and the single rank's from one `FrameBasis`), the CPU backend in f64, P ranks
//! of `LocalComm`. Emission–absorption without early termination differs from the single rank
//! only by rounding (the order terms are summed in and transmittances multiplied in); with
//! termination each brick stops at the threshold on its own, which costs at most the
//! threshold's remainder.

use std::sync::{Arc, OnceLock};

use aarbf::accel::ClusterSize;
use aarbf::backend::cpu::CpuBackend;
use aarbf::backend::{Backend, Precision, StepInput};
use aarbf::dist::{
    Comm, DistImage, DistScene, DistShadows, render_distributed, run_local, slice_of,
};
use aarbf::field::FieldSettings;
use aarbf::render::{AutoValues, FrameBasis, RenderSettings};
use aarbf::scene::{Camera, TimeSeries};
use aarbf::values::{FrameParams, Integrator, Step};
use glam::DVec3;

use crate::common;

/// A dam break of 30k particles, its third step (the column has begun to fall).
struct Scene {
    series: TimeSeries,
    step: Arc<Step>,
    field: FieldSettings,
}

const STEP: usize = 2;

fn scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| {
        use aarbf::scene::synth::Generator;
        let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(30_000, STEP + 1, 3));
        let step = series.step(STEP).unwrap();
        Scene {
            field: FieldSettings::new(Some("velocity"), 0.03),
            series,
            step,
        }
    })
}

/// `frames` frames of a 128 x 128 image from a view close to the fluid, over a coloured
/// background (so the finish over it is compared too).
fn frames(integrator: Integrator, count: u32, terminate: bool) -> Vec<FrameParams> {
    frames_sized(integrator, count, terminate, (128, 128), 1)
}

/// [`frames`] of another size and seed.
fn frames_sized(
    integrator: Integrator,
    count: u32,
    terminate: bool,
    (width, height): (u32, u32),
    seed: u32,
) -> Vec<FrameParams> {
    let s = scene();
    let settings = RenderSettings {
        width,
        height,
        seed,
        integrator,
        camera: Some(Camera {
            eye: DVec3::new(1.1, 0.6, 1.2),
            at: DVec3::new(0.4, 0.15, 0.15),
            up: DVec3::Y,
            fovy: 45.0,
        }),
        background: [0.1, 0.2, 0.3],
        ..RenderSettings::default()
    };
    let basis = FrameBasis {
        bounds: s.series.bounds(),
        max_count: s.series.max_count(),
        periodic: false,
        field: &s.field,
        auto: AutoValues::of(&s.series, &s.field).unwrap(),
    };
    (0..count)
        .map(|f| {
            let mut frame = basis.frame_params(&settings, f).unwrap();
            if !terminate {
                // Out of reach: every sample is composited.
                frame.opacity_threshold = 2.0;
            }
            frame
        })
        .collect()
}

fn dist_scene(s: &Scene) -> DistScene<'_> {
    DistScene {
        field: &s.field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: s.series.bounds(),
        series_range: s.series.attribute("velocity").map(|a| (a.min, a.max)),
        precision: Precision::F64,
        periodic: None,
        shadows: DistShadows::default(),
    }
}

/// The single-rank render: the whole step on one CPU backend, as `aarbf render` does it.
fn single_rank(frames: &[FrameParams]) -> (Vec<[f64; 4]>, aarbf::values::Image) {
    let s = scene();
    let d = dist_scene(s);
    let mut backend = CpuBackend::new();
    backend.upload(&d.step_input(&s.step, d.precision)).unwrap();
    backend.build().unwrap();
    for f in frames {
        backend.render(f).unwrap();
    }
    (backend.mean_f64().unwrap(), backend.image().unwrap())
}

fn distributed(ranks: usize, frames: &[FrameParams]) -> DistImage {
    let s = scene();
    let d = dist_scene(s);
    run_local(ranks, |comm| {
        let local = slice_of(&s.step, comm.rank(), comm.size());
        render_distributed(comm, &mut CpuBackend::new(), &local, &d, frames)
    })
    .unwrap()
    .swap_remove(0)
    .expect("rank 0 holds the image")
}

fn max_abs(a: &[[f64; 4]], b: &[[f64; 4]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f64::max)
}

/// Point `i` of the R3 quasi-random sequence in the unit cube: a fixed fill with no two
/// points alike and no lattice to line up with the bricks' planes.
fn r3_point(i: usize) -> DVec3 {
    let alpha = [
        0.819_172_513_396_164_4,
        0.671_043_606_703_789_2,
        0.549_700_477_901_970_4,
    ];
    DVec3::from_array(alpha.map(|a| (0.5 + a * i as f64).fract()))
}

/// Pixels where the data shows (opacity above a hundredth): the comparison is not of
/// background alone.
fn covered(pixels: &[[f64; 4]]) -> usize {
    pixels.iter().filter(|p| p[3] > 0.01).count()
}

#[test]
fn one_rank_is_bit_identical_to_the_single_rank_render() {
    for terminate in [false, true] {
        let frames = frames(Integrator::Ea, 2, terminate);
        let (want, want_image) = single_rank(&frames);
        let got = distributed(1, &frames);
        assert_eq!(got.frames, 2);
        assert!(covered(&want) > 2000, "{} pixels show data", covered(&want));
        assert!(
            got.mean == want,
            "termination {terminate}: max |diff| {:e}",
            max_abs(&got.mean, &want)
        );
        assert_eq!(got.image(), want_image);
        let r = got.reports[0];
        assert_eq!((r.read, r.owned, r.ghosts), (30_000, 30_000, 0));
    }
}

/// EA without early termination: every rank count matches the single rank to rounding.
/// The differences are the order of floating-point operations only: each sample's Phi summed
/// over the same particles in another order (a brick's cells hold fewer), and each pixel's
/// transmittance multiplied brick by brick; both are relative errors of a few ulps per
/// operation over a few hundred samples, far below 1e-12 on values of order 1.
#[test]
fn emission_absorption_without_termination_matches_to_rounding() {
    let frames = frames(Integrator::Ea, 2, false);
    let (want, _) = single_rank(&frames);
    let mut ghosts_seen = false;
    for p in [2, 3, 4, 8] {
        let got = distributed(p, &frames);
        let diff = max_abs(&got.mean, &want);
        let owned: u64 = got.reports.iter().map(|r| r.owned).sum();
        let ghosts: u64 = got.reports.iter().map(|r| r.ghosts).sum();
        eprintln!(
            "P = {p}: max |distributed - single rank| = {diff:.3e}; {ghosts} ghosts ({:.1}%)",
            100.0 * ghosts as f64 / owned as f64
        );
        assert_eq!(owned, 30_000);
        ghosts_seen |= ghosts > 0;
        assert!(diff <= 1e-12, "P = {p}: max abs difference {diff:e}");
        assert!(got.reports.iter().all(|r| r.f64_positions == 1));
    }
    assert!(ghosts_seen);
}

/// EA with the default opacity threshold (0.99): each brick stops on its own, so a pixel
/// differs from the single rank by at most what the threshold leaves behind a ray.
#[test]
fn emission_absorption_with_termination_stays_within_the_threshold() {
    let frames = frames(Integrator::Ea, 1, true);
    assert_eq!(frames[0].opacity_threshold, 0.99);
    let (want, _) = single_rank(&frames);
    for p in [2, 3, 4, 8] {
        let got = distributed(p, &frames);
        let diff = max_abs(&got.mean, &want);
        eprintln!("P = {p}, termination on: max |distributed - single rank| = {diff:.3e}");
        assert!(diff <= 0.01, "P = {p}: max abs difference {diff:e}");
    }
}

/// A brick wholly behind an opaque one renders nothing: a dense slab in front of the camera
/// and a cloud behind it of as many particles, split between two ranks at the gap.
/// Emission–absorption's occluding pass gives the cloud's brick the slab's depth, and under
/// the opacity threshold its rays end before their first sample: its layer is all
/// `[0, 0, 0, 1]`, so it sends rank 0 (which owns the image's one tile) nothing (and, last in
/// view order, no depth either). Without early termination it renders the cloud, which the
/// composite then hides. Both images are the single rank's (within the threshold's remainder).
#[test]
fn a_brick_behind_an_opaque_one_renders_nothing() {
    // A fixed quasi-random fill of a box.
    let fill = |n: usize, lo: DVec3, hi: DVec3| -> Vec<DVec3> {
        (0..n).map(|i| lo + (hi - lo) * r3_point(i)).collect()
    };
    let mut positions = fill(4507, DVec3::ZERO, DVec3::new(0.15, 1.0, 1.0));
    positions.extend(fill(
        4507,
        DVec3::new(0.85, 0.35, 0.35),
        DVec3::new(1.0, 0.65, 0.65),
    ));
    let attribute = positions.iter().map(|p| p.y + 0.5 * p.z).collect();
    let step = Step {
        name: "slab and cloud".into(),
        positions,
        attributes: vec![aarbf::values::Attribute {
            name: "a".into(),
            values: attribute,
        }],
    };
    let series = TimeSeries::from_steps(vec![step.clone()]);
    let field = FieldSettings::new(Some("a"), 0.06);
    let range = series.attribute("a").map(|a| (a.min, a.max));
    let settings = RenderSettings {
        width: 64,
        height: 48,
        camera: Some(Camera {
            eye: DVec3::new(-2.0, 0.5, 0.5),
            at: DVec3::splat(0.5),
            up: DVec3::Y,
            fovy: 20.0,
        }),
        ..RenderSettings::default()
    };
    let basis = FrameBasis {
        bounds: series.bounds(),
        max_count: series.max_count(),
        periodic: false,
        field: &field,
        auto: AutoValues::of(&series, &field).unwrap(),
    };
    let scene = DistScene {
        field: &field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: series.bounds(),
        series_range: range,
        precision: Precision::F64,
        periodic: None,
        shadows: DistShadows::default(),
    };
    for threshold in [0.99, 2.0] {
        let mut frame = basis.frame_params(&settings, 0).unwrap();
        frame.opacity_threshold = threshold;
        // Dense enough that the slab is opaque along every pixel.
        frame.density_scale *= 200.0;
        let frames = [frame];
        let mut single = CpuBackend::new();
        single
            .upload(&scene.step_input(&Arc::new(step.clone()), Precision::F64))
            .unwrap();
        single.build().unwrap();
        single.render(&frames[0]).unwrap();
        let want = single.mean_f64().unwrap();
        assert!(
            want.iter().all(|p| p[3] >= 0.99),
            "the slab covers the image: least opacity {}",
            want.iter().map(|p| p[3]).fold(1.0, f64::min)
        );
        let got = run_local(2, |comm| {
            let local = slice_of(&step, comm.rank(), comm.size());
            render_distributed(comm, &mut CpuBackend::new(), &local, &scene, &frames)
        })
        .unwrap()
        .swap_remove(0)
        .expect("rank 0 holds the image");
        let diff = max_abs(&got.mean, &want);
        let [front, behind] = [got.reports[0], got.reports[1]];
        eprintln!(
            "threshold {threshold}: max |distributed - single rank| {diff:.2e}; tile bytes sent \
             {} in front, {} behind",
            front.tile_bytes, behind.tile_bytes
        );
        assert_eq!(
            (front.owned, behind.owned),
            (4507, 4507),
            "split at the gap"
        );
        assert!(diff <= 0.01, "threshold {threshold}: {diff:e}");
        if threshold < 1.0 {
            assert_eq!(behind.tile_bytes, 0, "the cloud's brick sends nothing");
        } else {
            assert!(behind.tile_bytes > 0, "the cloud's brick renders it");
        }
    }
}

fn distributed_shadowed(ranks: usize, frames: &[FrameParams], shadows: DistShadows) -> DistImage {
    let s = scene();
    let d = DistScene {
        shadows,
        ..dist_scene(s)
    };
    run_local(ranks, |comm| {
        let local = slice_of(&s.step, comm.rank(), comm.size());
        render_distributed(comm, &mut CpuBackend::new(), &local, &d, frames)
    })
    .unwrap()
    .swap_remove(0)
    .expect("rank 0 holds the image")
}

/// One rank of every single-scattering integrator is the single-rank render bit for bit
/// (its brick is all of space: no depth in front, no brick nearer the light, brick 0's
/// numbers).
#[test]
fn one_rank_single_scattering_is_bit_identical() {
    for integrator in [
        Integrator::Marching,
        Integrator::Delta,
        Integrator::SsReference,
    ] {
        let frames = frames(integrator, 2, true);
        let (want, _) = single_rank(&frames);
        let got = distributed_shadowed(1, &frames, DistShadows::default());
        assert!(
            covered(&want) > 2000,
            "{integrator:?}: {} pixels",
            covered(&want)
        );
        assert!(
            got.mean == want,
            "{integrator:?}: max |diff| {:e}",
            max_abs(&got.mean, &want)
        );
    }
}

/// Stochastic marching scatters in the brick where the single rank does: the depth in front
/// of each brick (pass 1, scanned in view order) plus its own passes the same free-flight
/// depth at the same sample. Under ambient light only (no shadow ray to cross bricks) the
/// image is the single rank's up to rounding.
#[test]
fn stochastic_marching_scatters_where_the_single_rank_does() {
    let mut frames = frames(Integrator::Marching, 2, true);
    for f in &mut frames {
        f.light_intensity = 0.0;
        f.ambient = 1.0;
    }
    let (want, _) = single_rank(&frames);
    assert!(covered(&want) > 2000, "{} pixels", covered(&want));
    for p in [2, 3, 4, 8] {
        let got = distributed_shadowed(p, &frames, DistShadows::Local);
        let diff = max_abs(&got.mean, &want);
        eprintln!("marching, ambient only, P = {p}: max |diff| = {diff:.3e}");
        assert!(diff <= 1e-12, "P = {p}: max abs difference {diff:e}");
    }
}

/// Shadows across bricks by the prefix map follow the single rank's shadows: FLIP at most
/// 0.02, and far closer than shadows from each ray's own brick only (`local`, which lets
/// light through every brick nearer the light).
#[test]
fn shadows_across_bricks_follow_the_single_rank() {
    let frames = frames(Integrator::Marching, 1, true);
    let (_, want) = single_rank(&frames);
    for p in [2, 3, 4, 8] {
        let image = |shadows| distributed_shadowed(p, &frames, shadows).image();
        let (map, local) = (
            image(DistShadows::PrefixMap(256)),
            image(DistShadows::Local),
        );
        let (flip_map, flip_local) = (map.flip(&want), local.flip(&want));
        eprintln!(
            "P = {p}: prefix map 256² FLIP {flip_map:.4} RMSE {:.4}; local FLIP {flip_local:.4} RMSE {:.4}",
            map.rmse(&want),
            local.rmse(&want)
        );
        assert!(flip_map <= 0.02, "P = {p}: FLIP {flip_map}");
        assert!(
            flip_map < 0.5 * flip_local,
            "P = {p}: prefix map {flip_map} against local {flip_local}"
        );
    }
}

/// Delta tracking restarts in every brick with the brick's own numbers (a free flight is
/// memoryless), so a distributed image is another sample of the same estimate: at 1024 spp it
/// differs from the single rank's by what two single-rank seeds differ by, and no more on
/// average (no bias).
#[test]
fn delta_tracking_across_bricks_is_within_two_seeds_noise() {
    let size = (16, 16);
    let spp = 1024;
    let frames_a = frames_sized(Integrator::Delta, spp, true, size, 1);
    let frames_b = frames_sized(Integrator::Delta, spp, true, size, 2);
    let (_, a) = single_rank(&frames_a);
    let (_, b) = single_rank(&frames_b);
    let mean_difference = |x: &aarbf::values::Image, y: &aarbf::values::Image| {
        let sum: f64 = x
            .pixels
            .iter()
            .zip(&y.pixels)
            .flat_map(|(p, q)| (0..3).map(move |c| f64::from(p[c]) - f64::from(q[c])))
            .sum();
        sum / (3 * x.pixels.len()) as f64
    };
    let seeds = a.rmse(&b);
    // The standard error of a mean difference of independent estimates over the image.
    let standard_error = seeds / ((3 * a.pixels.len()) as f64).sqrt();
    assert!(seeds > 0.0);
    for p in [3, 8] {
        let got = distributed_shadowed(p, &frames_a, DistShadows::PrefixMap(256)).image();
        let (rmse, bias) = (got.rmse(&b), mean_difference(&got, &b));
        eprintln!(
            "delta, {spp} spp, P = {p}: RMSE against seed 2 {rmse:.5} (seeds 1 and 2: {seeds:.5}); \
             mean difference {bias:.2e} (standard error {standard_error:.2e})"
        );
        assert!(
            rmse <= 1.25 * seeds,
            "P = {p}: RMSE {rmse} against the seeds' {seeds}"
        );
        assert!(
            bias.abs() <= 4.0 * standard_error,
            "P = {p}: mean difference {bias:e}, standard error {standard_error:e}"
        );
    }
}

/// `aarbf render --ranks 3` as a user runs it: the same image as without `--ranks` (the
/// default termination on: within its threshold), also with `--balance cost`, the ranks'
/// counts logged, the single rank's Phi_ref and cluster size found from the ranks' parts of
/// step 0, and what is not distributed yet refused by name.
#[test]
fn the_command_line_renders_with_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = common::generated_dam_break(d);
    let render = |name: &str, extra: &[&str]| {
        let path = d.join(name);
        let mut args = common::dam_break_render_args(&header, &path, (64, 48), 2);
        args.extend(extra.iter().map(|a| a.to_string()));
        let out = common::aarbf_logged(&args.iter().map(String::as_str).collect::<Vec<_>>());
        (out, path)
    };
    let (single, single_path) = render("single.exr", &[]);
    assert!(
        single.status.success(),
        "{}",
        String::from_utf8_lossy(&single.stderr)
    );
    let (ranked, ranked_path) = render("ranks.exr", &["--ranks", "3"]);
    let log = String::from_utf8_lossy(&ranked.stderr);
    assert!(ranked.status.success(), "{log}");
    assert!(
        log.contains("rank 2: read") && log.contains("owned once each"),
        "{log}"
    );
    // The automatic values that come from step 0, computed by the ranks from their parts of
    // it: the single rank's Phi_ref (to the order of its sums) and cluster size.
    let single_log = String::from_utf8_lossy(&single.stderr);
    let (phi_ref, single_phi_ref) = (logged_phi_ref(&log), logged_phi_ref(&single_log));
    assert!(
        (phi_ref - single_phi_ref).abs() <= 1e-12 * single_phi_ref,
        "--ranks 3: phi_ref {phi_ref}, single rank {single_phi_ref}"
    );
    assert!(log.contains("from the 3 ranks' parts of step 0"), "{log}");
    let cluster = |log: &str| {
        log.lines()
            .find_map(|l| l.split_once("cluster size K = ").map(|(_, k)| k.to_owned()))
            .unwrap_or_else(|| panic!("no cluster size in {log}"))
    };
    assert_eq!(cluster(&log), cluster(&single_log));
    let a = image::open(&single_path).unwrap().to_rgba32f();
    assert_eq!(a.dimensions(), (64, 48));
    let diff = common::max_image_difference(&single_path, &ranked_path);
    assert!(a.as_raw().iter().any(|&v| v > 0.05), "the fluid shows");
    assert!(
        diff <= 0.01,
        "--ranks 3 differs from the single-rank image by {diff}"
    );

    // Balanced by measured cost: the same image, and refused where nothing is distributed.
    let (cost, cost_path) = render("cost.exr", &["--ranks", "3", "--balance", "cost"]);
    let log = String::from_utf8_lossy(&cost.stderr);
    assert!(cost.status.success(), "{log}");
    assert!(log.contains("slowest render"), "{log}");
    let diff = common::max_image_difference(&single_path, &cost_path);
    assert!(diff <= 0.01, "--balance cost differs by {diff}");
    let (refused, path) = render("lone.exr", &["--balance", "cost"]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("--balance cost") && err.contains("--ranks"),
        "{err}"
    );
    assert!(!path.exists());

    // Single scattering, shadows across bricks by the light map: the single rank's image up
    // to the map's interpolation across the light.
    let (single_ss, single_ss_path) = render("ss1.exr", &["--integrator", "marching"]);
    assert!(single_ss.status.success());
    let (ss, ss_path) = render("ss.exr", &["--ranks", "2", "--integrator", "marching"]);
    let log = String::from_utf8_lossy(&ss.stderr);
    assert!(ss.status.success(), "{log}");
    assert!(log.contains("64x64 light map"), "{log}");
    let (a, b) = (
        image::open(&single_ss_path).unwrap().to_rgba32f(),
        image::open(&ss_path).unwrap().to_rgba32f(),
    );
    let mean: f32 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (x - y).abs())
        .sum::<f32>()
        / a.as_raw().len() as f32;
    assert!(
        mean <= 0.005,
        "--ranks 2 marching: mean |difference| {mean}"
    );
    let (ea, _) = render("ea-shadows.exr", &["--ranks", "2", "--shadow-map", "32"]);
    let log = String::from_utf8_lossy(&ea.stderr);
    assert!(ea.status.success(), "{log}");
    assert!(log.contains("no effect on emission-absorption"), "{log}");
    let (refused, _) = render("lonely.exr", &["--dist-shadows", "local"]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        err.contains("--dist-shadows") && err.contains("--ranks"),
        "{err}"
    );

    // A build without MPI started by mpirun: each process would render the whole image.
    #[cfg(not(feature = "mpi"))]
    {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(["render", "--data", &header, "--out"])
            .arg(d.join("mpi.png"))
            .env("OMPI_COMM_WORLD_SIZE", "4")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(
            err.contains("--ranks 4") && err.contains("--features mpi"),
            "{err}"
        );
        assert!(!d.join("mpi.png").exists());
    }
}

/// The Phi_ref a render's log says it used (`phi_ref X (...)`).
fn logged_phi_ref(log: &str) -> f64 {
    log.lines()
        .find_map(|line| {
            let (_, after) = line.split_once("phi_ref ")?;
            after.split_whitespace().next()?.parse().ok()
        })
        .unwrap_or_else(|| panic!("no phi_ref in the log:\n{log}"))
}

/// The f32 path (the CPU's fast kernel, where its bound allows): each brick holds its own
/// f32 cells, so the terms are rounded differently from the single rank's, but the samples,
/// the noise and the compositing are the same.
#[test]
fn emission_absorption_in_f32_matches_to_f32_rounding() {
    let frames = frames(Integrator::Ea, 1, false);
    let s = scene();
    let d = DistScene {
        precision: Precision::F32,
        ..dist_scene(s)
    };
    let mut backend = CpuBackend::new();
    backend.upload(&d.step_input(&s.step, d.precision)).unwrap();
    backend.build().unwrap();
    backend.render(&frames[0]).unwrap();
    let want = backend.mean_f64().unwrap();
    for p in [2, 4] {
        let got = run_local(p, |comm| {
            let local = slice_of(&s.step, comm.rank(), comm.size());
            render_distributed(comm, &mut CpuBackend::new(), &local, &d, &frames)
        })
        .unwrap()
        .swap_remove(0)
        .unwrap();
        assert!(got.reports.iter().all(|r| r.f64_positions == 0));
        let diff = max_abs(&got.mean, &want);
        eprintln!("P = {p}, f32: max |distributed - single rank| = {diff:.3e}");
        assert!(diff <= 1e-5, "P = {p}: max abs difference {diff:e}");
    }
}

/// A periodic box, as a cosmological code writes it: particles filling `[0, 1)³` (a few a
/// rounding outside it, as codes leave them), each felt across the faces through its periodic
/// images. Every rank wraps its own particles and makes their images; the images are then
/// exchanged as particles, so a brick at a face sums those across it. The image matches the
/// single rank's periodic render to rounding at every P, and differs from the open box's
/// (the test sees the wrap).
#[test]
fn a_periodic_box_matches_the_single_rank_to_rounding() {
    use aarbf::field::PeriodicBox;
    let n: usize = 6001;
    // A fixed quasi-random fill, and every 97th particle pushed 1e-12 past a face.
    let positions: Vec<DVec3> = (0..n)
        .map(|i| {
            let p = r3_point(i);
            if i % 97 == 0 {
                p.with_x(1.0 + 1e-12)
            } else {
                p
            }
        })
        .collect();
    let attribute = positions.iter().map(|p| (6.0 * p.y).sin() + p.z).collect();
    let step = Step {
        name: "periodic".into(),
        positions,
        attributes: vec![aarbf::values::Attribute {
            name: "a".into(),
            values: attribute,
        }],
    };
    let series = TimeSeries::from_steps(vec![step.clone()]);
    let field = FieldSettings::new(Some("a"), 0.11);
    let range = series.attribute("a").map(|a| (a.min, a.max));
    let pbox = PeriodicBox::from_origin([1.0; 3]).unwrap();
    let settings = RenderSettings {
        width: 96,
        height: 80,
        camera: Some(Camera {
            eye: DVec3::new(2.1, 1.4, 1.9),
            at: DVec3::splat(0.5),
            up: DVec3::Y,
            fovy: 40.0,
        }),
        ..RenderSettings::default()
    };
    let basis = FrameBasis {
        bounds: pbox.bounds(),
        max_count: series.max_count(),
        periodic: true,
        field: &field,
        auto: AutoValues::of(&series, &field).unwrap(),
    };
    let frames: Vec<FrameParams> = (0..2)
        .map(|f| {
            let mut frame = basis.frame_params(&settings, f).unwrap();
            frame.opacity_threshold = 2.0;
            frame
        })
        .collect();

    // The single rank, as `render::Session` uploads a periodic step: with its images, the
    // Hilbert grid over the box grown by the largest reach.
    let images = pbox.images(&step, &field, range).unwrap();
    assert_eq!(images.wrapped, n.div_ceil(97));
    let mut single = CpuBackend::new();
    single
        .upload(&StepInput {
            step: &images.step,
            field: &field,
            cluster: ClusterSize::new(4).unwrap(),
            series_bounds: pbox.bounds().grown(images.largest_reach),
            series_range: range,
            precision: Precision::F64,
        })
        .unwrap();
    single.build().unwrap();
    for f in &frames {
        single.render(f).unwrap();
    }
    let want = single.mean_f64().unwrap();
    assert!(covered(&want) > 3000, "{} pixels show data", covered(&want));

    let scene = |periodic| DistScene {
        field: &field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: series.bounds(),
        series_range: range,
        precision: Precision::F64,
        periodic,
        shadows: DistShadows::default(),
    };
    let render = |ranks: usize, scene: &DistScene<'_>| {
        run_local(ranks, |comm| {
            let local = slice_of(&step, comm.rank(), comm.size());
            render_distributed(comm, &mut CpuBackend::new(), &local, scene, &frames)
        })
        .unwrap()
        .swap_remove(0)
        .expect("rank 0 holds the image")
    };
    let periodic = scene(Some(pbox));
    let one = render(1, &periodic);
    assert!(one.mean == want, "P = 1: {:e}", max_abs(&one.mean, &want));
    for p in [2, 3, 5, 8] {
        let got = render(p, &periodic);
        let diff = max_abs(&got.mean, &want);
        let owned: u64 = got.reports.iter().map(|r| r.owned).sum();
        eprintln!("periodic, P = {p}: max |distributed - single rank| = {diff:.3e}");
        assert_eq!(
            owned as usize,
            images.step.len(),
            "particles and images owned once"
        );
        assert!(diff <= 1e-12, "P = {p}: max abs difference {diff:e}");
    }
    let open = render(3, &scene(None));
    let seen = max_abs(&open.mean, &want);
    assert!(
        seen > 1e-3,
        "the open box renders the periodic image ({seen:e})"
    );
}

/// A SWIFT snapshot as h5py writes it (tests/data/h5py_swift: two particle types, a periodic
/// box in its header) rendered as a user would, with no data flags: `--ranks 3` renders the
/// periodic box as one rank does, within the opacity threshold's remainder.
#[test]
fn an_hdf5_snapshot_in_a_periodic_box_renders_with_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = common::swift_snapshot_copy(d);
    let render = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        let mut args = common::swift_render_args(&data, &out);
        args.extend(extra.iter().map(|a| a.to_string()));
        let run = common::aarbf_logged(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let log = String::from_utf8_lossy(&run.stderr).into_owned();
        assert!(run.status.success(), "{log}");
        (out, log)
    };
    let (single, _) = render("single.exr", &[]);
    let (ranked, log) = render("ranks.exr", &["--ranks", "3"]);
    assert!(log.contains("periodic box"), "{log}");
    let (open, _) = render("open.exr", &["--ranks", "3", "--no-periodic"]);
    let gas = image::open(&single).unwrap().to_rgba32f();
    assert!(gas.as_raw().iter().any(|&v| v > 0.01), "the gas shows");
    let d_ranked = common::max_image_difference(&single, &ranked);
    eprintln!("h5py SWIFT, periodic: max |--ranks 3 - single rank| = {d_ranked:e}");
    assert!(d_ranked <= 0.01, "--ranks 3 differs by {d_ranked}");
    assert!(
        common::max_image_difference(&single, &open) > d_ranked,
        "the open box renders as the periodic one"
    );

    // Single scattering on the same snapshot: shadows across the bricks of a periodic box.
    let (single, _) = render("ss-single.exr", &["--integrator", "marching"]);
    let (ranked, log) = render(
        "ss-ranks.exr",
        &["--integrator", "marching", "--ranks", "3"],
    );
    assert!(log.contains("light map"), "{log}");
    let (a, b) = (
        image::open(&single).unwrap().to_rgba32f(),
        image::open(&ranked).unwrap().to_rgba32f(),
    );
    assert!(a.as_raw().iter().any(|&v| v > 0.01), "the gas shows");
    let mean = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (x - y).abs())
        .sum::<f32>()
        / a.as_raw().len() as f32;
    eprintln!("h5py SWIFT, periodic, marching: mean |--ranks 3 - single rank| = {mean:e}");
    assert!(
        mean <= 0.005,
        "--ranks 3 marching differs by {mean} on average"
    );
}

/// `aarbf bench distributed` as a user runs it: a row per run and rank in the CSV, each run's
/// particles owned once over its ranks, the summary's two tables, and no overwrite without
/// `--force`.
#[test]
fn the_scaling_benchmark_reports_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let args = [
        "bench",
        "distributed",
        "--ranks",
        "1,3",
        "--count",
        "3001",
        "--weak-count",
        "1500",
        "--size",
        "48x40",
        "--out",
        out.to_str().unwrap(),
    ];
    let summary = common::aarbf_ok(&args);
    assert!(
        summary.contains("## Strong scaling") && summary.contains("## Weak scaling"),
        "{summary}"
    );
    let csv = std::fs::read_to_string(out.join("distributed.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    // Strong: 1 + 3 ranks; weak: 1 + 3 ranks.
    assert_eq!(rows.len(), 8, "{csv}");
    for (scaling, ranks, particles) in [
        ("strong", 1, 3001),
        ("strong", 3, 3001),
        ("weak", 1, 1500),
        ("weak", 3, 4500),
    ] {
        let run: Vec<&Vec<&str>> = rows
            .iter()
            .filter(|r| r[col("scaling")] == scaling && r[col("ranks")] == ranks.to_string())
            .collect();
        assert_eq!(run.len(), ranks, "{scaling} {ranks}: {csv}");
        let sum = |name: &str| -> u64 {
            run.iter()
                .map(|r| r[col(name)].parse::<u64>().unwrap())
                .sum()
        };
        assert_eq!(sum("owned"), particles, "{scaling} {ranks}");
        assert_eq!(sum("read"), particles, "{scaling} {ranks}");
        assert!(
            run.iter()
                .all(|r| r[col("render_cpu_s")].parse::<f64>().unwrap() > 0.0)
        );
        assert!(
            run.iter()
                .all(|r| r[col("memory_bytes")].parse::<u64>().unwrap() > 0)
        );
        if ranks > 1 {
            assert!(
                sum("ghosts") > 0 && sum("tile_bytes") > 0,
                "{scaling} {ranks}"
            );
        }
    }
    let again = common::aarbf_logged(&args);
    assert!(!again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("--force"));

    // Single scattering: the light map is a stage of its own, and the shadows are compared
    // with the single rank's for each map side and `local`.
    let out = dir.path().join("bench-ss");
    let summary = common::aarbf_ok(&[
        "bench",
        "distributed",
        "--ranks",
        "1,3",
        "--count",
        "3001",
        "--weak-count",
        "0",
        "--size",
        "48x40",
        "--integrator",
        "marching",
        "--shadow-map",
        "32",
        "--shadow-maps",
        "16,64",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        summary.contains("## Shadows across bricks against the single rank"),
        "{summary}"
    );
    let csv = std::fs::read_to_string(out.join("distributed.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let three: Vec<Vec<&str>> = lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[col("ranks")] == "3")
        .collect();
    assert_eq!(three.len(), 3, "{csv}");
    assert!(
        three
            .iter()
            .all(|r| r[col("shadow_map_cpu_s")].parse::<f64>().unwrap() > 0.0),
        "{csv}"
    );
    let shadows = std::fs::read_to_string(out.join("shadows.csv")).unwrap();
    let rows: Vec<Vec<&str>> = shadows
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let flip = |how: &str, map: &str| -> f64 {
        rows.iter()
            .find(|r| r[1] == how && r[2] == map)
            .unwrap_or_else(|| panic!("{how} {map}: {shadows}"))[3]
            .parse()
            .unwrap()
    };
    assert_eq!(rows.len(), 3, "{shadows}");
    assert!(
        flip("prefix-map", "64") < flip("local", "0"),
        "the light map is closer to the single rank than local shadows: {shadows}"
    );
}

/// Balanced by cost (`--balance cost`), the leaves move and the image does not: a render
/// decomposed by a cost model in which one region costs three times as much a particle is
/// still the single rank's to rounding, and its bricks' particles follow the cost. (The model
/// is given rather than measured, so the leaves move the same on every run.)
#[test]
fn a_cost_balanced_render_is_still_the_single_rank_image() {
    use aarbf::dist::kd::{KdTree, WeightedPoint};
    use aarbf::dist::{CostModel, render_balanced};
    let frames = frames(Integrator::Ea, 1, false);
    let (want, _) = single_rank(&frames);
    let s = scene();
    let d = dist_scene(s);
    let sample: Vec<WeightedPoint> = s
        .step
        .positions
        .iter()
        .step_by(97)
        .map(|p| WeightedPoint {
            at: p.to_array(),
            weight: 1.0,
            reach: 0.0,
        })
        .collect();
    let model = CostModel::new(KdTree::build(&sample, 2), &[[1000.0, 3.0], [1000.0, 1.0]]);
    let results = run_local(4, |comm| {
        let local = slice_of(&s.step, comm.rank(), comm.size());
        let mut backend = CpuBackend::new();
        let (by_count, _) = render_balanced(comm, &mut backend, &local, &d, &frames, None)?;
        let (by_cost, _) = render_balanced(comm, &mut backend, &local, &d, &frames, Some(&model))?;
        Ok((by_count, by_cost))
    })
    .unwrap();
    let (Some(by_count), Some(by_cost)) = &results[0] else {
        panic!("rank 0 holds the images");
    };
    let owned = |image: &DistImage| image.reports.iter().map(|r| r.owned).collect::<Vec<_>>();
    let (count, cost) = (owned(by_count), owned(by_cost));
    eprintln!("balanced by cost: owned {cost:?} (by count {count:?})");
    assert!(
        cost.iter().max() > count.iter().max(),
        "the cheap region's bricks hold more particles: {cost:?} against {count:?}"
    );
    assert_eq!(cost.iter().sum::<u64>(), 30_000);
    let diff = max_abs(&by_cost.mean, &want);
    assert!(diff <= 1e-12, "max abs difference {diff:e}");
}

/// Ranks that read their parts of a file (`TimeSeries::step_part`, as `aarbf render --ranks`
/// does) render the image of ranks that cut their share from the whole step: the dam break
/// written as NumPy writes a float64 array holds the same particles, in the same order, so the
/// images are bit-identical, for P not dividing N.
#[test]
fn ranks_reading_their_parts_render_what_ranks_cutting_the_whole_step_render() {
    let s = scene();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dambreak.npy");
    let velocity = &s.step.attribute("velocity").unwrap().values;
    let table: Vec<f64> = s
        .step
        .positions
        .iter()
        .zip(velocity)
        .flat_map(|(p, v)| [p.x, p.y, p.z, *v])
        .collect();
    common::write_numpy(&path, s.step.len(), 4, &table);
    let series = TimeSeries::open(&path, &aarbf::scene::OpenOptions::default()).unwrap();
    let field = FieldSettings::new(Some("col3"), 0.03);
    let d = DistScene {
        field: &field,
        ..dist_scene(s)
    };
    let frames = frames(Integrator::Ea, 1, false);
    for ranks in [3, 7] {
        let parts = run_local(ranks, |comm| {
            let part = aarbf::io::Part::new(comm.rank(), comm.size());
            let read = series
                .step_part(0, part, &aarbf::dist::knn::RankLengths { comm })
                .unwrap();
            assert_eq!(read.decoded, part.range(s.step.len()).len());
            render_distributed(comm, &mut CpuBackend::new(), &read.step, &d, &frames)
        })
        .unwrap()
        .swap_remove(0)
        .unwrap();
        let cut = distributed(ranks, &frames);
        assert_eq!(parts.mean, cut.mean, "{ranks} ranks");
        assert_eq!(parts.reports.len(), ranks);
        for (r, (a, b)) in parts.reports.iter().zip(&cut.reports).enumerate() {
            assert_eq!(
                (a.read, a.owned, a.ghosts),
                (b.read, b.owned, b.ghosts),
                "rank {r}"
            );
        }
    }
}

/// Series as SPH codes lay them out, with no index beside them and no `--attribute`,
/// `--radius` or `--phi-ref`: under `--ranks`, the ranks scan the steps the index lacks and find
/// the defaults (the colour, the radius from the median smoothing length or from the spacing)
/// from their parts, and say the single rank's values; the image is the single rank's.
#[test]
fn ranks_find_a_new_series_defaults_from_their_parts() {
    let runs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs");
    // SWIFT-like CSV (%.17g; 'SmoothingLength': radius 2 x its median); GADGET-like NumPy
    // (no smoothing length: radius from the spacing).
    let series = [
        (
            "swift_like",
            "output_*.csv",
            "median smoothing length 'SmoothingLength'",
        ),
        ("gadget_like", "snapshot_*.npy", "particles' spacing"),
    ];
    for (folder, pattern, how) in series {
        let copy = |dir: &std::path::Path| {
            for entry in std::fs::read_dir(runs.join(folder)).unwrap() {
                let path = entry.unwrap().path();
                if path.is_file() {
                    std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
                }
            }
            dir.join(pattern)
        };
        let (one, ranked) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        let render = |data: std::path::PathBuf, out: std::path::PathBuf, extra: &[&str]| {
            let mut args: Vec<String> = ["render", "--width", "64", "--height", "48", "--spp", "1"]
                .map(String::from)
                .to_vec();
            args.extend(["--data".into(), data.display().to_string()]);
            args.extend(["--out".into(), out.display().to_string()]);
            args.extend(extra.iter().map(|a| a.to_string()));
            let out = common::aarbf_logged(&args.iter().map(String::as_str).collect::<Vec<_>>());
            let log = String::from_utf8_lossy(&out.stderr).into_owned();
            assert!(out.status.success(), "{folder} {extra:?}: {log}");
            log
        };
        let single_log = render(copy(one.path()), one.path().join("single.exr"), &[]);
        let log = render(
            copy(ranked.path()),
            ranked.path().join("ranks.exr"),
            &["--ranks", "3"],
        );
        let line = |log: &str, start: &str| {
            log.lines()
                .find_map(|l| l.split_once(start).map(|(_, rest)| rest.to_owned()))
                .unwrap_or_else(|| panic!("{folder}: no '{start}' in {log}"))
        };
        for start in ["radius: ", "colour: ", "cluster size K = "] {
            assert_eq!(
                line(&log, start),
                line(&single_log, start),
                "{folder}: {start}"
            );
        }
        assert!(line(&log, "radius: ").contains(how), "{folder}: {log}");
        assert!(
            log.contains("steps the series' index lacks, each rank its part of each"),
            "{folder}: {log}"
        );
        let a = image::open(one.path().join("single.exr"))
            .unwrap()
            .into_rgba32f();
        let b = image::open(ranked.path().join("ranks.exr"))
            .unwrap()
            .into_rgba32f();
        let diff = a
            .as_raw()
            .iter()
            .zip(b.as_raw())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        eprintln!("{folder}: --ranks 3 max |difference| {diff:.2e}");
        assert!(diff <= 1e-5, "{folder}: max |difference| {diff}");
        // The ranks wrote the index a later open uses.
        assert!(ranked.path().join(".aarbf-index.json").exists());
    }
}

/// A GADGET-like NumPy series without smoothing lengths, `--smoothing knn:16`, no index and
/// no cache beside it: under `--ranks 3` the ranks find each particle's length together from
/// their parts (no rank reads a step whole) and render the single rank's image; the lengths
/// they cache are the single rank's.
#[test]
fn ranks_find_neighbour_smoothing_lengths_from_their_parts() {
    let runs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs");
    let copy = |dir: &std::path::Path| {
        for n in 0..3 {
            let name = format!("snapshot_{n:03}.npy");
            std::fs::copy(runs.join("gadget_like").join(&name), dir.join(&name)).unwrap();
        }
        dir.join("snapshot_*.npy")
    };
    let render = |dir: &std::path::Path, extra: &[&str]| {
        let mut args: Vec<String> = [
            "render",
            "--width",
            "64",
            "--height",
            "48",
            "--spp",
            "1",
            "--smoothing",
            "knn:16",
            "--step",
            "2",
        ]
        .map(String::from)
        .to_vec();
        args.extend(["--data".into(), copy(dir).display().to_string()]);
        args.extend(["--out".into(), dir.join("out.exr").display().to_string()]);
        args.extend(extra.iter().map(|a| a.to_string()));
        let out = common::aarbf_logged(&args.iter().map(String::as_str).collect::<Vec<_>>());
        let log = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{extra:?}: {log}");
        log
    };
    let (one, ranked) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let single_log = render(one.path(), &[]);
    let log = render(ranked.path(), &["--ranks", "3"]);
    // The steps scanned from the ranks' parts, their lengths with them.
    assert!(
        log.contains("steps the series' index lacks, each rank its part of each"),
        "{log}"
    );
    let line = |log: &str, start: &str| {
        log.lines()
            .find_map(|l| l.split_once(start).map(|(_, rest)| rest.to_owned()))
            .unwrap_or_else(|| panic!("no '{start}' in {log}"))
    };
    for start in ["radius: ", "colour: ", "cluster size K = "] {
        assert_eq!(line(&log, start), line(&single_log, start), "{start}");
    }
    assert!(line(&log, "radius: ").contains("h_knn16"), "{log}");
    // The backend is chosen once: the ranks that are threads take the first one's kind.
    assert_eq!(
        log.matches("auto: ").count(),
        single_log.matches("auto: ").count(),
        "{log}"
    );
    let image = |dir: &std::path::Path| image::open(dir.join("out.exr")).unwrap().into_rgba32f();
    let (a, b) = (image(one.path()), image(ranked.path()));
    let diff = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f32, f32::max);
    eprintln!("knn:16 --ranks 3 max |difference| {diff:.2e}");
    assert!(a.as_raw().iter().any(|&v| v > 0.01), "the particles show");
    assert!(diff <= 1e-5, "max |difference| {diff}");
    // Each step's lengths cached beside the data by the ranks, as one process caches them.
    let (single_cache, ranks_cache) = (
        common::cached_lengths(one.path()),
        common::cached_lengths(ranked.path()),
    );
    assert_eq!(ranks_cache.len(), 3, "{ranks_cache:?}");
    assert_eq!(single_cache, ranks_cache);
}

/// A targeted render's chunks of frames over the ranks (`dist::target::RankChunks`: each rank
/// renders its brick's share, rank 0 composites and sends every rank the image) are the
/// single process's session's chunks: later chunks of a sequence (their frame numbers pick
/// the noise) and chunks on the half-resolution lattice, every rank holding the same image.
/// Emission-absorption without early termination, where the ranks' image is the single
/// rank's up to rounding.
#[test]
fn the_ranks_chunks_of_frames_are_a_session_s() {
    use aarbf::dist::prepare_brick;
    use aarbf::dist::target::RankChunks;
    use aarbf::render::RenderSession;
    use aarbf::render::target::ChunkRenderer;
    let s = scene();
    let d = dist_scene(s);
    let settings = RenderSettings {
        width: 48,
        height: 36,
        seed: 7,
        integrator: Integrator::Ea,
        opacity_threshold: 1.0,
        camera: Some(Camera {
            eye: DVec3::new(1.1, 0.6, 1.2),
            at: DVec3::new(0.4, 0.15, 0.15),
            up: DVec3::Y,
            fovy: 45.0,
        }),
        background: [0.1, 0.2, 0.3],
        ..RenderSettings::default()
    };
    let mut session = RenderSession::new(Box::new(CpuBackend::new()), &s.series);
    session.set_precision(Precision::F64);
    session.show(&s.series, STEP, &s.field, d.cluster).unwrap();
    let chunks = [(0, 2, false), (2, 3, false), (0, 2, true), (5, 1, true)];
    let single: Vec<aarbf::values::Image> = chunks
        .iter()
        .map(|&(first, count, half)| {
            if half {
                session.render_frames_on_half_lattice(&settings, first, count)
            } else {
                session.render_frames(&settings, first, count)
            }
            .unwrap()
        })
        .collect();
    let basis = FrameBasis {
        bounds: s.series.bounds(),
        max_count: s.series.max_count(),
        periodic: false,
        field: &s.field,
        auto: AutoValues::of(&s.series, &s.field).unwrap(),
    };
    for ranks in [1, 3, 4] {
        let got = run_local(ranks, |comm| {
            let local = slice_of(&s.step, comm.rank(), comm.size());
            let mut backend = CpuBackend::new();
            let brick = prepare_brick(comm, &mut backend, &local, &d, None)?;
            let mut rank = RankChunks::new(comm, &mut backend, &brick, &d, basis);
            let images: Vec<aarbf::values::Image> = chunks
                .iter()
                .map(|&(first, count, half)| rank.render_frames(&settings, first, count, half))
                .collect::<Result<_, _>>()
                .map_err(|e| aarbf::dist::DistError::Malformed(e.to_string()))?;
            assert!(rank.elapsed() > std::time::Duration::ZERO, "rank 0's clock");
            Ok(images)
        })
        .unwrap();
        for (r, images) in got.iter().enumerate() {
            assert_eq!(images, &got[0], "rank {r} of {ranks} holds rank 0's images");
        }
        for ((want, have), chunk) in single.iter().zip(&got[0]).zip(&chunks) {
            assert_eq!((have.width, have.height), (want.width, want.height));
            let diff = want
                .pixels
                .iter()
                .zip(&have.pixels)
                .flat_map(|(p, q)| (0..4).map(move |c| (p[c] - q[c]).abs()))
                .fold(0.0f32, f32::max);
            assert!(
                diff <= 1e-5,
                "{ranks} ranks, chunk {chunk:?}: max |difference| {diff:e}"
            );
        }
    }
}

/// `--target-error` and `--time-budget` under `--ranks`: every rank runs the single process's
/// controller on the images rank 0 composites, and the image meets the target against a
/// converged single-process image as one process's does (the estimates are within 2x of the
/// truth: tests/target_error.rs), on a dam break the CLI generated.
#[test]
fn ranks_render_to_a_target_error_and_a_time_budget() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("db");
    let made = common::aarbf_logged(&[
        "generate",
        "dambreak-demo",
        "--count",
        "5003",
        "--steps",
        "1",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(made.status.success(), "{made:?}");
    let render = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec!["render", "--width", "48", "--height", "36", "--data"];
        let data = data.to_str().unwrap();
        args.push(data);
        let out_arg = out.to_str().unwrap().to_owned();
        args.extend(["--out", &out_arg]);
        args.extend(extra);
        let done = common::aarbf_logged(&args);
        let log = String::from_utf8_lossy(&done.stderr).into_owned();
        assert!(done.status.success(), "{extra:?}: {log}");
        (image::open(&out).unwrap().into_rgba32f(), log)
    };
    // Stochastic marching under the default light: noise enough for the target to decide
    // the samples (128 here, as one process chooses).
    let marching = ["--integrator", "marching"];
    let (truth, _) = render("truth.exr", &[&marching[..], &["--spp", "512"]].concat());
    let target = 0.001;
    let (ranked, log) = render(
        "ranks.exr",
        &[
            &marching[..],
            &["--ranks", "3", "--target-error", &target.to_string()],
        ]
        .concat(),
    );
    assert!(
        log.contains("estimated error") && log.contains("met") && !log.contains("NOT met"),
        "{log}"
    );
    assert_eq!(
        log.matches("estimated error").count(),
        1,
        "rank 0 says it: {log}"
    );
    let error = rmse(&ranked, &truth);
    eprintln!("--ranks 3 --target-error {target}: RMSE {error:.2e} against 512 spp");
    assert!(
        error >= 0.1 * target,
        "the target decides the samples: RMSE {error}"
    );
    assert!(
        error <= 2.0 * target,
        "RMSE {error} for a target of {target}"
    );
    let (_, log) = render("budget.exr", &["--ranks", "2", "--time-budget", "0.5"]);
    assert!(log.contains("estimated error"), "{log}");
}

/// `--reference` under `--ranks`: the ranks run the single process's search (samples doubled,
/// then the step halved, until each changes the image by at most the tolerance) on the images
/// rank 0 composites from bricks in f64 on the CPU. It converges where one process's does, to
/// its image within the tolerance, and each finds the other's reference in the cache: the
/// ranks' parts digest to the whole step's particles.
#[test]
fn ranks_converge_the_reference_one_process_does() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("db");
    let made = common::aarbf_logged(&[
        "generate",
        "dambreak-demo",
        "--count",
        "5003",
        "--steps",
        "1",
        "--out",
        data.to_str().unwrap(),
    ]);
    assert!(made.status.success(), "{made:?}");
    let tolerance = 0.004;
    let render = |out: &str, cache: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let done = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(["render", "--width", "40", "--height", "30", "--data"])
            .arg(&data)
            .args([
                "--reference",
                "--reference-tolerance",
                &tolerance.to_string(),
            ])
            .arg("--out")
            .arg(&out)
            .args(extra)
            .env("AARBF_LOG", "info")
            .env("XDG_CACHE_HOME", dir.path().join(cache))
            .output()
            .unwrap();
        let log = String::from_utf8_lossy(&done.stderr).into_owned();
        assert!(done.status.success(), "{extra:?}: {log}");
        (image::open(&out).unwrap().into_rgba32f(), log)
    };
    // What the search settled on: "step size S, N spp; ... (tolerance T, converged)".
    let settled = |log: &str| {
        let line = log
            .lines()
            .find(|l| l.contains("reference of step 0"))
            .unwrap_or_else(|| panic!("no reference line: {log}"));
        assert!(
            line.contains(", converged)") && !line.contains("from the cache"),
            "{line}"
        );
        let from = line.find("step size").unwrap();
        line[from..line.find(" spp").unwrap()].to_owned()
    };
    let (single, log) = render("one.exr", "one", &[]);
    let single_settled = settled(&log);
    for ranks in ["2", "3"] {
        let (ranked, log) = render(&format!("{ranks}.exr"), ranks, &["--ranks", ranks]);
        assert_eq!(
            log.matches("reference of step").count(),
            1,
            "rank 0 says it: {log}"
        );
        assert_eq!(settled(&log), single_settled, "{ranks} ranks: {log}");
        let error = rmse(&ranked, &single);
        eprintln!("--ranks {ranks} --reference: RMSE {error:.2e} against one process's");
        assert!(error <= tolerance, "{ranks} ranks: RMSE {error}");
    }
    // One process's reference serves the ranks, and the ranks' one process.
    for (cache, extra) in [("one", &["--ranks", "3"][..]), ("2", &[][..])] {
        let (_, log) = render(&format!("again-{cache}.exr"), cache, extra);
        assert!(
            log.contains("reference from the cache") && log.contains("from the cache"),
            "{extra:?} with the {cache} cache: {log}"
        );
    }
}

/// RMSE over RGB of two images of one size.
fn rmse(a: &image::Rgba32FImage, b: &image::Rgba32FImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let (sum, n) = a
        .pixels()
        .zip(b.pixels())
        .flat_map(|(p, q)| (0..3).map(move |c| f64::from(p[c] - q[c]).powi(2)))
        .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
    (sum / n as f64).sqrt()
}

/// Under `--ranks`, each rank reads its part of the first step once for the automatic values
/// that come from it (the spacing that sets the radius, the mean overlap that sets the cluster
/// size, Phi_ref), not once for each, and renders it from that read; a later step is read
/// for its render, and the first step's parts are not kept for it.
#[test]
fn ranks_read_the_first_step_once_for_its_automatic_values() {
    let runs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/sph_runs");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        runs.join("gadget_like/snapshot_000.npy"),
        dir.path().join("snapshot_000.npy"),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(["render", "--width", "32", "--height", "24", "--ranks", "3"])
        .arg("--data")
        .arg(dir.path().join("snapshot_000.npy"))
        .arg("--out")
        .arg(dir.path().join("out.exr"))
        .env("AARBF_LOG", "info,aarbf::scene::series=debug")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    // The radius from the spacing, the cluster size and Phi_ref all came from the parts.
    for said in [
        "particles' spacing",
        "cluster size K = ",
        "automatic, from the 3 ranks",
    ] {
        assert!(log.contains(said), "{said}: {log}");
    }
    for rank in 0..3 {
        let reads = log.matches(&format!("rank {rank} of 3 decoded")).count();
        assert_eq!(reads, 1, "rank {rank}: {log}");
    }

    // A series of two steps, the second rendered: the first is read for the automatic values
    // and the second for the render, once each.
    std::fs::copy(
        runs.join("gadget_like/snapshot_000.npy"),
        dir.path().join("snapshot_001.npy"),
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_aarbf"))
        .args(["render", "--width", "32", "--height", "24", "--ranks", "3"])
        .args(["--step", "1", "--data"])
        .arg(dir.path())
        .arg("--out")
        .arg(dir.path().join("second.exr"))
        .env("AARBF_LOG", "info,aarbf::scene::series=debug")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{log}");
    for rank in 0..3 {
        for step in ["snapshot_000", "snapshot_001"] {
            let reads = log
                .lines()
                .filter(|l| l.contains(step) && l.contains(&format!("rank {rank} of 3 decoded")))
                .count();
            assert_eq!(reads, 1, "rank {rank}, {step}: {log}");
        }
    }
}
