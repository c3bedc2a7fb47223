//! The viewer as a user drives it: headless (egui_kittest on lavapipe) for its panels, its
//! controls and its state file, and once in a real X11 window on a virtual display.
//!
//! The data is written as another program would write it: a time series of CSV files with
//! 17 significant digits, far from the origin, with a different particle count per step.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use aarbf::backend::BackendKind;
use aarbf::scene_file::SceneFile;
use aarbf::scene_file::resolve::{DataArgs, FieldOptions, resolve};
use aarbf::viewer::worker::ShownImage;
use aarbf::viewer::{Shown, ViewOptions, ViewerApp};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use rand::{Rng, SeedableRng};

const COUNTS: [usize; 3] = [1500, 1733, 1201];
/// Frames per converged image: small, so each test renders in seconds on 2 cores.
const SPP: u32 = 2;
const SETTLE: Duration = Duration::from_secs(240);
/// The headless window's size, in points.
const WINDOW: egui::Vec2 = egui::vec2(760.0, 520.0);

/// A three-step series of CSV files: a blob of particles around (1000.25, -20.5, 3.75) that
/// drifts along x, with `temperature` falling off from its centre and a `velocity`.
fn write_series(dir: &Path) -> PathBuf {
    let data = dir.join("cloud");
    std::fs::create_dir_all(&data).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    for (step, &count) in COUNTS.iter().enumerate() {
        let mut f = std::fs::File::create(data.join(format!("cloud_{step}.csv"))).unwrap();
        writeln!(f, "x,y,z,temperature,velocity").unwrap();
        for _ in 0..count {
            let p: [f64; 3] = std::array::from_fn(|_| {
                // A rough Gaussian: the sum of three uniforms.
                (0..3).map(|_| rng.random::<f64>() - 0.5).sum::<f64>() * 0.5
            });
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            let (x, y, z) = (
                1000.25 + p[0] + 0.05 * step as f64,
                -20.5 + p[1] * 0.6,
                3.75 + p[2],
            );
            let temperature = 300.0 + 900.0 * (-4.0 * r * r).exp();
            let velocity = rng.random::<f64>() * 2.0;
            writeln!(
                f,
                "{x:.16e},{y:.16e},{z:.16e},{temperature:.16e},{velocity:.16e}"
            )
            .unwrap();
        }
    }
    data
}

fn open(dir: &Path, backend: BackendKind) -> ViewerApp {
    let data = DataArgs {
        scene: None,
        data: Some(write_series(dir)),
        format: None,
        step: Some(0),
        time: None,
        cache_mib: 256,
        particle_type: None,
        physical: false,
        smoothing: None,
        rescan: false,
        periodic: None,
        no_periodic: false,
    };
    let field = FieldOptions {
        attribute: Some("temperature".into()),
        radius: Some("6%".parse().unwrap()),
        ..FieldOptions::default()
    };
    let mut loaded = resolve(&data, &field).unwrap();
    loaded.scene.render.spp = Some(SPP);
    // The window's view and the scene file's defaults are the user's; keep the march short.
    loaded.scene.render.step_size = Some(0.02);
    let mut app = ViewerApp::new(
        &egui::Context::default(),
        loaded,
        backend,
        ViewOptions { cache_mib: 256 },
    )
    .unwrap();
    app.scene_path = dir.join("view.toml").display().to_string();
    app.screenshot_path = dir.join("view.png").display().to_string();
    app
}

fn harness(app: ViewerApp) -> Harness<'static, ViewerApp> {
    // The window's instance flags: no shader debug information, which Debian's validation
    // layers misread (see `wgpu_lbvh::instance_flags`).
    let mut setup = egui_kittest::wgpu::default_wgpu_setup();
    // Vulkan only: probing for OpenGL through EGL on a machine without a display logs
    // driver errors that would read as failures.
    if let eframe::egui_wgpu::WgpuSetup::CreateNew(new) = &mut setup {
        new.instance_descriptor.flags = aarbf::backend::wgpu_lbvh::instance_flags();
        new.instance_descriptor.backends = wgpu::Backends::VULKAN;
    }
    Harness::builder()
        .with_size(WINDOW)
        .wgpu_setup(setup)
        .build_ui_state(|ui, app: &mut ViewerApp| app.ui(ui), app)
}

