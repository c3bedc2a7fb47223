//! The ash (Vulkan ray-tracing) backend's own mechanisms, on whatever Vulkan device with
//! ray-tracing pipelines this machine has (lavapipe in CI): its BLAS boxes, hit reports and
//! refit, its two traversals, its images against the wgpu backend's, arrays and images past a
//! binding, and its limits. What every GPU backend must do is checked in `gpu_backends`.
//!
//! - Without such a device the tests fail (a GPU test never passes without running).
//! - One Vulkan device serves every test of this process (the backend shares it), so each
//!   pipeline variant is JIT-compiled once.
//! - The validation layer is on (the `checked` profile has debug assertions) when installed,
//!   and every test ends by asserting that it reported nothing.

use std::sync::Arc;

use aarbf::accel::{ClusterBoxes, ClusterSize};
use aarbf::backend::ash_rt::{self, AshBackend};
use aarbf::backend::gpu_data::GpuStepData;
use aarbf::backend::shaders::cpu::blas_boxes;
use aarbf::backend::shaders::cpu::rbf::RadiusRule;
use aarbf::backend::{Backend, StepInput};
use aarbf::field::{Classification, FieldSettings, ReferenceField};
use aarbf::scene::maps::RadiusMap;
use aarbf::values::{Attribute, Bounds, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common::{self, assert_no_driver_messages};
use crate::gpu_backends::{
    assert_images_close, box_step, close_view, compare_sums, dambreak, input, queries,
    radius_map_with_zeros,
};

/// A backend on the shared ray-tracing device (the test fails without one).
fn backend() -> AshBackend {
    common::require(
        "a Vulkan device with ray-tracing pipelines",
        AshBackend::new(),
    )
}

#[test]
fn device_has_ray_tracing_and_validation_when_installed() {
    let b = backend();
    let caps = b.capabilities();
    assert_eq!(caps.name, "ash");
    assert!(caps.hardware_rt);
    eprintln!("device: {}", caps.device);
    let ctx = ash_rt::context::shared().unwrap();
    let layer =
        std::path::Path::new("/usr/share/vulkan/explicit_layer.d/VkLayer_khronos_validation.json");
    if layer.exists() && std::env::var("AARBF_VK_VALIDATION").as_deref() != Ok("0") {
        assert!(
            ctx.validation,
            "the validation layer is installed and this build has debug assertions"
        );
    }
    // More particles than the device can allocate: a clear error naming need and limit.
    let mut b = b;
    let step = std::sync::Arc::new(box_step(10, 1));
    let field = FieldSettings::new(Some("s"), 0.1);
    b.reserve(1 << 40);
    let e = b.upload(&input(&step, &field, 1)).unwrap_err().to_string();
    assert!(
        e.contains("1099511627776 particles") && e.contains("allocates at most"),
        "{e}"
    );
    assert_no_driver_messages();
}

/// The box kernel's boxes equal its CPU twin's (`cpu::blas_boxes::blas_boxes`, the same f32
/// rule) to an ulp, contain the CPU's (f64, outward-rounded) cluster boxes and exceed them by
/// no more than the padding; clusters whose particles all have radius 0 get a degenerate box at
/// their first particle; clusters past the step are NaN.
#[test]
fn boxes_match_the_cpu_cluster_boxes() {
    let mut b = backend();
    let step = std::sync::Arc::new(box_step(1237, 1));
    let mut field = FieldSettings::new(Some("s"), 0.05);
    field.radius_map = radius_map_with_zeros();
    field.radius_attribute = Some("h".into());
    for k in [1, 4, 16] {
        b.reserve(1500);
        b.upload(&input(&step, &field, k)).unwrap();
        b.build().unwrap();
        let reference = ReferenceField::of_step(
            &step,
            &field,
            ClusterSize::new(k).unwrap(),
            step.bounds(),
            None,
        )
        .unwrap();
        let cpu: &ClusterBoxes = reference.boxes();
        let gpu = b.read_boxes().unwrap();
        let (data, particles) = GpuStepData::prepare(&input(&step, &field, k)).unwrap();
        let rule = RadiusRule {
            field: data.field,
            radius_table: data.radius_map_varies.then_some(&data.tables.radius[..]),
            radius_attribute: particles.radius_attribute.as_deref(),
        };
        let twin = blas_boxes::blas_boxes(&particles.points, k as usize, &rule, gpu.len());
        for (c, (g, t)) in gpu.iter().zip(&twin).enumerate() {
            for (a, e) in g.iter().zip(t) {
                // One ulp: the compiler may fuse the padding's multiply into the subtraction.
                let same = (a.is_nan() && e.is_nan()) || (a - e).abs() <= e.abs() * 2.4e-7;
                assert!(same, "K = {k}, box {c}: GPU {g:?}, twin {t:?}");
            }
        }
        let origin = b.origin().unwrap();
        let clusters = cpu.len();
        assert_eq!(gpu.len(), ClusterSize::new(k).unwrap().clusters_for(1500));
        let mut degenerate = 0;
        for (c, g) in gpu.iter().enumerate() {
            if c >= clusters {
                assert!(
                    g.iter().all(|v| v.is_nan()),
                    "K = {k}, box {c} past the step: {g:?}"
                );
                continue;
            }
            let lo = DVec3::new(g[0].into(), g[1].into(), g[2].into()) + origin;
            let hi = DVec3::new(g[3].into(), g[4].into(), g[5].into()) + origin;
            let want: Bounds = cpu.boxes[c];
            if want.is_empty() {
                degenerate += 1;
                let first =
                    reference.particles.origin + reference.particles.centers[c * k as usize];
                assert_eq!(lo, hi, "K = {k}, box {c}: degenerate");
                assert!((lo - first).abs().max_element() < 1e-4, "K = {k}, box {c}");
                continue;
            }
            // The f32 local box against the f64 box: the GPU's may be larger by its padding
            // plus the rounding of local coordinates (~1e-4 of the 2-unit extent at 1000).
            let (wlo, whi) = (
                want.min + reference.particles.origin,
                want.max + reference.particles.origin,
            );
            let slack = 2e-4;
            assert!(
                lo.cmple(wlo + slack).all() && hi.cmpge(whi - slack).all(),
                "K = {k}, box {c}: GPU {lo}..{hi} does not contain CPU {wlo}..{whi}"
            );
            assert!(
                lo.cmpge(wlo - slack).all() && hi.cmple(whi + slack).all(),
                "K = {k}, box {c}: GPU {lo}..{hi} much larger than CPU {wlo}..{whi}"
            );
        }
        assert!(
            k > 4 || degenerate > 0,
            "K = {k}: the scene has clusters of zero-radius particles"
        );
    }
    assert_no_driver_messages();
}

/// The paper's per-particle hit reports (selectable for the traversal study) give what the
/// default per-cluster sums give, on a driver (lavapipe) that calls any-hit for every report
/// of a box; double-single positions in both.
#[test]
fn per_particle_hit_reports_match_per_cluster_sums() {
    use aarbf::backend::ash_rt::HitReports;
    let mut b = backend();
    let step = std::sync::Arc::new(box_step(1200, 21));
    let points = queries(&step, 22);
    for k in [1, 4, 16] {
        let mut field = FieldSettings::new(Some("s"), 0.2);
        field.radius_map = radius_map_with_zeros();
        b.upload(&input(&step, &field, k)).unwrap();
        b.build().unwrap();
        b.set_hit_reports(HitReports::PerCluster);
        let sums = b.query(&points).unwrap();
        b.set_hit_reports(HitReports::PerParticle);
        let each = b.query(&points).unwrap();
        b.set_hit_reports(HitReports::PerCluster);
        for (i, (a, e)) in sums.iter().zip(&each).enumerate() {
            // The same terms summed in another order (f32).
            assert!(
                (a.0 - e.0).abs() <= 1e-5 * a.0.max(1e-30)
                    && (0..3).all(|c| (a.1[c] - e.1[c]).abs() <= 1e-5 * a.0.max(1e-30)),
                "K = {k}, query {i}: per cluster {a:?}, per particle {e:?}"
            );
        }
    }
    assert_no_driver_messages();
}

/// A refit after a radius change (global radius, radius map with zeros moving, radius attribute
/// switched on) gives the field a fresh build gives, and both match the reference.
#[test]
fn refit_after_a_radius_change_equals_a_fresh_build() {
    let mut refitted = backend();
    let mut fresh = backend();
    let step = std::sync::Arc::new(box_step(1400, 4));
    let points = queries(&step, 5);
    let k = 4;
    let mut before = FieldSettings::new(Some("s"), 0.15);
    before.radius_map = radius_map_with_zeros();
    refitted.upload(&input(&step, &before, k)).unwrap();
    refitted.build().unwrap();
    let build_time = refitted.timings().build;
    // Particles with t < 0.2 had radius 0 (degenerate boxes); now those with t > 0.8 have.
    let mut after = before.clone();
    after.radius = 0.21;
    // Continuous and on the table grid (a jump would fall between two table samples).
    after.radius_map = RadiusMap("0:1,0.6:0.6,0.8:0,1:0".parse().unwrap());
    after.radius_attribute = Some("h".into());
    refitted.refit(&after).unwrap();
    let t = refitted.structure_timings();
    assert!(t.refit && refitted.timings().refit > std::time::Duration::ZERO);
    eprintln!(
        "build {build_time:?}, refit {:?} (BLAS {:?})",
        refitted.timings().refit,
        t.blas
    );
    fresh.upload(&input(&step, &after, k)).unwrap();
    fresh.build().unwrap();
    let a = refitted.query(&points).unwrap();
    let b = fresh.query(&points).unwrap();
    let mut worst: f64 = 0.0;
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        // Same terms, possibly summed in another order (the refitted tree's shape differs).
        let tol = 1e-5 * x.0.abs().max(y.0.abs()) + 1e-7;
        let err = (x.0 - y.0)
            .abs()
            .max((0..3).map(|c| (x.1[c] - y.1[c]).abs()).fold(0.0, f64::max));
        assert!(err <= tol, "query {i}: refit {x:?} vs fresh {y:?}");
        worst = worst.max(err / x.0.abs().max(1e-30));
    }
    eprintln!("refit vs fresh build: max relative difference {worst:.2e}");
    let reference = ReferenceField::of_step(
        &step,
        &after,
        ClusterSize::new(k).unwrap(),
        step.bounds(),
        None,
    )
    .unwrap();
    compare_sums(&reference, &points, &a, "refitted");
    // Refit back to the first radii: equal to the first build's field again.
    refitted.refit(&before).unwrap();
    let reference = ReferenceField::of_step(
        &step,
        &before,
        ClusterSize::new(k).unwrap(),
        step.bounds(),
        None,
    )
    .unwrap();
    compare_sums(
        &reference,
        &points,
        &refitted.query(&points).unwrap(),
        "refitted back",
    );
    // Bad radii are errors, and leave the backend usable.
    let mut bad = after.clone();
    bad.radius = -1.0;
    assert!(refitted.refit(&bad).is_err());
    bad.radius = 0.1;
    bad.radius_attribute = Some("nonexistent".into());
    assert!(refitted.refit(&bad).is_err());
    assert!(refitted.query(&points[..10]).is_ok());
    assert_no_driver_messages();
}

