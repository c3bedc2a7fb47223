//! Knoll et al.'s splatter (`aarbf render --method splat`), the paper's other Table 3
//! baseline: particles that do not overlap splat to exactly what the RBF renderer integrates
//! (their optical depth along the ray is the chord integral, for an optical map linear in
//! Phi); where particles overlap, ordering and per-particle colour make it differ, and a
//! buffer too small for a slab's hits loses them, which its image error shows.
//!
//! On every GPU backend, and on each of its traversals (ash's RT pipeline, `splat.rgen`: a ray
//! per slab, the any-hit shader filling the slab's buffer; the LBVH kernels of ash and wgpu,
//! `lbvh_splat.comp`), the splatter draws what the CPU's draws (`backend::cpu::splat`, over the
//! f64 reference's hits): equal within f32 where no buffer overflows (which hits overflow
//! depends on the traversal's order, which differs between them), different once k is small
//! enough to lose hits, every pixel written, no validation message, and a clear error for a
//! buffer a payload cannot hold. The GPU backends are driven directly (uploaded and built as
//! `RenderSession::show` does), with the frame constants of a CPU session over the same series,
//! field and step. wgpu's poisoned accumulation and split bindings are checked in its own file
//! (`wgpu_lbvh`).

use std::process::Command;

use aarbf::accel::ClusterSize;
use aarbf::backend::precision::PositionKind;
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::shader_constants::SPLAT_K_MAX;
use aarbf::values::{Attribute, FrameParams, Image, Integrator, NoiseKind, Step};
use glam::DVec3;

use crate::common::{Gpu, assert_no_driver_messages, on_every_gpu};

fn splat(session: &mut RenderSession, settings: &RenderSettings, k: usize) -> (Image, f64) {
    let frame = session.frame_params(settings, 0).unwrap();
    let backend = session.backend_mut();
    backend.reset();
    let counts = backend
        .render_splat(&frame, k)
        .unwrap()
        .expect("the cpu counts hits");
    (backend.image().unwrap(), counts.lost_fraction())
}

#[test]
fn particles_apart_splat_to_the_rbf_image() {
    // Seven particles far apart, in double precision off the origin, attributes 0..6 in the
    // data's units: no two overlap, so each pixel sees one particle at most.
    let offset = DVec3::new(1.0e4 + 0.123_456_789_012_345_6, -2.5e3, 7.0 / 3.0);
    let positions: Vec<DVec3> = (0..7)
        .map(|i| offset + DVec3::new(0.3 * i as f64, 0.07 * (i % 3) as f64, 0.05 * i as f64))
        .collect();
    let step = Step {
        name: "apart".into(),
        positions,
        attributes: vec![Attribute {
            name: "a".into(),
            values: vec![3.0, -1.5, 0.25, 7.0, 2.0, 5.5, 0.0],
        }],
    };
    let series = TimeSeries::from_steps(vec![step]);
    let radius = 0.1;
    let field = FieldSettings::new(Some("a"), radius);
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session.set_precision(Precision::F64);
    session
        .show(&series, 0, &field, ClusterSize::new(1).unwrap())
        .unwrap();
    let base = RenderSettings {
        width: 40,
        height: 40,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        // Phi stays in the optical map's linear range (a lone particle's Phi is at most 1).
        phi_ref: Some(2.0),
        ..RenderSettings::default()
    };
    // The RBF image marched finely enough that its step's error is below the tolerance.
    let rbf = session
        .render(
            &RenderSettings {
                step_size: Some(radius / 100.0),
                ..base.clone()
            },
            8,
        )
        .unwrap();
    assert!(
        rbf.pixels.iter().filter(|p| p[3] > 0.05).count() > 20,
        "the particles are visible"
    );
    let (splatted, lost) = splat(&mut session, &base, 15);
    assert_eq!(lost, 0.0);
    let error = splatted.rmse(&rbf);
    eprintln!("particles apart: RMSE splat vs RBF {error:.3e}");
    assert!(error < 1e-5, "RMSE splat vs RBF {error}");
    let worst = splatted
        .pixels
        .iter()
        .zip(&rbf.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "largest pixel difference {worst}");
}

