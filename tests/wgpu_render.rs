//! The wgpu backend's images against the CPU backend's at equal settings, samples and seed,
//! through a RenderSession as a user drives it. Shares one wgpu device (the process-wide
//! `GpuContext`); without an adapter it fails.
//!
//! Tolerances: the two backends run the same integrator code (GLSL twin of the Rust), f32 on
//! the GPU against f64 on the CPU, so emission–absorption and stochastic marching agree pixel
//! for pixel up to rounding, except where rounding flips a free-flight decision (a few pixels).
//! Delta tracking on the CPU skips empty space (the same distribution, different random
//! numbers per pixel), so it is compared after a 1.5-pixel blur at more samples. Each case
//! states its RMSE (linear RGB) and mean FLIP bounds; on failure the GPU image and the FLIP
//! error map are written to the target directory as `*-actual.png` / `*-difference.png`.

use aarbf::accel::ClusterSize;
use aarbf::backend::wgpu_lbvh::{GpuContext, WgpuBackend};
use aarbf::backend::{self, BackendKind};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{OpticalDensityMap, PiecewiseLinear};
use aarbf::scene::synth::Generator;
use aarbf::values::Image;
use aarbf::values::{Integrator, NoiseKind};

use crate::common;
use common::assert_no_driver_messages;

fn gpu() -> std::sync::Arc<GpuContext> {
    common::capture_driver_messages();
    common::require("a wgpu adapter", GpuContext::shared())
}

fn demo() -> TimeSeries {
    TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1))
}

fn field(series: &TimeSeries) -> FieldSettings {
    FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal())
}

fn close_view(series: &TimeSeries) -> aarbf::scene::Camera {
    let b = series.bounds();
    aarbf::scene::Camera {
        eye: glam::DVec3::new(0.9, 0.45, 1.1),
        at: glam::DVec3::new(0.55, 0.12, 0.5 * b.max.z),
        up: glam::DVec3::Y,
        fovy: 35.0,
    }
}

fn srgb8(image: &Image) -> Vec<u8> {
    image.to_srgb8().into_raw()
}

/// Mean FLIP between two images (sRGB 8-bit, default viewing conditions).
fn flip(reference: &Image, test: &Image) -> (f32, nv_flip::FlipImageFloat) {
    let r = nv_flip::FlipImageRgb8::with_data(reference.width, reference.height, &srgb8(reference));
    let t = nv_flip::FlipImageRgb8::with_data(test.width, test.height, &srgb8(test));
    let err = nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    let mean = nv_flip::FlipPool::from_image(&err).mean();
    (mean, err)
}

fn compare(name: &str, cpu: &Image, gpu: &Image, max_rmse: f64, max_flip: f32) {
    assert!(
        gpu.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())),
        "{name}: finite"
    );
    let rmse = gpu.rmse(cpu);
    let (mean_flip, err) = flip(cpu, gpu);
    eprintln!(
        "{name}: RMSE {rmse:.5} (bound {max_rmse}), mean FLIP {mean_flip:.5} (bound {max_flip})"
    );
    if rmse > max_rmse || mean_flip > max_flip {
        let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
        let _ = gpu.to_srgb8().save(dir.join(format!("{name}-actual.png")));
        let _ = cpu
            .to_srgb8()
            .save(dir.join(format!("{name}-expected.png")));
        let diff = err.apply_color_lut(&nv_flip::magma_lut());
        let _ = image::RgbImage::from_raw(diff.width(), diff.height(), diff.to_vec())
            .map(|d| d.save(dir.join(format!("{name}-difference.png"))));
        panic!(
            "{name}: RMSE {rmse} (bound {max_rmse}), mean FLIP {mean_flip} (bound {max_flip}); \
             images in {}",
            dir.display()
        );
    }
}

fn session(kind: BackendKind, series: &TimeSeries, field: &FieldSettings) -> RenderSession {
    let backend = match kind {
        BackendKind::Wgpu => Box::new(WgpuBackend::new().unwrap()) as Box<dyn backend::Backend>,
        k => backend::create(k).unwrap(),
    };
    let mut s = RenderSession::new(backend, series);
    s.show(series, 5, field, ClusterSize::new(4).unwrap())
        .unwrap();
    s
}