/// Steps the window until the worker has converged on the window's current state.
fn settle(h: &mut Harness<'static, ViewerApp>) -> Shown {
    let start = Instant::now();
    loop {
        h.step();
        let shown = h.state().worker().shown();
        if shown.converged && shown.generation == h.state().generation() {
            // One more frame shows the final image.
            h.step();
            return shown;
        }
        assert!(
            start.elapsed() < SETTLE,
            "the viewer did not converge in {SETTLE:?}: {shown:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Whether two shown images are the same, and a short description of both for a failure.
fn compare(
    a: &Option<std::sync::Arc<ShownImage>>,
    b: &Option<std::sync::Arc<ShownImage>>,
) -> (bool, String) {
    let describe = |i: &Option<std::sync::Arc<ShownImage>>| match i {
        Some(i) => format!(
            "{}x{} ({} lit pixels)",
            i.width,
            i.height,
            i.rgba.chunks(4).filter(|p| p[..3] != [0, 0, 0]).count()
        ),
        None => "no image".into(),
    };
    (a == b, format!("{} vs {}", describe(a), describe(b)))
}

fn pixels(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn render_scene(scene: &Path, out: &Path) {
    let status = Command::new(env!("CARGO_BIN_EXE_aarbf"))
        // The viewer draws its legend over the window, not into its image.
        .args([
            "render",
            "--backend",
            "cpu",
            "--force",
            "--no-legend",
            "--scene",
        ])
        .arg(scene)
        .arg("--out")
        .arg(out)
        .status()
        .unwrap();
    assert!(status.success(), "aarbf render --scene {}", scene.display());
}

#[test]
fn the_window_shows_the_render_and_its_panels() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let shown = settle(&mut h);
    assert_eq!(shown.spp, SPP);
    assert!(shown.full_resolution);
    let image = shown.image.as_ref().unwrap();
    // The render fills the central panel, in pixels.
    let view = h.get_by_label("render view").rect();
    assert_eq!(
        (image.width, image.height),
        (view.width().round() as u32, view.height().round() as u32)
    );
    // Not blank: the data covers part of the view with more than one colour.
    let lit = image.rgba.chunks(4).filter(|p| p[..3] != [0, 0, 0]).count();
    let total = (image.width * image.height) as usize;
    assert!(
        lit > total / 50 && lit < total,
        "{lit} of {total} pixels lit"
    );
    // What changes from run to run (timings) is masked: the status bar and the backend's
    // figures, folded away.
    h.get_by_label("Backend").click();
    let shown = settle(&mut h);
    h.mask(egui::Rect::from_min_max(
        egui::pos2(0.0, WINDOW.y - 64.0),
        egui::pos2(WINDOW.x, WINDOW.y),
    ));
    // ... and the data's path, in a new temporary folder each run.
    let path = h.get_by_label_contains("cloud").rect();
    h.mask(egui::Rect::from_x_y_ranges(
        0.0..=WINDOW.x / 2.0,
        path.y_range(),
    ));
    // Small rasterisation differences (a newer lavapipe, another CPU's LLVM) pass: up to 0.5%
    // of the window's pixels may differ. A panel moved, resized or changed differs in far
    // more.
    let max_failed = (WINDOW.x * WINDOW.y * 0.005) as usize;
    h.snapshot_options(
        "viewer_window",
        &egui_kittest::SnapshotOptions::new()
            .threshold(1.0)
            .max_failed_pixels(max_failed),
    );
    assert!(shown.converged);
}

#[test]
fn dragging_a_control_point_changes_the_field_and_restarts_accumulation() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let before = settle(&mut h);
    let generation = h.state().generation();
    assert_eq!(
        h.state().state.field.density_map.0.points(),
        [[0.0, 1.0], [1.0, 1.0]]
    );
    // The density map's first control point sits at the editor's top left (value 1 of 1).
    let editor = h.get_by_label("density map").rect();
    let from = editor.left_top() + egui::vec2(4.0, 4.0);
    let to = egui::pos2(from.x + 0.5 * editor.width(), editor.center().y);
    h.drag_at(from);
    h.step();
    for i in 1..=4 {
        h.hover_at(from + (to - from) * (i as f32 / 4.0));
        h.step();
    }
    h.drop_at(to);
    h.step();
    let points = h.state().state.field.density_map.0.points().to_vec();
    assert_eq!(points.len(), 2);
    assert_eq!(points[1], [1.0, 1.0]);
    assert!(
        (points[0][0] - 0.5).abs() < 0.05 && (points[0][1] - 0.5).abs() < 0.1,
        "{points:?}"
    );
    assert!(h.state().generation() > generation);
    let after = settle(&mut h);
    // A new accumulation: SPP frames of the new field only (an image that kept the old
    // frames would differ from the batch render of the saved state, checked below).
    assert_eq!(after.spp, SPP);
    let (same, what) = compare(&before.image, &after.image);
    assert!(!same, "the image did not change: {what}");
    let scene = dir.path().join("dragged.toml");
    h.state_mut().save_scene(&scene).unwrap();
    let shot = dir.path().join("dragged.png");
    h.state().worker().screenshot(shot.clone());
    let start = Instant::now();
    while !h.state().worker().shown().screenshots.contains(&shot) {
        assert!(start.elapsed() < SETTLE);
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let batch = dir.path().join("batch.png");
    render_scene(&scene, &batch);
    assert_eq!(
        pixels(&shot),
        pixels(&batch),
        "aarbf render --scene of the saved state differs from the viewer's image"
    );
}

#[test]
fn the_step_slider_changes_the_step_and_the_state_file_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    settle(&mut h);
    h.get_by_role_and_label(egui::Role::Slider, "step")
        .set_value_accesskit(2.0);
    h.step();
    assert_eq!(h.state().state.step, 2);
    let shown = settle(&mut h);
    assert_eq!(shown.step, Some(2));
    let histogram = shown.histogram.as_ref().unwrap();
    assert_eq!(
        histogram.counts.iter().map(|&c| c as usize).sum::<usize>(),
        COUNTS[2]
    );

    // Save, then load: the same state, with the automatic values it used now pinned.
    let scene_path = dir.path().join("saved.toml");
    h.state_mut().save_scene(&scene_path).unwrap();
    let used = shown.used.unwrap();
    let mut expected = h.state().state.clone();
    expected.settings.phi_ref = Some(used.phi_ref);
    expected.settings.step_size = Some(used.step_size);
    expected.settings.optical = aarbf::scene::maps::OpticalDensityMap::new(
        expected.settings.optical.map().clone(),
        Some(used.density_scale),
    )
    .unwrap();
    h.state_mut().load_scene(&scene_path).unwrap();
    assert_eq!(h.state().state, expected);
    // Saved again, the file is the same text.
    let settled = settle(&mut h);
    assert_eq!(settled.step, Some(2));
    let again = dir.path().join("again.toml");
    h.state_mut().save_scene(&again).unwrap();
    assert_eq!(
        std::fs::read_to_string(&scene_path).unwrap(),
        std::fs::read_to_string(&again).unwrap()
    );
    // The file is an ordinary scene file, with the step and the data.
    let file = SceneFile::load(&scene_path).unwrap();
    assert_eq!(file.data.step, Some(2));
    assert_eq!(file.data.attribute.as_deref(), Some("temperature"));
}

#[test]
fn a_refused_setting_is_reported_and_the_previous_state_kept() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let good = settle(&mut h);
    let kept = h.state().state.clone();
    // A step so fine that a ray would take more samples than any march may.
    h.state_mut().state.settings.step_size = Some(1e-12);
    let start = Instant::now();
    while h.state().messages().is_empty() {
        assert!(
            start.elapsed() < SETTLE,
            "no message for a refused step size"
        );
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let message = h.state().messages().join("\n");
    assert!(message.contains("step size"), "{message}");
    let back = settle(&mut h);
    // The previous state again (the window's size aside: the message line may move it), and
    // an image of it.
    let mut state = h.state().state.clone();
    state.settings.width = kept.settings.width;
    state.settings.height = kept.settings.height;
    assert_eq!(state, kept);
    assert!(back.converged && back.image.is_some());
    // A scene file that cannot be read is an error naming it; the state stays.
    let missing = dir.path().join("no-such-scene.toml");
    let e = h.state_mut().load_scene(&missing).unwrap_err();
    assert!(e.contains("no-such-scene.toml"), "{e}");
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[field]\nradius = \"-3%\"\n").unwrap();
    let e = h.state_mut().load_scene(&bad).unwrap_err();
    assert!(e.contains("bad.toml") && e.contains("radius"), "{e}");
    assert_eq!(h.state().state.field, kept.field);
    if back.full_size == good.full_size {
        let (same, what) = compare(&back.image, &good.image);
        assert!(same, "the previous state's image is not back: {what}");
    }
}

#[test]
fn the_backend_switches_at_run_time() {
    common::capture_driver_messages();
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let cpu = settle(&mut h);
    assert_eq!(cpu.backend.as_ref().unwrap().0, "cpu");
    h.state_mut().state.backend = BackendKind::Wgpu;
    let gpu = settle(&mut h);
    assert_eq!(
        common::require("the wgpu backend", gpu.backend.clone().ok_or("none")).0,
        "wgpu"
    );
    assert_eq!(gpu.spp, SPP);
    // The same image up to the f32 arithmetic of the GPU path.
    let (a, b) = (cpu.image.unwrap(), gpu.image.unwrap());
    assert_eq!((a.width, a.height), (b.width, b.height));
    let mean_diff = a
        .rgba
        .iter()
        .zip(&b.rgba)
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .sum::<f64>()
        / a.rgba.len() as f64;
    assert!(mean_diff < 1.0, "mean difference {mean_diff} of 255");
    common::assert_no_driver_messages();
}

/// The quality panel's precision reaches the backend: the CPU's f64 reference and its f32
/// path, chosen at run time, give the same image up to f32 rounding.
#[test]
fn the_precision_switches_at_run_time() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    settle(&mut h);
    h.state_mut().state.precision = "f64".into();
    let reference = settle(&mut h);
    assert!(
        reference
            .positions
            .as_deref()
            .is_some_and(|p| p.starts_with("f64")),
        "{:?}",
        reference.positions
    );
    h.state_mut().state.precision = "f32".into();
    let fast = settle(&mut h);
    assert!(
        fast.positions
            .as_deref()
            .is_some_and(|p| p.starts_with("f32")),
        "{:?}",
        fast.positions
    );
    let (a, b) = (reference.image.unwrap(), fast.image.unwrap());
    let worst = a
        .rgba
        .iter()
        .zip(&b.rgba)
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap();
    assert!(worst <= 1, "largest difference {worst} of 255");
}