#[test]
fn overlapping_particles_differ_and_a_small_buffer_loses_hits() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session.set_precision(Precision::F64);
    session
        .show(&series, 7, &field, ClusterSize::new(1).unwrap())
        .unwrap();
    let settings = RenderSettings {
        width: 48,
        height: 48,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    let reference = session.render(&settings, 64).unwrap();
    assert!(reference.pixels.iter().any(|p| p[3] > 0.3));
    let (all, lost_none) = splat(&mut session, &settings, 4096);
    let (fifteen, lost_fifteen) = splat(&mut session, &settings, 15);
    let (one, lost_one) = splat(&mut session, &settings, 1);
    assert_eq!(lost_none, 0.0);
    assert!(
        lost_one > 0.05 && lost_one > lost_fifteen,
        "lost: k = 1 {lost_one}, k = 15 {lost_fifteen}"
    );
    let errors = [all, fifteen, one].map(|i| i.rmse(&reference));
    eprintln!(
        "dam break: lost k = 1 {lost_one:.3}, k = 15 {lost_fifteen:.3}; RMSE k = 4096, 15, 1: {errors:?}"
    );
    // The splatter is close to the RBF image but not equal to it (overlapping particles are
    // composited one after another), and losing hits moves it further away.
    assert!(errors[0] > 1e-4 && errors[0] < 0.05, "{errors:?}");
    assert!(errors[2] > 1.5 * errors[0], "{errors:?}");
    assert!(errors[1] <= errors[2], "{errors:?}");
}

#[test]
fn aarbf_render_splats_text_data_and_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A lattice far from the origin, written with 17 significant digits as NumPy's savetxt
    // ("%.17g") writes it.
    let mut csv = String::from("x,y,z,temperature\n");
    for i in 0..6 {
        for j in 0..5 {
            for k in 0..3 {
                let p = [
                    -3.0e5 + 0.1 * i as f64 + 1.0 / 3.0,
                    1.0e5 + 0.1 * j as f64,
                    0.1 * k as f64 + 2.0 / 7.0,
                ];
                csv += &format!(
                    "{:.17e},{:.17e},{:.17e},{:.17e}\n",
                    p[0],
                    p[1],
                    p[2],
                    300.0 + (i * j + k) as f64 / 7.0
                );
            }
        }
    }
    let data = d.join("lattice.csv");
    std::fs::write(&data, csv).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(args)
            .env("AARBF_LOG", "info")
            .output()
            .unwrap()
    };
    let out = d.join("splat.png");
    let common = [
        "render",
        "--data",
        data.to_str().unwrap(),
        "--attribute",
        "temperature",
        "--radius",
        "0.12",
        "--width",
        "32",
        "--height",
        "24",
        "--method",
        "splat",
        "--out",
        out.to_str().unwrap(),
    ];
    let ok = run(&[&common[..], &["--backend", "cpu", "--splat-k", "2"]].concat());
    let stderr = String::from_utf8_lossy(&ok.stderr);
    assert!(ok.status.success(), "{stderr}");
    assert!(
        stderr.contains("lost to full 2-entry slab buffers"),
        "{stderr}"
    );
    let image = image::open(&out).unwrap().to_rgb8();
    assert_eq!((image.width(), image.height()), (32, 24));
    assert!(
        image.pixels().any(|p| p.0 != image.get_pixel(0, 0).0),
        "the lattice is drawn"
    );
    for (extra, says) in [
        (
            &["--backend", "cpu", "--integrator", "marching", "--force"][..],
            "--integrator ea",
        ),
        (
            &["--backend", "cpu", "--splat-k", "0", "--force"][..],
            "--splat-k must be at least 1",
        ),
        (
            &["--backend", "wgpu", "--splat-k", "65", "--force"][..],
            "the GPU splatter's slab buffer holds 1..=64 hits",
        ),
    ] {
        let bad = run(&[&common[..], extra].concat());
        let stderr = String::from_utf8_lossy(&bad.stderr);
        assert!(
            !bad.status.success() && stderr.contains(says),
            "{extra:?}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

on_every_gpu!(
    particles_apart_splat_as_on_the_cpu,
    the_dam_break_splats_as_on_the_cpu_until_a_small_buffer_loses_hits,
    a_slab_buffer_outside_1_to_splat_k_max_is_an_error,
);

/// A CPU session (f64) showing `step` of `series`, the reference.
pub(crate) fn cpu_session(
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: u32,
) -> RenderSession {
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), series);
    cpu.set_precision(Precision::F64);
    cpu.show(series, step, field, ClusterSize::new(cluster).unwrap())
        .unwrap();
    cpu
}