#[test]
fn images_match_the_cpu_backend_at_equal_samples_and_seed() {
    gpu();
    let series = demo();
    let f = field(&series);
    let mut cpu = session(BackendKind::Cpu, &series, &f);
    let mut wgpu = session(BackendKind::Wgpu, &series, &f);
    let camera = Some(close_view(&series));
    // (integrator, noise, spp, blur, RMSE bound, FLIP bound)
    let cases = [
        // Measured on lavapipe: RMSE < 5e-6 and FLIP < 1e-4 for EA, marching and the SS
        // reference; delta tracking 0.0026 / 0.033 after the blur.
        (Integrator::Ea, NoiseKind::Stbn, 2, 0.0, 1e-4, 1e-3),
        (Integrator::Ea, NoiseKind::White, 2, 0.0, 1e-4, 1e-3),
        (Integrator::Marching, NoiseKind::Stbn, 4, 0.0, 5e-3, 0.01),
        (Integrator::SsReference, NoiseKind::Stbn, 1, 0.0, 1e-4, 1e-3),
        (Integrator::Delta, NoiseKind::Stbn, 32, 1.5, 0.008, 0.06),
    ];
    for (integrator, noise, spp, blur, max_rmse, max_flip) in cases {
        let settings = RenderSettings {
            width: 64,
            height: 48,
            integrator,
            noise,
            seed: 3,
            camera,
            ..RenderSettings::default()
        };
        let a = cpu.render(&settings, spp).unwrap();
        let b = wgpu.render(&settings, spp).unwrap();
        let (a, b) = if blur > 0.0 {
            (a.blurred(blur), b.blurred(blur))
        } else {
            (a, b)
        };
        compare(
            &format!("wgpu-{integrator:?}-{noise:?}-{spp}spp").to_lowercase(),
            &a,
            &b,
            max_rmse,
            max_flip,
        );
    }
    // The half-resolution lattice a targeted render measures its noise on (odd sizes: the
    // lattice keeps the last row and column): the same rays as on the CPU.
    let settings = RenderSettings {
        width: 63,
        height: 47,
        seed: 3,
        camera,
        ..RenderSettings::default()
    };
    let a = cpu.render_frames_on_half_lattice(&settings, 0, 2).unwrap();
    let b = wgpu.render_frames_on_half_lattice(&settings, 0, 2).unwrap();
    assert_eq!((b.width, b.height), (32, 24));
    compare("wgpu-lattice", &a, &b, 1e-4, 1e-3);
    assert_no_driver_messages();
}

/// A transfer-function change between frames of one uploaded step reaches the device (the
/// backend writes its map tables only when their bytes change), and changing back gives the
/// first image again bit for bit: each frame matches the CPU backend's.
#[test]
fn frames_follow_transfer_function_changes_without_a_new_upload() {
    gpu();
    let series = demo();
    let f = field(&series);
    let mut cpu = session(BackendKind::Cpu, &series, &f);
    let mut wgpu = session(BackendKind::Wgpu, &series, &f);
    let settings_with = |optical: &str, scale: f64| RenderSettings {
        width: 48,
        height: 32,
        integrator: Integrator::Ea,
        noise: NoiseKind::White,
        seed: 5,
        camera: Some(close_view(&series)),
        optical: OpticalDensityMap::new(optical.parse::<PiecewiseLinear>().unwrap(), Some(scale))
            .unwrap(),
        ..RenderSettings::default()
    };
    let ramp = settings_with("0:0,1:1", 2.0);
    let step = settings_with("0:0.4,0.5:0,1:0.6", 6.0);
    let mut images = Vec::new();
    for (name, settings) in [("ramp", &ramp), ("step", &step), ("ramp again", &ramp)] {
        let a = cpu.render(settings, 1).unwrap();
        let b = wgpu.render(settings, 1).unwrap();
        compare(
            &format!("wgpu-transfer-{name}").replace(' ', "-"),
            &a,
            &b,
            1e-4,
            1e-3,
        );
        images.push(b);
    }
    assert_ne!(
        images[0], images[1],
        "the transfer function changed the image"
    );
    assert_eq!(images[0], images[2], "back to the first transfer function");
    assert_no_driver_messages();
}

