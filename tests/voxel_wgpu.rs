//! The voxel-grid baseline on the wgpu backend (`voxel_particles.comp` and `voxel_splat.wgsl`
//! splat the particles into a 3D texture with f32 atomic adds; `voxel_render.comp` marches it
//! with the shared integrators) against the CPU backend's, the reference: the CPU scatters in
//! f64 and rounds the sums to f32, and marches the grid with the f64 integrators. Without a
//! wgpu adapter these tests fail.

use std::sync::Arc;

use aarbf::accel::ClusterSize;
use aarbf::backend::voxel::{MAX_GRID, VoxelGrid};
use aarbf::backend::wgpu_lbvh::{GpuContext, WgpuBackend};
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

fn gpu() -> Arc<GpuContext> {
    common::capture_driver_messages();
    common::require("a wgpu adapter", GpuContext::shared())
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

#[test]
fn the_device_grid_equals_the_cpu_grid() {
    let ctx = gpu();
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
        let mut wgpu = WgpuBackend::with_context(ctx.clone());
        upload(&mut wgpu, &series, &field, 4, precision);
        assert_eq!(
            wgpu.step_data().unwrap().double_single(),
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
            // A first grid makes the texture; poisoned, the second must write every cell.
            wgpu.voxelize(&frame, n).unwrap();
            wgpu.poison_voxels().unwrap();
            wgpu.voxelize(&frame, n).unwrap();
            let grid = wgpu.voxel_grid().unwrap();
            assert!(
                wgpu.memory().voxel_bytes >= grid.bytes(),
                "{name}: the grid's memory is reported"
            );
            let (worst, finite) = grid_difference(&grid, &reference);
            eprintln!(
                "{name}, grid {n} {:?}: largest relative difference per channel {worst:?}",
                grid.dims()
            );
            assert!(finite, "{name}, {n}: a cell kept its poison");
            // f32 kernels and atomics in another order against f64 sums rounded to f32
            // (measured on lavapipe: at most 3.3e-6 of the channel's largest sum).
            assert!(worst.iter().all(|&w| w < 1e-5), "{name}, {n}: {worst:?}");
        }
    }
    assert_no_driver_messages();
}

#[test]
fn a_grid_in_many_slabs_and_chunks_equals_one_in_one() {
    // Bindings of 8 KiB: the particles split over parts, the slab buffer two layers, the
    // first pass 256 particles at a time.
    let series = random_series(1237, 5, DVec3::new(0.5, 0.25, -1.0));
    let field = FieldSettings::new(Some("a"), 0.06);
    let settings = RenderSettings {
        width: 16,
        height: 16,
        ..RenderSettings::default()
    };
    let (mut cpu, frame) = frame_of(&series, &field, &settings);
    cpu.backend_mut().voxelize(&frame, 13).unwrap();
    let reference = cpu.backend_mut().voxel_grid().unwrap();
    let mut small = WgpuBackend::with_max_binding(gpu(), 8192);
    upload(&mut small, &series, &field, 4, Precision::RENDER);
    small.voxelize(&frame, 13).unwrap();
    small.poison_voxels().unwrap();
    small.voxelize(&frame, 13).unwrap();
    let (worst, finite) = grid_difference(&small.voxel_grid().unwrap(), &reference);
    eprintln!("8 KiB bindings: largest relative difference per channel {worst:?}");
    assert!(finite);
    assert!(worst.iter().all(|&w| w < 1e-5), "{worst:?}");
    // A layer larger than a binding is refused, naming the limit.
    let e = small.voxelize(&frame, 64).unwrap_err().to_string();
    assert!(e.contains("slab buffer") && e.contains("8192"), "{e}");
    assert_no_driver_messages();
}

fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max)
}

#[test]
fn the_device_voxel_image_equals_the_cpu_voxel_image() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let step = series.step(7).unwrap();
    let series = TimeSeries::from_steps(vec![(*step).clone()]);
    let mut wgpu = WgpuBackend::with_context(gpu());
    upload(&mut wgpu, &series, &field, 4, Precision::RENDER);
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
            for backend in [cpu_backend, &mut wgpu as &mut dyn Backend] {
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
                "{integrator:?}, grid {n}: wgpu vs cpu voxel image RMSE {error:.3e}, largest difference {worst:.3e}"
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
fn grids_beyond_the_limits_are_refused_with_the_limit_named() {
    let series = random_series(100, 3, DVec3::ZERO);
    let field = FieldSettings::new(Some("a"), 0.06);
    let settings = RenderSettings::default();
    let (_, frame) = frame_of(&series, &field, &settings);
    let mut wgpu = WgpuBackend::with_context(gpu());
    upload(&mut wgpu, &series, &field, 4, Precision::RENDER);
    let e = wgpu.voxelize(&frame, MAX_GRID + 1).unwrap_err().to_string();
    assert!(e.contains("1..=1024"), "{e}");
    // Before any grid, the march and the read-back say so.
    let e = wgpu.render_voxels(&frame).unwrap_err().to_string();
    assert!(e.contains("no voxel grid"), "{e}");
    // A device whose 3D textures are at most 32 texels a side refuses a 64-cell grid.
    let limits = wgpu::Limits {
        max_texture_dimension_3d: 32,
        ..wgpu::Limits::default()
    };
    let small = Arc::new(common::require(
        "a wgpu adapter",
        GpuContext::with_limits(limits),
    ));
    let mut wgpu = WgpuBackend::with_context(small);
    upload(&mut wgpu, &series, &field, 4, Precision::RENDER);
    let e = wgpu.voxelize(&frame, 64).unwrap_err().to_string();
    assert!(
        e.contains("max_texture_dimension_3d") && e.contains("32"),
        "{e}"
    );
    wgpu.voxelize(&frame, 32).unwrap();
    assert_no_driver_messages();
}

#[test]
fn aarbf_render_draws_the_voxel_baseline_on_wgpu_as_on_the_cpu() {
    gpu();
    let dir = tempfile::tempdir().unwrap();
    let images = crate::voxel_cli::render_voxels_on(dir.path(), &["cpu", "wgpu"]);
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