/// A step with fewer particles than the buffers hold (NaN boxes past its clusters) renders and
/// queries like the same step loaded alone.
#[test]
fn a_smaller_step_renders_like_that_step_alone() {
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::values::{Integrator, NoiseKind};
    let (mut shared, mut alone) = (backend(), backend());
    let series = dambreak();
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let k = 2;
    let (big, small) = (series.step(7).unwrap(), series.step(3).unwrap());
    // The demo's steps hold different counts; pad the difference in any case.
    let max = series.max_count() + 100;
    assert!(small.len() < max);
    let range = series.attribute("velocity").map(|a| (a.min, a.max));
    let input = |step| StepInput {
        series_bounds: series.bounds(),
        series_range: range,
        ..input(step, &field, k)
    };
    shared.reserve(max);
    shared.upload(&input(&big)).unwrap();
    shared.build().unwrap();
    shared.upload(&input(&small)).unwrap();
    shared.build().unwrap();
    alone.upload(&input(&small)).unwrap();
    alone.build().unwrap();
    assert!(shared.blas_boxes() > alone.blas_boxes());
    assert_eq!(shared.blas_active_boxes(), alone.blas_active_boxes());
    // Frame constants from a CPU session over the same step (any will do, as long as both
    // backends get the same).
    let mut session = RenderSession::new(
        aarbf::backend::create(aarbf::backend::BackendKind::Cpu).unwrap(),
        &series,
    );
    session
        .show(&series, 3, &field, ClusterSize::new(k).unwrap())
        .unwrap();
    for integrator in [Integrator::Ea, Integrator::Marching] {
        let settings = RenderSettings {
            width: 48,
            height: 48,
            integrator,
            noise: NoiseKind::Stbn,
            ..RenderSettings::default()
        };
        shared.reset();
        alone.reset();
        for frame in 0..2 {
            let params = session.frame_params(&settings, frame).unwrap();
            shared.render(&params).unwrap();
            alone.render(&params).unwrap();
        }
        let (a, b) = (shared.image().unwrap(), alone.image().unwrap());
        assert!(a.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())));
        let visible = a.pixels.iter().filter(|p| p[3] > 0.0).count();
        assert!(
            visible > 50,
            "{integrator:?}: {visible} pixels see the fluid"
        );
        assert_eq!(a, b, "{integrator:?}: the image with NaN boxes differs");
    }
    let points = queries(&small, 9);
    assert_eq!(
        shared.query(&points).unwrap(),
        alone.query(&points).unwrap()
    );
    assert_no_driver_messages();
}