#[test]
fn sessions_refit_restart_and_reproduce_on_wgpu() {
    gpu();
    let series = demo();
    let mut f = field(&series);
    let settings = RenderSettings {
        width: 32,
        height: 32,
        integrator: Integrator::Ea,
        noise: NoiseKind::White,
        ..RenderSettings::default()
    };
    let mut s = session(BackendKind::Wgpu, &series, &f);
    let base = s.render(&settings, 2).unwrap();
    assert_eq!(s.frames(), 2);
    assert_eq!(
        base,
        s.render(&settings, 0).unwrap(),
        "no new frames, same image"
    );
    // The same seed and settings give the same image bit for bit.
    let mut again = session(BackendKind::Wgpu, &series, &f);
    assert_eq!(base, again.render(&settings, 2).unwrap());
    // A radius change refits (timed) and restarts accumulation.
    f.radius *= 1.5;
    s.show(&series, 5, &f, ClusterSize::new(4).unwrap())
        .unwrap();
    let wider = s.render(&settings, 1).unwrap();
    assert_eq!(s.frames(), 1);
    assert!(s.backend().timings().refit > std::time::Duration::ZERO);
    assert_ne!(base, wider);
    // Pre-classification: a new upload.
    f.classification = Classification::Pre;
    s.show(&series, 5, &f, ClusterSize::new(4).unwrap())
        .unwrap();
    let pre = s.render(&settings, 1).unwrap();
    assert_ne!(pre, wider);
    // Another step and cluster size: upload and build into the same buffers.
    s.show(&series, 6, &f, ClusterSize::new(16).unwrap())
        .unwrap();
    let other = s.render(&settings, 1).unwrap();
    assert_ne!(other, pre);
    let m = s.backend().memory();
    assert!(m.particle_bytes > 0 && m.structure_bytes > 0 && m.image_bytes == 32 * 32 * 16);
    // The step's preparation keeps at least its staging and raw copy of the particles.
    assert!(m.preparation_bytes >= 2 * m.particle_bytes, "{m:?}");
    assert_no_driver_messages();
}

#[test]
fn gpu_work_is_timed_by_device_timestamps_where_the_adapter_writes_them() {
    let ctx = gpu();
    let features = ctx.adapter.features();
    let has = features.contains(
        wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
    );
    let series = demo();
    let mut s = session(BackendKind::Wgpu, &series, &field(&series));
    let caps = s.backend().capabilities().clone();
    assert_eq!(
        caps.frame_timer,
        if has {
            backend::FrameTimer::DeviceTimestamps
        } else {
            backend::FrameTimer::SubmitToCompletion
        },
        "{}",
        caps.device
    );
    let settings = RenderSettings {
        width: 48,
        height: 40,
        ..RenderSettings::default()
    };
    for _ in 0..3 {
        let started = std::time::Instant::now();
        s.accumulate(&settings, 1).unwrap();
        let wall = started.elapsed();
        let frame = s.backend().timings().frame;
        // The device's time lies within the host's around the call (which adds the uniforms'
        // writes, the submission and the readback of the timestamps).
        assert!(
            frame > std::time::Duration::ZERO && frame <= wall,
            "frame {frame:?}, wall clock {wall:?}"
        );
    }
    // The tree's build and refit, and queries, on the same clock.
    let within = |what: &str, took: std::time::Duration, wall: std::time::Duration| {
        assert!(
            took > std::time::Duration::ZERO && took <= wall,
            "{what} {took:?}, wall clock {wall:?}"
        );
    };
    let started = std::time::Instant::now();
    s.backend_mut().build().unwrap();
    within("build", s.backend().timings().build, started.elapsed());
    let wider = FieldSettings::new(Some("velocity"), 0.02 * series.bounds().diagonal());
    let started = std::time::Instant::now();
    s.backend_mut().refit(&wider).unwrap();
    within("refit", s.backend().timings().refit, started.elapsed());
    let b = series.bounds();
    let points: Vec<glam::DVec3> = (0..1000)
        .map(|i| b.min + (b.max - b.min) * (i as f64 / 1000.0))
        .collect();
    let started = std::time::Instant::now();
    s.backend_mut().query(&points).unwrap();
    within("query", s.backend().timings().query, started.elapsed());
    assert_no_driver_messages();
}