/// The real thing: `aarbf view` opens an X11 window (on Xvfb) through eframe and wgpu on
/// lavapipe, renders, and writes a screenshot of the whole window.
#[test]
fn the_real_window_opens_renders_and_takes_a_screenshot() {
    let dir = tempfile::tempdir().unwrap();
    let data = write_series(dir.path());
    let shot = dir.path().join("window.png");
    let have_xvfb = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .is_ok_and(|o| o.status.success());
    assert!(
        have_xvfb,
        "xvfb-run is missing: `cargo xtask setup` installs it (Debian package xvfb)"
    );
    let output = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1024x768x24"])
        .arg(env!("CARGO_BIN_EXE_aarbf"))
        .args(["view", "--backend", "cpu", "--attribute", "temperature"])
        .args([
            "--radius", "6%", "--spp", "1", "--window", "800x560", "--data",
        ])
        .arg(&data)
        .arg("--window-screenshot")
        .arg(&shot)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "aarbf view failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let image = pixels(&shot);
    assert_eq!(image.dimensions(), (800, 560));
    let distinct: std::collections::HashSet<[u8; 3]> = image.pixels().map(|p| p.0).collect();
    assert!(
        distinct.len() > 200,
        "the window looks blank: {} colours",
        distinct.len()
    );
    // The render (right of the panel) shows the data: colour beyond the black background.
    let coloured = (400..800)
        .flat_map(|x| (0..500).map(move |y| (x, y)))
        .filter(|&(x, y)| {
            let p = image.get_pixel(x, y).0;
            p.iter().any(|&c| c > 40)
        })
        .count();
    assert!(coloured > 2000, "{coloured} coloured pixels in the view");
}