/// Uploads and builds `step` of `series` on `backend` as `RenderSession::show` does, with
/// positions as `precision` says.
pub(crate) fn show(
    backend: &mut dyn Backend,
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: u32,
    precision: Precision,
) {
    backend.reserve(series.max_count());
    let range = field
        .attribute
        .as_deref()
        .and_then(|a| series.attribute(a))
        .map(|a| (a.min, a.max));
    backend
        .upload(&StepInput {
            step: &series.step(step).unwrap(),
            field,
            cluster: ClusterSize::new(cluster).unwrap(),
            series_bounds: series.bounds(),
            series_range: range,
            precision,
        })
        .unwrap();
    backend.build().unwrap();
}

/// One splatter frame of `backend` (its accumulation restarted), as an image.
pub(crate) fn gpu_splat(backend: &mut dyn Backend, frame: &FrameParams, k: usize) -> Image {
    backend.reset();
    backend.render_splat(frame, k).unwrap();
    backend.image().unwrap()
}

pub(crate) fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max)
}

pub(crate) fn all_finite(image: &Image) -> bool {
    image.pixels.iter().flatten().all(|v| v.is_finite())
}

pub(crate) fn dam_break() -> (TimeSeries, FieldSettings) {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    (series, field)
}

fn particles_apart_splat_as_on_the_cpu(gpu: Gpu) {
    // Seven particles far apart, in double precision off the origin, attributes 0..6 in the
    // data's units (as in `particles_apart_splat_to_the_rbf_image`): each pixel sees one
    // particle at most, so the backends differ only by f32 rounding.
    let offset = DVec3::new(1.0e4 + 0.123_456_789_012_345_6, -2.5e3, 7.0 / 3.0);
    let positions: Vec<DVec3> = (0..7)
        .map(|i| offset + DVec3::new(0.3 * i as f64, 0.07 * (i % 3) as f64, 0.05 * i as f64))
        .collect();
    let step = Step {
        name: "apart".into(),
        positions,
        attributes: vec![Attribute {
            name: "a".into(),
            values: vec![3.0, -1.5, 0.25, 7.0, 2.0, 5.5, 0.0],
        }],
    };
    let series = TimeSeries::from_steps(vec![step]);
    let field = FieldSettings::new(Some("a"), 0.1);
    let settings = RenderSettings {
        width: 40,
        height: 40,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        // Phi stays in the optical map's linear range (a lone particle's Phi is at most 1).
        phi_ref: Some(2.0),
        ..RenderSettings::default()
    };
    let mut cpu = cpu_session(&series, 0, &field, 1);
    let frame = cpu.frame_params(&settings, 0).unwrap();
    let (reference, lost) = splat(&mut cpu, &settings, 15);
    assert_eq!(lost, 0.0);
    assert!(
        reference.pixels.iter().filter(|p| p[3] > 0.05).count() > 20,
        "the particles are visible"
    );
    // f32 local positions (what the automatic precision picks here) and double-single ones
    // (splat_offset adds the lo parts).
    for precision in [Precision::RENDER, Precision::DoubleSingle] {
        for (traversal, mut device) in gpu.traversals() {
            show(&mut *device, &series, 0, &field, 1, precision);
            assert_eq!(
                device.representation().unwrap().positions == PositionKind::DoubleSingle,
                precision == Precision::DoubleSingle,
                "{precision:?}"
            );
            let image = gpu_splat(&mut *device, &frame, 15);
            assert!(all_finite(&image), "{traversal}: every pixel is written");
            let error = image.rmse(&reference);
            let worst = largest_difference(&image, &reference);
            eprintln!(
                "particles apart, {precision:?}: {gpu} {traversal} vs cpu splat RMSE {error:.3e}, \
                 largest difference {worst:.3e}"
            );
            // Measured on lavapipe, every backend and traversal alike: RMSE 1.2e-8, largest
            // difference 5.5e-7 (f32 rounding).
            assert!(
                error < 1e-6 && worst < 1e-5,
                "{traversal}, {precision:?}: RMSE {error}, largest pixel difference {worst}"
            );
        }
    }
    assert_no_driver_messages();
}

