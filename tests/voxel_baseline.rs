//! The voxel-grid baseline (`aarbf render --method voxel`): the particles splatted into a grid
//! with the same kernel, ray-marched with the same integrator. Its image must converge to the
//! RBF image as the grid grows (same camera, noise and seed: only the field differs), and the
//! command must render it as a user asks.
//!
//! On every GPU backend the grid and its image equal the CPU backend's, the reference: the CPU
//! scatters in f64 and rounds the sums to f32, and marches the grid with the f64 integrators;
//! ash adds each particle's kernel to a grid buffer reached by device address with f32
//! compare-exchange loops (`voxel_splat.comp`), wgpu splats into a 3D texture with f32 atomic
//! adds (`voxel_particles.comp`, `voxel_splat.wgsl`), and both march it with the shared
//! integrators (`voxel_render.comp`). The limits of one backend's grid are checked in its own
//! file (`ash_rt`, `wgpu_lbvh`).

use std::path::Path;
use std::process::Command;

use aarbf::accel::ClusterSize;
use aarbf::backend::precision::PositionKind;
use aarbf::backend::voxel::{MAX_GRID, VoxelGrid};
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, FrameParams, Image, Integrator, NoiseKind, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common::{self, Gpu, GpuBackend, assert_no_driver_messages, on_every_gpu};

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

on_every_gpu!(
    the_device_grid_equals_the_cpu_grid,
    the_device_voxel_image_equals_the_cpu_voxel_image,
    bad_grids_and_a_march_before_a_grid_are_refused,
    aarbf_render_draws_the_voxel_baseline_on_the_gpu_as_on_the_cpu,
);

/// Uploads `step` of `series` to `backend` as `RenderSession::show` does (no build: the
/// voxel path needs none).
pub(crate) fn upload(
    backend: &mut dyn Backend,
    series: &TimeSeries,
    field: &FieldSettings,
    cluster: u32,
    precision: Precision,
) {
    let range = field
        .attribute
        .as_deref()
        .and_then(|a| series.attribute(a))
        .map(|a| (a.min, a.max));
    backend
        .upload(&StepInput {
            step: &series.step(0).unwrap(),
            field,
            cluster: ClusterSize::new(cluster).unwrap(),
            series_bounds: series.bounds(),
            series_range: range,
            precision,
        })
        .unwrap();
}

/// `count` particles at random (not on a lattice) in a box off the origin, with an attribute
/// `a` and a radius attribute `h` in 0.5..1.5.
pub(crate) fn random_series(count: usize, seed: u64, offset: DVec3) -> TimeSeries {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let extent = DVec3::new(1.0, 0.7, 0.45);
    let positions = (0..count)
        .map(|_| offset + extent * DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let a = (0..count).map(|_| rng.random_range(-2.0..5.0)).collect();
    let h = (0..count).map(|_| rng.random_range(0.5..1.5)).collect();
    TimeSeries::from_steps(vec![Step {
        name: "random".into(),
        positions,
        attributes: vec![
            Attribute {
                name: "a".into(),
                values: a,
            },
            Attribute {
                name: "h".into(),
                values: h,
            },
        ],
    }])
}

/// The largest difference between two grids' sums, per channel, relative to the channel's
/// largest magnitude in `reference` (absolute where that is 0), and whether every sum of
/// `grid` is finite.
pub(crate) fn grid_difference(grid: &VoxelGrid, reference: &VoxelGrid) -> ([f64; 4], bool) {
    assert_eq!(grid.dims(), reference.dims());
    let mut scale = [0.0f64; 4];
    for s in reference.sums() {
        for c in 0..4 {
            scale[c] = scale[c].max(f64::from(s[c]).abs());
        }
    }
    let mut worst = [0.0f64; 4];
    let mut finite = true;
    for (g, r) in grid.sums().iter().zip(reference.sums()) {
        for c in 0..4 {
            finite &= g[c].is_finite();
            let d = (f64::from(g[c]) - f64::from(r[c])).abs();
            worst[c] = worst[c].max(if scale[c] > 0.0 { d / scale[c] } else { d });
        }
    }
    (worst, finite)
}

/// A CPU session (f64) showing `series`, and its frame constants for `settings`.
pub(crate) fn frame_of(
    series: &TimeSeries,
    field: &FieldSettings,
    settings: &RenderSettings,
) -> (RenderSession, FrameParams) {
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), series);
    cpu.set_precision(Precision::F64);
    cpu.show(series, 0, field, ClusterSize::new(4).unwrap())
        .unwrap();
    let frame = cpu.frame_params(settings, 0).unwrap();
    (cpu, frame)
}

fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max)
}

fn the_device_grid_equals_the_cpu_grid(gpu: Gpu) {
    let settings = RenderSettings {
        width: 16,
        height: 16,
        ..RenderSettings::default()
    };
    // Awkward counts, positions off the origin (f32 local coordinates, and double-single ones
    // far off), post- and pre-classified attributes, no attribute (Phi alone), a radius
    // attribute; grids of awkward sizes (rows not a multiple of the copy alignment).
    struct Case {
        name: &'static str,
        count: usize,
        offset: DVec3,
        precision: Precision,
        attribute: Option<&'static str>,
        classification: Classification,
        radius_attribute: Option<&'static str>,
    }
    let post = Case {
        name: "post",
        count: 1237,
        offset: DVec3::new(3.25, -1.5, 0.75),
        precision: Precision::RENDER,
        attribute: Some("a"),
        classification: Classification::Post,
        radius_attribute: None,
    };
    let cases = [
        Case {
            name: "pre, radius attribute",
            count: 611,
            offset: DVec3::new(-7.0, 2.0, 1.0),
            classification: Classification::Pre,
            radius_attribute: Some("h"),
            ..post
        },
        Case {
            name: "density only",
            count: 389,
            offset: DVec3::ZERO,
            attribute: None,
            ..post
        },
        Case {
            name: "double-single far off",
            count: 777,
            offset: DVec3::new(2.0e5 + 1.0 / 3.0, -4.0e4, 1.0e5),
            precision: Precision::DoubleSingle,
            ..post
        },
        post,
    ];
    for (i, case) in cases.into_iter().enumerate() {
        let Case {
            name,
            count,
            offset,
            precision,
            attribute,
            classification,
            radius_attribute,
        } = case;
        let series = random_series(count, 17 + i as u64, offset);
        let mut field = FieldSettings::new(attribute, 0.06);
        field.classification = classification;
        field.radius_attribute = radius_attribute.map(str::to_owned);
        let (mut cpu, frame) = frame_of(&series, &field, &settings);
        let mut device = gpu.backend();
        upload(&mut *device, &series, &field, 4, precision);
        assert_eq!(
            device.representation().unwrap().positions == PositionKind::DoubleSingle,
            precision == Precision::DoubleSingle,
            "{name}"
        );
        for n in [13, 37] {
            cpu.backend_mut().voxelize(&frame, n).unwrap();
            let reference = cpu.backend_mut().voxel_grid().unwrap();
            assert!(
                reference.sums().iter().filter(|s| s[0] > 0.0).count()
                    > reference.sums().len() / 10,
                "{name}, {n}: the particles reach the grid"
            );
            device.voxelize(&frame, n).unwrap();
            if let GpuBackend::Wgpu(wgpu) = &mut device {
                // wgpu keeps the grid's texture: poisoned, a second grid must write every cell.
                wgpu.poison_voxels().unwrap();
                wgpu.voxelize(&frame, n).unwrap();
            }
            let grid = device.voxel_grid().unwrap();
            assert!(
                device.memory().voxel_bytes >= grid.bytes(),
                "{name}: the grid's memory is reported"
            );
            let (worst, finite) = grid_difference(&grid, &reference);
            eprintln!(
                "{gpu} {name}, grid {n} {:?}: largest relative difference per channel {worst:?}",
                grid.dims()
            );
            assert!(
                finite,
                "{name}, {n}: a sum is not finite (a cell kept its poison)"
            );
            // f32 kernels and atomics in another order against f64 sums rounded to f32
            // (measured on lavapipe: at most 3.3e-6 of the channel's largest sum).
            assert!(worst.iter().all(|&w| w < 1e-5), "{name}, {n}: {worst:?}");
        }
    }
    assert_no_driver_messages();
}