/// The software traversal on the same device (the LBVH compute pipeline, Fig. 10a's other
/// side) gives the RT pipeline's field and images: same particles, RBF code and integrators.
#[test]
fn lbvh_traversal_on_the_same_device_matches_the_rt_pipeline() {
    use aarbf::backend::ash_rt::Traversal;
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::values::{Integrator, NoiseKind};
    let mut b = backend();
    let step = std::sync::Arc::new(box_step(1300, 6));
    let points = queries(&step, 7);
    for (k, classification) in [
        (1, Classification::Post),
        (4, Classification::Pre),
        (16, Classification::Post),
    ] {
        let mut field = FieldSettings::new(Some("s"), 0.2);
        field.classification = classification;
        field.radius_map = radius_map_with_zeros();
        field.radius_attribute = Some("h".into());
        b.set_traversal(Traversal::RtPipeline);
        b.upload(&input(&step, &field, k)).unwrap();
        b.build().unwrap();
        let rt = b.query(&points).unwrap();
        b.set_traversal(Traversal::Lbvh);
        let lbvh = b.query(&points).unwrap();
        assert!(b.lbvh_depth().unwrap() > 0);
        let reference = ReferenceField::of_step(
            &step,
            &field,
            ClusterSize::new(k).unwrap(),
            step.bounds(),
            None,
        )
        .unwrap();
        let what = format!("LBVH, K = {k}, {classification:?}");
        compare_sums(&reference, &points, &lbvh, &what);
        for (i, (a, c)) in rt.iter().zip(&lbvh).enumerate() {
            let tol = 1e-5 * a.0 + 1e-7;
            assert!(
                (a.0 - c.0).abs() <= tol && (0..3).all(|j| (a.1[j] - c.1[j]).abs() <= tol),
                "{what}: query {i}: RT {a:?} vs LBVH {c:?}"
            );
        }
        // A refit invalidates the LBVH, which is rebuilt on the next query.
        let mut wider = field.clone();
        wider.radius = 0.25;
        b.refit(&wider).unwrap();
        let reference = ReferenceField::of_step(
            &step,
            &wider,
            ClusterSize::new(k).unwrap(),
            step.bounds(),
            None,
        )
        .unwrap();
        compare_sums(
            &reference,
            &points,
            &b.query(&points).unwrap(),
            "LBVH after a refit",
        );
    }
    // Frames: the RT pipeline and the LBVH kernel through the same session.
    let series = dambreak();
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let mut session = RenderSession::new(Box::new(backend()), &series);
    session
        .show(&series, 7, &field, ClusterSize::new(4).unwrap())
        .unwrap();
    let settings = RenderSettings {
        width: 48,
        height: 40,
        integrator: Integrator::Marching,
        noise: NoiseKind::Stbn,
        camera: Some(close_view(&series)),
        ..RenderSettings::default()
    };
    let frames: Vec<_> = (0..2)
        .map(|f| session.frame_params(&settings, f).unwrap())
        .collect();
    let mut b = backend();
    let range = series.attribute("velocity").map(|a| (a.min, a.max));
    let step = series.step(7).unwrap();
    b.upload(&StepInput {
        series_bounds: series.bounds(),
        series_range: range,
        ..input(&step, &field, 4)
    })
    .unwrap();
    b.build().unwrap();
    let mut render = |traversal| {
        b.set_traversal(traversal);
        b.reset();
        for f in &frames {
            b.render(f).unwrap();
        }
        b.image().unwrap()
    };
    let rt = render(Traversal::RtPipeline);
    let lbvh = render(Traversal::Lbvh);
    assert_images_close("lbvh-vs-rt-marching", &rt, &lbvh, 1e-4, 1e-3);
    assert_no_driver_messages();
}

