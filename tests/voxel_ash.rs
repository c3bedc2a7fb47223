//! The voxel-grid baseline on the ash backend (`voxel_splat.comp` adds each particle's kernel
//! to a grid buffer reached by device address with f32 compare-exchange loops;
//! `voxel_render.comp` marches it with the shared integrators) against the CPU backend's, the
//! reference: the CPU scatters in f64 and rounds the sums to f32, and marches the grid with
//! the f64 integrators. Without a Vulkan device with ray-tracing pipelines these tests fail.

use aarbf::accel::ClusterSize;
use aarbf::backend::ash_rt::AshBackend;
use aarbf::backend::voxel::{MAX_GRID, VoxelGrid};
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, FrameParams, Image, Integrator, NoiseKind, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common;
use common::assert_no_driver_messages;

fn ash() -> AshBackend {
    common::capture_driver_messages();
    common::require(
        "a Vulkan device with ray-tracing pipelines",
        AshBackend::new(),
    )
}

/// Uploads `step` of `series` to `backend` as `RenderSession::show` does (no build: the
/// voxel path needs none).
fn upload(
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
fn random_series(count: usize, seed: u64, offset: DVec3) -> TimeSeries {
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
fn grid_difference(grid: &VoxelGrid, reference: &VoxelGrid) -> ([f64; 4], bool) {
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

fn frame_of(
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

#[test]
fn the_device_grid_equals_the_cpu_grid() {
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
        let mut gpu = ash();
        upload(&mut gpu, &series, &field, 4, precision);
        for n in [13, 37] {
            cpu.backend_mut().voxelize(&frame, n).unwrap();
            let reference = cpu.backend_mut().voxel_grid().unwrap();
            assert!(
                reference.sums().iter().filter(|s| s[0] > 0.0).count()
                    > reference.sums().len() / 10,
                "{name}, {n}: the particles reach the grid"
            );
            gpu.voxelize(&frame, n).unwrap();
            let grid = gpu.voxel_grid().unwrap();
            assert!(
                gpu.memory().voxel_bytes >= grid.bytes(),
                "{name}: the grid's memory is reported"
            );
            let (worst, finite) = grid_difference(&grid, &reference);
            eprintln!(
                "{name}, grid {n} {:?}: largest relative difference per channel {worst:?}",
                grid.dims()
            );
            assert!(finite, "{name}, {n}: a sum is not finite");
            // f32 kernels and atomics in another order against f64 sums rounded to f32
            // (measured on lavapipe: at most 3.3e-6 of the channel's largest sum).
            assert!(worst.iter().all(|&w| w < 1e-5), "{name}, {n}: {worst:?}");
        }
    }
    assert_no_driver_messages();
}

#[test]
fn the_device_voxel_image_equals_the_cpu_voxel_image() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let step = series.step(7).unwrap();
    let series = TimeSeries::from_steps(vec![(*step).clone()]);
    let mut gpu = ash();
    upload(&mut gpu, &series, &field, 4, Precision::RENDER);
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
            for backend in [cpu_backend, &mut gpu as &mut dyn Backend] {
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
                "{integrator:?}, grid {n}: ash vs cpu voxel image RMSE {error:.3e}, largest difference {worst:.3e}"
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

#[test]
fn bad_grids_and_a_march_before_a_grid_are_refused() {
    let series = random_series(100, 3, DVec3::ZERO);
    let field = FieldSettings::new(Some("a"), 0.06);
    let (_, frame) = frame_of(&series, &field, &RenderSettings::default());
    let mut gpu = ash();
    upload(&mut gpu, &series, &field, 4, Precision::RENDER);
    let e = gpu.render_voxels(&frame).unwrap_err().to_string();
    assert!(e.contains("no voxel grid"), "{e}");
    for n in [0, MAX_GRID + 1] {
        let e = gpu.voxelize(&frame, n).unwrap_err().to_string();
        assert!(e.contains("1..=1024"), "{e}");
    }
    // A cube's 1024³ grid (16 GiB, 2^32 words) is more than the device allocates (lavapipe:
    // 2 GiB) or the kernels index: refused before anything is allocated.
    let corners: Vec<DVec3> = (0..8)
        .map(|i| DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64))
        .collect();
    let cube = TimeSeries::from_steps(vec![Step {
        name: "cube".into(),
        attributes: vec![Attribute {
            name: "a".into(),
            values: (0..8).map(f64::from).collect(),
        }],
        positions: corners,
    }]);
    let (_, frame) = frame_of(&cube, &field, &RenderSettings::default());
    let mut gpu = ash();
    upload(&mut gpu, &cube, &field, 4, Precision::RENDER);
    let e = gpu.voxelize(&frame, MAX_GRID).unwrap_err().to_string();
    assert!(
        e.contains("maxMemoryAllocationSize") || e.contains("2^32 words"),
        "{e}"
    );
    gpu.voxelize(&frame, 16).unwrap();
    assert_eq!(gpu.voxel_grid().unwrap().dims(), [16, 16, 16]);
    assert_no_driver_messages();
}

#[test]
fn aarbf_render_draws_the_voxel_baseline_on_ash_as_on_the_cpu() {
    ash();
    let dir = tempfile::tempdir().unwrap();
    let images = crate::voxel_cli::render_voxels_on(dir.path(), &["cpu", "ash"]);
    let worst = crate::voxel_cli::largest_byte_difference(&images[0], &images[1]);
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