use crate::common;

/// The splatter baseline from the quality panel: it renders Knoll et al.'s splatter (a
/// different image from the RBFs'), and the scene saved from the viewer renders the same image
/// with `aarbf render --scene` (the scene file carries `splat_k`).
#[test]
fn the_splatter_is_one_tick_away_and_its_scene_reproduces_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let before = settle(&mut h);
    // The quality panel offers it (set through the state, as the precision test does: the
    // panel lies below the window's fold).
    h.get_by_label("renderer");
    h.state_mut().state.settings.splat_k = Some(aarbf::render::SPLAT_K);
    let after = settle(&mut h);
    let (same, what) = compare(&before.image, &after.image);
    assert!(!same, "the splatter's image equals the RBF image: {what}");
    let lit = after
        .image
        .as_ref()
        .unwrap()
        .rgba
        .chunks(4)
        .filter(|p| p[..3] != [0, 0, 0])
        .count();
    assert!(lit > 100, "{lit} pixels lit");
    let scene = dir.path().join("splat.toml");
    h.state_mut().save_scene(&scene).unwrap();
    assert!(
        std::fs::read_to_string(&scene)
            .unwrap()
            .contains("splat_k = 15")
    );
    let shot = dir.path().join("splat.png");
    h.state().worker().screenshot(shot.clone());
    let start = Instant::now();
    while !h.state().worker().shown().screenshots.contains(&shot) {
        assert!(start.elapsed() < SETTLE);
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let batch = dir.path().join("batch.png");
    render_scene(&scene, &batch);
    assert_eq!(
        pixels(&shot),
        pixels(&batch),
        "aarbf render --scene of the splatting state differs from the viewer's image"
    );
}