/// The ash backend's images against the wgpu backend's (the same shared GLSL integrators over
/// an LBVH) at equal spp and seed: the same decisions from the same random numbers, for every
/// integrator, so only f32 summation order differs.
#[test]
fn renders_match_the_wgpu_backend() {
    use aarbf::backend::{self, BackendKind};
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::values::{Integrator, NoiseKind};
    backend();
    let wgpu = common::require("the wgpu backend", backend::create(BackendKind::Wgpu));
    let series = dambreak();
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let k = ClusterSize::new(4).unwrap();
    let mut other = RenderSession::new(wgpu, &series);
    let mut gpu = RenderSession::new(backend::create(BackendKind::Ash).unwrap(), &series);
    other.show(&series, 7, &field, k).unwrap();
    gpu.show(&series, 7, &field, k).unwrap();
    // (integrator, RMSE limit, FLIP limit); measured: RMSE ~3e-10, FLIP 0 for all three.
    for (integrator, max_rmse, max_flip) in [
        (Integrator::Ea, 1e-4, 1e-3),
        (Integrator::Marching, 1e-3, 5e-3),
        (Integrator::Delta, 1e-3, 5e-3),
    ] {
        let settings = RenderSettings {
            width: 48,
            height: 40,
            integrator,
            noise: NoiseKind::Stbn,
            seed: 5,
            camera: Some(close_view(&series)),
            ..RenderSettings::default()
        };
        let expected = other.render(&settings, 2).unwrap();
        let actual = gpu.render(&settings, 2).unwrap();
        let name = format!("wgpu-{integrator:?}").to_lowercase();
        assert_images_close(&name, &expected, &actual, max_rmse, max_flip);
    }
    // The half-resolution lattice a targeted render measures its noise on (odd sizes).
    let settings = RenderSettings {
        width: 47,
        height: 39,
        seed: 5,
        camera: Some(close_view(&series)),
        ..RenderSettings::default()
    };
    let expected = other
        .render_frames_on_half_lattice(&settings, 0, 2)
        .unwrap();
    let actual = gpu.render_frames_on_half_lattice(&settings, 0, 2).unwrap();
    assert_eq!((actual.width, actual.height), (24, 20));
    assert_images_close("wgpu-lattice", &expected, &actual, 1e-4, 1e-3);
    assert_no_driver_messages();
}