fn the_dam_break_splats_as_on_the_cpu_until_a_small_buffer_loses_hits(gpu: Gpu) {
    let (series, field) = dam_break();
    for size in [32, 64] {
        for cluster in [1, 4] {
            let mut cpu = cpu_session(&series, 7, &field, cluster);
            let settings = RenderSettings {
                width: size,
                height: size,
                integrator: Integrator::Ea,
                noise: NoiseKind::Stbn,
                ..RenderSettings::default()
            };
            let frame = cpu.frame_params(&settings, 0).unwrap();
            let (reference, lost) = splat(&mut cpu, &settings, SPLAT_K_MAX as usize);
            assert!(
                reference.pixels.iter().any(|p| p[3] > 0.3),
                "the data shows"
            );
            for (traversal, mut device) in gpu.traversals() {
                show(&mut *device, &series, 7, &field, cluster, Precision::RENDER);
                let what = format!("{traversal}, {size}x{size}, cluster size {cluster}");
                let all = gpu_splat(&mut *device, &frame, SPLAT_K_MAX as usize);
                let one = gpu_splat(&mut *device, &frame, 1);
                assert!(all_finite(&all) && all_finite(&one), "{what}");
                let error = all.rmse(&reference);
                let worst = largest_difference(&all, &reference);
                let loss = one.rmse(&all);
                eprintln!(
                    "dam break, {what}: k = {SPLAT_K_MAX}: cpu lost {lost:.2e} of its hits, \
                     {gpu} vs cpu RMSE {error:.3e} (largest difference {worst:.3e}); {gpu} k = \
                     1 vs k = {SPLAT_K_MAX} RMSE {loss:.3e}"
                );
                // Measured on lavapipe, every backend and traversal alike: RMSE 5.9e-8 (32x32)
                // and 5.1e-8 (64x64), largest difference 4.0e-6 and 3.0e-6.
                assert!(error < 1e-6, "{what}: RMSE {gpu} vs cpu {error}");
                assert!(worst < 1e-3, "{what}: largest pixel difference {worst}");
                // One hit per slab loses most of the overlapping particles: a different image
                // (measured: RMSE 1.5e-2 to 1.9e-2 from the k = 64 image).
                assert!(
                    loss > 0.005,
                    "{what}: k = 1 differs from k = {SPLAT_K_MAX} by RMSE {loss}"
                );
                if size == 64 {
                    print_frame_times(&mut *device, &frame, &what);
                }
            }
        }
    }
    assert_no_driver_messages();
}

/// What a splatter frame costs beside the RBF renderer's emission–absorption: the median of 5
/// frames of each after a first one (no pipeline compilation counted). Printed, not asserted:
/// lavapipe's times vary with the machine's load.
fn print_frame_times(device: &mut dyn Backend, frame: &FrameParams, what: &str) {
    let mut timed = |f: &mut dyn FnMut(&mut dyn Backend)| {
        f(device);
        let mut ms: Vec<f64> = (0..5)
            .map(|_| {
                f(device);
                device.timings().frame.as_secs_f64() * 1e3
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        ms[2]
    };
    let splat_ms = timed(&mut |b| {
        b.render_splat(frame, 15).unwrap();
    });
    let rbf_ms = timed(&mut |b| b.render(frame).unwrap());
    eprintln!(
        "dam break, {what} on {}: splat (k = 15) frame {splat_ms:.1} ms, RBF (EA) frame \
         {rbf_ms:.1} ms (medians of 5)",
        device.capabilities().device
    );
}

fn a_slab_buffer_outside_1_to_splat_k_max_is_an_error(gpu: Gpu) {
    let (series, field) = dam_break();
    let cpu = cpu_session(&series, 7, &field, 4);
    let mut device = gpu.backend();
    show(&mut *device, &series, 7, &field, 4, Precision::RENDER);
    let settings = RenderSettings {
        width: 8,
        height: 8,
        ..RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    for k in [0, SPLAT_K_MAX as usize + 1] {
        let message = device.render_splat(&frame, k).unwrap_err().to_string();
        assert!(
            message.contains(&format!("1..={SPLAT_K_MAX}")) && message.contains(&k.to_string()),
            "k = {k}: {message}"
        );
    }
    // The limits themselves are accepted.
    for k in [1, SPLAT_K_MAX as usize] {
        assert_eq!(device.render_splat(&frame, k).unwrap(), None);
    }
    assert_no_driver_messages();
}
