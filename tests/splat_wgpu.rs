//! Knoll et al.'s splatter on the wgpu backend (`shaders_glsl/wgpu/lbvh_splat.comp`: the slabs'
//! hits collected by a software traversal of the LBVH) against the CPU backend's splatter, the
//! reference: the same slabs, hits and compositing, f32 on the GPU against f64 on the CPU.
//! Without a wgpu adapter these tests fail.
//!
//! The wgpu backend is driven directly (uploaded and built as `RenderSession::show` does) so
//! the tests can poison its accumulation; the frame constants come from a CPU session over the
//! same series, field and step.

use std::sync::Arc;

use aarbf::accel::ClusterSize;
use aarbf::backend::wgpu_lbvh::{GpuContext, WgpuBackend};
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::shader_constants::SPLAT_K_MAX;
use aarbf::values::{Attribute, FrameParams, Image, Integrator, NoiseKind, Step};
use glam::DVec3;

use crate::common;
use common::assert_no_driver_messages;

fn gpu() -> Arc<GpuContext> {
    common::capture_driver_messages();
    common::require("a wgpu adapter", GpuContext::shared())
}

/// The CPU reference (f64) showing `step` of `series`, and the wgpu backend holding the same
/// with positions as `precision` says.
fn backends(
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: u32,
    precision: Precision,
) -> (RenderSession, WgpuBackend) {
    let cluster = ClusterSize::new(cluster).unwrap();
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), series);
    cpu.set_precision(Precision::F64);
    cpu.show(series, step, field, cluster).unwrap();
    let mut wgpu = WgpuBackend::with_context(gpu());
    show(&mut wgpu, series, step, field, cluster, precision);
    (cpu, wgpu)
}

/// Uploads and builds `step` of `series` as `RenderSession::show` does.
fn show(
    wgpu: &mut WgpuBackend,
    series: &TimeSeries,
    step: usize,
    field: &FieldSettings,
    cluster: ClusterSize,
    precision: Precision,
) {
    wgpu.reserve(series.max_count());
    let range = field
        .attribute
        .as_deref()
        .and_then(|a| series.attribute(a))
        .map(|a| (a.min, a.max));
    wgpu.upload(&StepInput {
        step: &series.step(step).unwrap(),
        field,
        cluster,
        series_bounds: series.bounds(),
        series_range: range,
        precision,
    })
    .unwrap();
    wgpu.build().unwrap();
}

/// One splatter frame of `backend` (its accumulation restarted), as an image.
fn splat(backend: &mut dyn Backend, frame: &FrameParams, k: usize) -> Image {
    backend.reset();
    backend.render_splat(frame, k).unwrap();
    backend.image().unwrap()
}

fn cpu_splat(cpu: &mut RenderSession, frame: &FrameParams, k: usize) -> (Image, f64) {
    let backend = cpu.backend_mut();
    backend.reset();
    let counts = backend
        .render_splat(frame, k)
        .unwrap()
        .expect("the cpu counts hits");
    (backend.image().unwrap(), counts.lost_fraction())
}

fn largest_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .map(|(a, b)| (0..4).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max)
}

fn all_finite(image: &Image) -> bool {
    image.pixels.iter().flatten().all(|v| v.is_finite())
}

fn dam_break() -> (TimeSeries, FieldSettings) {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1));
    let field = FieldSettings::new(Some("velocity"), 0.03 * series.bounds().diagonal());
    (series, field)
}