/// A step larger than one storage-buffer binding (maxStorageBufferRange: 128 MiB on lavapipe,
/// 8,388,608 particles as vec4) uploads, builds and answers queries: the shaders reach the
/// particle and box arrays by device address, so only the allocation limit applies. Checked
/// against a brute-force f64 sum at points spread over the whole index range.
#[test]
fn a_step_larger_than_one_binding_is_not_refused() {
    use rayon::prelude::*;
    let mut b = backend();
    let range = ash_rt::context::shared()
        .unwrap()
        .info
        .max_storage_buffer_range;
    // Enough particles that both the particles (16 B) and the K = 1 boxes (24 B) pass the
    // binding limit, bounded so the test stays quick where bindings are huge (real GPUs).
    let n = (range / 16 + 100_000).min(12_000_000) as usize;
    let over = n as u64 * 16 > range;
    eprintln!(
        "{n} particles: {} MiB of particles, binding limit {} MiB{}",
        (n * 16) >> 20,
        range >> 20,
        if over {
            ""
        } else {
            " (this device's bindings are larger: no overflow tested)"
        }
    );
    let mut rng = rand_pcg::Pcg64::seed_from_u64(41);
    let positions: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let s: Vec<f64> = (0..n).map(|_| rng.random_range(0.0f64..1.0)).collect();
    let step = Arc::new(Step {
        name: "large".into(),
        positions,
        attributes: vec![Attribute {
            name: "s".into(),
            values: s,
        }],
    });
    // ~35 particles within reach of a point.
    let radius = 0.01;
    let field = FieldSettings::new(Some("s"), radius);
    b.upload(&input(&step, &field, 1)).unwrap();
    b.build().unwrap();
    let mut points: Vec<DVec3> = (0..48)
        .map(|_| step.positions[rng.random_range(0..n)])
        .collect();
    points.extend((0..48).map(|_| DVec3::new(rng.random(), rng.random(), rng.random())));
    let got = b.query(&points).unwrap();
    let (lo, hi) = step.attributes[0]
        .values
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let mut checked = 0;
    for (x, g) in points.iter().zip(&got) {
        // (Phi, Σ t phi, whether a particle's sphere passes within f32 rounding of x).
        let (phi, num, edge) = step
            .positions
            .par_iter()
            .zip(&step.attributes[0].values)
            .map(|(c, &v)| {
                let d = (*x - c).length();
                if d > radius * (1.0 + 1e-5) {
                    return (0.0, 0.0, false);
                }
                let edge = (d - radius).abs() <= 1e-5 * radius;
                let phi = if d <= radius {
                    (-0.5 * (3.0 * d / radius).powi(2)).exp()
                } else {
                    0.0
                };
                let t = (v - lo) / (hi - lo);
                (phi, t * phi, edge)
            })
            .reduce(
                || (0.0, 0.0, false),
                |a, b| (a.0 + b.0, a.1 + b.1, a.2 || b.2),
            );
        if edge {
            continue;
        }
        checked += 1;
        let tol = 1e-4 * phi + 1e-6;
        assert!(
            (g.0 - phi).abs() <= tol && (g.1[0] - num).abs() <= tol,
            "at {x}: GPU {g:?}, f64 ({phi}, {num})"
        );
    }
    assert!(
        checked >= 80,
        "only {checked} of 96 queries away from an edge"
    );
    assert_no_driver_messages();
}

