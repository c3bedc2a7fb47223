//! The wgpu backend through a RenderSession as a user drives it: frames following transfer
//! function changes without a new upload (each as the CPU backend's), sessions that refit,
//! restart and reproduce, and the device's timestamps. Shares one wgpu device (the
//! process-wide `GpuContext`); without an adapter it fails. Its images against the CPU
//! backend's, as every GPU backend's, are checked in `gpu_backends`.

use aarbf::accel::ClusterSize;
use aarbf::backend::wgpu_lbvh::WgpuBackend;
use aarbf::backend::{self, BackendKind};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{OpticalDensityMap, PiecewiseLinear};
use aarbf::values::{Integrator, NoiseKind};

use crate::common::{assert_no_driver_messages, wgpu_context as gpu};
use crate::gpu_backends::{assert_images_close, close_view, dambreak};

fn field(series: &TimeSeries) -> FieldSettings {
    FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal())
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

/// A transfer-function change between frames of one uploaded step reaches the device (the
/// backend writes its map tables only when their bytes change), and changing back gives the
/// first image again bit for bit: each frame matches the CPU backend's.
#[test]
fn frames_follow_transfer_function_changes_without_a_new_upload() {
    gpu();
    let series = dambreak();
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
        assert_images_close(
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
    let series = dambreak();
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
    let series = dambreak();
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