/// The voxel-grid baseline from the same menu: a different image from the RBFs' (the grid's
/// cells are coarse), and the saved scene (`voxel_grid`) renders the viewer's image pixel for
/// pixel through `aarbf render --scene`.
#[test]
fn the_voxel_grid_is_one_choice_away_and_its_scene_reproduces_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    let before = settle(&mut h);
    h.get_by_label("renderer");
    h.state_mut().state.settings.voxel_grid = Some(24);
    let after = settle(&mut h);
    let (same, what) = compare(&before.image, &after.image);
    assert!(!same, "the voxel grid's image equals the RBF image: {what}");
    let lit = after
        .image
        .as_ref()
        .unwrap()
        .rgba
        .chunks(4)
        .filter(|p| p[..3] != [0, 0, 0])
        .count();
    assert!(lit > 100, "{lit} pixels lit");
    let scene = dir.path().join("voxel.toml");
    h.state_mut().save_scene(&scene).unwrap();
    let text = std::fs::read_to_string(&scene).unwrap();
    assert!(
        text.contains("voxel_grid = 24") && !text.contains("splat_k"),
        "{text}"
    );
    let shot = dir.path().join("voxel.png");
    h.state().worker().screenshot(shot.clone());
    let start = Instant::now();
    while !h.state().worker().shown().screenshots.contains(&shot) {
        assert!(start.elapsed() < SETTLE);
        h.step();
        std::thread::sleep(Duration::from_millis(20));
    }
    let batch = dir.path().join("batch.png");
    render_scene(&scene, &batch);
    assert_eq!(
        pixels(&shot),
        pixels(&batch),
        "aarbf render --scene of the voxel state differs from the viewer's image"
    );
}

#[test]
fn the_robust_ranges_are_one_click_away() {
    use aarbf::io::AttributeSelection;
    use aarbf::scene::index::robust_range;
    use aarbf::scene::{OpenOptions, TimeSeries};
    let dir = tempfile::tempdir().unwrap();
    let mut h = harness(open(dir.path(), BackendKind::Cpu));
    settle(&mut h);
    let series = TimeSeries::open(
        &dir.path().join("cloud"),
        &OpenOptions {
            attributes: AttributeSelection::Only(vec!["temperature".into()]),
            ..OpenOptions::default()
        },
    )
    .unwrap();
    let t = series.attribute("temperature").unwrap();
    h.get_by_label("series 1-99%").click();
    settle(&mut h);
    assert_eq!(h.state().state.field.attribute_range, Some((t.p01, t.p99)));
    assert!(t.p01 > t.min && t.p99 < t.max, "{t:?}");
    h.get_by_label("this step 1-99%").click();
    settle(&mut h);
    let step = series.step(0).unwrap();
    let values = &step.attribute("temperature").unwrap().values;
    assert_eq!(h.state().state.field.attribute_range, robust_range(values));
    h.get_by_label("series").click();
    settle(&mut h);
    assert_eq!(h.state().state.field.attribute_range, None);
}