/// An image whose accumulation is larger than one storage-buffer binding (a 4K frame's f32
/// RGBA sums pass lavapipe's 128 MiB) renders on both traversals: the render kernels reach the
/// accumulation by device address. The accumulation is poisoned before the first frame, so an
/// unwritten pixel would show as NaN; the data covers a small part of the view (the test stays
/// quick), the rest must be exactly the background.
#[test]
fn an_image_larger_than_one_binding_is_not_refused() {
    use aarbf::backend::ash_rt::Traversal;
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::scene::Camera;
    backend();
    let range = ash_rt::context::shared()
        .unwrap()
        .info
        .max_storage_buffer_range;
    let width = 4096u32;
    // One row more than a binding holds, at most 2049 rows (real GPUs bind 4 GiB).
    let height = ((range / 16 / u64::from(width)) as u32 + 1).min(2049);
    let over = u64::from(width) * u64::from(height) * 16 > range;
    eprintln!(
        "{width} x {height}: {} MiB of accumulation, binding limit {} MiB{}",
        (u64::from(width) * u64::from(height) * 16) >> 20,
        range >> 20,
        if over {
            ""
        } else {
            " (no overflow tested on this device)"
        }
    );
    let step = box_step(1300, 8);
    let series = aarbf::scene::TimeSeries::from_steps(vec![step]);
    let field = FieldSettings::new(Some("s"), 0.2);
    let centre = series.bounds().center();
    let settings = RenderSettings {
        width,
        height,
        seed: 9,
        // The data (a 2-unit cube) from 40 units away: about 1% of the pixels.
        camera: Some(Camera {
            eye: centre + DVec3::new(0.0, 0.0, 40.0),
            at: centre,
            up: DVec3::Y,
            fovy: 30.0,
        }),
        ..RenderSettings::default()
    };
    for traversal in [Traversal::RtPipeline, Traversal::Lbvh] {
        let mut b = backend();
        b.set_traversal(traversal);
        let mut session = RenderSession::new(Box::new(b), &series);
        session
            .show(&series, 0, &field, ClusterSize::new(4).unwrap())
            .unwrap();
        let image = session.render(&settings, 1).unwrap();
        assert_eq!((image.width, image.height), (width, height));
        assert!(
            image.pixels.iter().flatten().all(|v| v.is_finite()),
            "{traversal:?}: every pixel written, none NaN"
        );
        let shown = image.pixels.iter().filter(|p| p[3] > 0.0).count();
        assert!(
            shown > 10_000 && shown < image.pixels.len() / 10,
            "{traversal:?}: the data covers {shown} pixels"
        );
        let bg = settings.background;
        for p in [&image.pixels[0], image.pixels.last().unwrap()] {
            assert_eq!(
                [p[0], p[1], p[2], p[3]],
                [bg[0] as f32, bg[1] as f32, bg[2] as f32, 0.0],
                "{traversal:?}: a corner is the background"
            );
        }
    }
    assert_no_driver_messages();
}