#[test]
fn particles_apart_splat_as_on_the_cpu() {
    // Seven particles far apart, in double precision off the origin, attributes 0..6 in the
    // data's units (as in tests/splat_baseline.rs): each pixel sees one particle at most, so
    // the two backends differ only by f32 rounding.
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
    // f32 local positions (what the automatic precision picks here) and double-single ones
    // (splat_offset adds the lo parts).
    for (precision, double_single) in [(Precision::RENDER, false), (Precision::DoubleSingle, true)]
    {
        let (mut cpu, mut wgpu) = backends(&series, 0, &field, 1, precision);
        assert_eq!(
            wgpu.step_data().unwrap().double_single(),
            double_single,
            "{precision:?}"
        );
        let frame = cpu.frame_params(&settings, 0).unwrap();
        let (reference, lost) = cpu_splat(&mut cpu, &frame, 15);
        assert_eq!(lost, 0.0);
        assert!(
            reference.pixels.iter().filter(|p| p[3] > 0.05).count() > 20,
            "the particles are visible"
        );
        let image = splat(&mut wgpu, &frame, 15);
        assert!(all_finite(&image));
        let error = image.rmse(&reference);
        let worst = largest_difference(&image, &reference);
        eprintln!(
            "particles apart, {precision:?}: wgpu vs cpu splat RMSE {error:.3e}, largest \
             difference {worst:.3e}"
        );
        // Measured on lavapipe: RMSE 1.2e-8, largest difference 4.2e-7 (f32 rounding).
        assert!(
            error < 1e-5,
            "{precision:?}: RMSE wgpu vs cpu splat {error}"
        );
        assert!(
            worst < 1e-4,
            "{precision:?}: largest pixel difference {worst}"
        );
    }
    assert_no_driver_messages();
}

#[test]
fn dam_break_splats_as_on_the_cpu_and_a_small_buffer_loses_hits() {
    let (series, field) = dam_break();
    for cluster in [1, 4] {
        let (mut cpu, mut wgpu) = backends(&series, 7, &field, cluster, Precision::RENDER);
        let settings = RenderSettings {
            width: 64,
            height: 64,
            integrator: Integrator::Ea,
            noise: NoiseKind::Stbn,
            ..RenderSettings::default()
        };
        let frame = cpu.frame_params(&settings, 0).unwrap();
        let (reference, lost) = cpu_splat(&mut cpu, &frame, SPLAT_K_MAX as usize);
        assert!(
            reference.pixels.iter().any(|p| p[3] > 0.3),
            "the data shows"
        );
        let all = splat(&mut wgpu, &frame, SPLAT_K_MAX as usize);
        let one = splat(&mut wgpu, &frame, 1);
        assert!(all_finite(&all) && all_finite(&one));
        let error = all.rmse(&reference);
        let worst = largest_difference(&all, &reference);
        let loss = one.rmse(&all);
        eprintln!(
            "dam break, cluster size {cluster}: k = {SPLAT_K_MAX}: cpu lost {lost:.2e} of its \
             hits, wgpu vs cpu RMSE {error:.3e} (largest difference {worst:.3e}); wgpu k = 1 vs \
             k = {SPLAT_K_MAX} RMSE {loss:.3e}"
        );
        // Measured on lavapipe: RMSE 5.5e-8, largest difference 2.7e-6 at both cluster sizes.
        assert!(
            error < 1e-5,
            "cluster size {cluster}: RMSE wgpu vs cpu {error}"
        );
        assert!(
            worst < 1e-3,
            "cluster size {cluster}: largest pixel difference {worst}"
        );
        // One hit per slab loses most of the overlapping particles: a different image
        // (measured: RMSE 2.4e-2 from the k = 64 image at both cluster sizes).
        assert!(
            loss > 0.005,
            "cluster size {cluster}: k = 1 differs from k = {SPLAT_K_MAX} by RMSE {loss}"
        );

        // What a frame costs beside the RBF renderer's emission–absorption: the median of 5
        // frames of each after a first one (no pipeline compilation counted). Printed, not
        // asserted: lavapipe's times vary with the machine's load.
        let mut timed = |f: &mut dyn FnMut(&mut WgpuBackend)| {
            f(&mut wgpu);
            let mut ms: Vec<f64> = (0..5)
                .map(|_| {
                    f(&mut wgpu);
                    wgpu.timings().frame.as_secs_f64() * 1e3
                })
                .collect();
            ms.sort_by(f64::total_cmp);
            ms[2]
        };
        let splat_ms = timed(&mut |b| {
            b.render_splat(&frame, 15).unwrap();
        });
        let rbf_ms = timed(&mut |b| b.render(&frame).unwrap());
        eprintln!(
            "dam break, cluster size {cluster}, 64x64 on {}: splat (k = 15) frame {splat_ms:.1} \
             ms, RBF (EA) frame {rbf_ms:.1} ms (medians of 5)",
            wgpu.capabilities().device
        );
    }
    assert_no_driver_messages();
}