fn the_device_voxel_image_equals_the_cpu_voxel_image(gpu: Gpu) {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let step = series.step(7).unwrap();
    let series = TimeSeries::from_steps(vec![(*step).clone()]);
    let mut device = gpu.backend();
    upload(&mut *device, &series, &field, 4, Precision::RENDER);
    for (integrator, noise) in [
        (Integrator::Ea, NoiseKind::Stbn),
        (Integrator::Marching, NoiseKind::White),
    ] {
        let settings = RenderSettings {
            width: 37,
            height: 29,
            integrator,
            noise,
            ..RenderSettings::default()
        };
        let (mut cpu, frame) = frame_of(&series, &field, &settings);
        for n in [24, 50] {
            let cpu_backend = cpu.backend_mut();
            cpu_backend.voxelize(&frame, n).unwrap();
            cpu_backend.reset();
            let mut images = Vec::new();
            for backend in [cpu_backend, &mut *device] {
                backend.voxelize(&frame, n).unwrap();
                backend.reset();
                for f in 0..2 {
                    let mut params = frame.clone();
                    params.frame = f;
                    backend.render_voxels(&params).unwrap();
                }
                images.push(backend.image().unwrap());
            }
            let (reference, image) = (&images[0], &images[1]);
            assert!(
                reference.pixels.iter().any(|p| p[3] > 0.3),
                "the fluid shows"
            );
            assert!(image.pixels.iter().flatten().all(|v| v.is_finite()));
            let error = image.rmse(reference);
            let worst = largest_difference(image, reference);
            eprintln!(
                "{integrator:?}, grid {n}: {gpu} vs cpu voxel image RMSE {error:.3e}, largest difference {worst:.3e}"
            );
            let bound = if integrator == Integrator::Ea {
                1e-4
            } else {
                2e-2
            };
            assert!(error < bound, "{integrator:?}, {n}: RMSE {error}");
        }
    }
    assert_no_driver_messages();
}

fn bad_grids_and_a_march_before_a_grid_are_refused(gpu: Gpu) {
    let series = random_series(100, 3, DVec3::ZERO);
    let field = FieldSettings::new(Some("a"), 0.06);
    let (_, frame) = frame_of(&series, &field, &RenderSettings::default());
    let mut device = gpu.backend();
    upload(&mut *device, &series, &field, 4, Precision::RENDER);
    // Before any grid, the march says so.
    let e = device.render_voxels(&frame).unwrap_err().to_string();
    assert!(e.contains("no voxel grid"), "{e}");
    for n in [0, MAX_GRID + 1] {
        let e = device.voxelize(&frame, n).unwrap_err().to_string();
        assert!(e.contains("1..=1024"), "{e}");
    }
    assert_no_driver_messages();
}

fn aarbf_render_draws_the_voxel_baseline_on_the_gpu_as_on_the_cpu(gpu: Gpu) {
    gpu.require();
    let dir = tempfile::tempdir().unwrap();
    let images = render_voxels_on(dir.path(), &["cpu", &gpu.to_string()]);
    let worst = largest_byte_difference(&images[0], &images[1]);
    let distinct: std::collections::HashSet<&[u8]> = images[0].as_raw().chunks(4).collect();
    assert!(
        distinct.len() > 20,
        "the fluid shows ({} colours)",
        distinct.len()
    );
    eprintln!("aarbf render --method voxel: largest difference to the cpu's {worst} of 255");
    // Measured on lavapipe: 0 (the images differ by far less than one 8-bit step).
    assert!(worst <= 1, "largest difference {worst} of 255");
}

/// The dam break's first step drawn by `aarbf render --method voxel` with a 64-cell grid
/// (radius 0.03: a few cells) at 2 spp on each of `backends`.
fn render_voxels_on(dir: &Path, backends: &[&str]) -> Vec<image::RgbaImage> {
    let data = common::aarbf_ok(&[
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
            common::aarbf_ok(&[
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

fn largest_byte_difference(a: &image::RgbaImage, b: &image::RgbaImage) -> u8 {
    assert_eq!(a.dimensions(), b.dimensions());
    a.as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| x.abs_diff(*y))
        .max()
        .unwrap()
}