/// The voxel baseline's grid of a cube at 1024³ (16 GiB, 2^32 words) is more than the device
/// allocates (lavapipe: 2 GiB) or the kernels index: refused before anything is allocated;
/// the same cube's 16³ grid is made.
#[test]
fn a_voxel_grid_beyond_the_allocation_limit_is_refused() {
    use crate::voxel_baseline as voxel;
    use aarbf::backend::Precision;
    use aarbf::backend::voxel::MAX_GRID;
    let corners: Vec<DVec3> = (0..8)
        .map(|i| DVec3::new((i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64))
        .collect();
    let cube = aarbf::scene::TimeSeries::from_steps(vec![Step {
        name: "cube".into(),
        attributes: vec![Attribute {
            name: "a".into(),
            values: (0..8).map(f64::from).collect(),
        }],
        positions: corners,
    }]);
    let field = FieldSettings::new(Some("a"), 0.06);
    let (_, frame) = voxel::frame_of(&cube, &field, &Default::default());
    let mut b = backend();
    voxel::upload(&mut b, &cube, &field, 4, Precision::RENDER);
    let e = b.voxelize(&frame, MAX_GRID).unwrap_err().to_string();
    assert!(
        e.contains("maxMemoryAllocationSize") || e.contains("2^32 words"),
        "{e}"
    );
    b.voxelize(&frame, 16).unwrap();
    assert_eq!(b.voxel_grid().unwrap().dims(), [16, 16, 16]);
    assert_no_driver_messages();
}