/// The splatter writes every pixel: its first frame stores into the accumulation without
/// clearing it, so with the sums poisoned (NaN) a missed pixel would show. At a size that is
/// no multiple of the 8x8 tiles, so the edge tiles' pixels count too. A second frame adds to
/// the first (the image, their mean, is the same deterministic frame), and `render` after it
/// accumulates into the same sums.
#[test]
fn every_pixel_is_written_over_a_poisoned_accumulation() {
    let (series, field) = dam_break();
    let (cpu, mut wgpu) = backends(&series, 7, &field, 4, Precision::RENDER);
    let settings = RenderSettings {
        width: 37,
        height: 29,
        integrator: Integrator::Ea,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    let first = splat(&mut wgpu, &frame, 15);
    assert!(all_finite(&first));
    assert!(first.pixels.iter().any(|p| p[3] > 0.3), "the data shows");
    wgpu.poison_accumulation().unwrap();
    wgpu.render_splat(&frame, 15).unwrap();
    let again = wgpu.image().unwrap();
    assert!(all_finite(&again), "a pixel kept the poison");
    assert_eq!(again.pixels, first.pixels, "the same frame");
    wgpu.render_splat(&frame, 15).unwrap();
    let twice = wgpu.image().unwrap();
    assert_eq!(wgpu.frames(), 2);
    let worst = largest_difference(&twice, &first);
    assert!(worst < 1e-6, "the mean of two equal frames: {worst}");
    assert_no_driver_messages();
}

/// With the binding limit lowered so that the particles, the tree and the accumulation each
/// span several storage bindings, the splatter (its 4-part kernel) draws the same image, bit
/// for bit, as with one binding per array, over a poisoned accumulation.
#[test]
fn a_step_and_image_split_over_bindings_splat_the_same_image() {
    let (series, field) = dam_break();
    let (cpu, mut whole) = backends(&series, 7, &field, 4, Precision::RENDER);
    // 3000 particles (48,000 B) in 3 parts of 16 KiB, 750 clusters' nodes and boxes (24,000
    // B each) in 2, a 48x40 image's sums (30,720 B) in 2.
    let mut split = WgpuBackend::with_max_binding(gpu(), 16 * 1024);
    let cluster = ClusterSize::new(4).unwrap();
    show(&mut split, &series, 7, &field, cluster, Precision::RENDER);
    assert_eq!(split.split_parts(), Some((3, 2)));
    let settings = RenderSettings {
        width: 48,
        height: 40,
        ..RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    let expected = splat(&mut whole, &frame, 15);
    assert!(expected.pixels.iter().any(|p| p[3] > 0.3), "the data shows");
    splat(&mut split, &frame, 15);
    split.poison_accumulation().unwrap();
    let image = splat(&mut split, &frame, 15);
    assert!(
        image == expected,
        "split and unsplit splatter images differ"
    );
    assert_no_driver_messages();
}

#[test]
fn a_slab_buffer_outside_1_to_splat_k_max_is_an_error() {
    let (series, field) = dam_break();
    let (cpu, mut wgpu) = backends(&series, 7, &field, 4, Precision::RENDER);
    let settings = RenderSettings {
        width: 8,
        height: 8,
        ..RenderSettings::default()
    };
    let frame = cpu.frame_params(&settings, 0).unwrap();
    for k in [0, SPLAT_K_MAX as usize + 1] {
        let message = wgpu.render_splat(&frame, k).unwrap_err().to_string();
        assert!(
            message.contains(&SPLAT_K_MAX.to_string()) && message.contains(&k.to_string()),
            "k = {k}: {message}"
        );
    }
    // The limits themselves are accepted.
    for k in [1, SPLAT_K_MAX as usize] {
        assert_eq!(wgpu.render_splat(&frame, k).unwrap(), None);
    }
    assert_no_driver_messages();
}
