//! The ash (Vulkan ray-tracing) backend against the CPU f64 reference, on whatever Vulkan
//! device with ray-tracing pipelines this machine has (lavapipe in CI).
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
use aarbf::scene::maps::{DensityMap, RadiusMap};
use aarbf::values::Image;
use aarbf::values::{Attribute, Bounds, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common;

/// A backend on the shared ray-tracing device (the test fails without one).
fn backend() -> AshBackend {
    common::require(
        "a Vulkan device with ray-tracing pipelines",
        AshBackend::new(),
    )
}

fn assert_no_validation_messages() {
    let messages = ash_rt::validation_messages();
    assert!(
        messages.is_empty(),
        "{} validation message(s):\n{}",
        messages.len(),
        messages.join("\n")
    );
}

/// `n` random particles in a box far from the origin (so local coordinates matter), with an
/// attribute `s` and a radius attribute `h` (some zeros).
fn random_step(n: usize, seed: u64) -> Step {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let centre = DVec3::new(1000.0, -50.0, 3.0);
    let positions = (0..n)
        .map(|_| centre + DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0)
        .collect();
    let s = (0..n).map(|_| rng.random_range(-3.0f64..5.0)).collect();
    let h = (0..n)
        .map(|_| {
            if rng.random::<f64>() < 0.1 {
                0.0
            } else {
                rng.random_range(0.5f64..1.5)
            }
        })
        .collect();
    Step {
        name: format!("random{seed}"),
        positions,
        attributes: vec![
            Attribute {
                name: "s".into(),
                values: s,
            },
            Attribute {
                name: "h".into(),
                values: h,
            },
        ],
    }
}

/// A radius map that is 0 below t = 0.2 (on the 256-sample table grid, so the GPU's table and
/// the CPU's exact map agree).
fn radius_map_with_zeros() -> RadiusMap {
    RadiusMap("0:0,0.2:0,0.6:1,1:0.5".parse().unwrap())
}

fn input<'a>(step: &'a Arc<Step>, field: &'a FieldSettings, k: u32) -> StepInput<'a> {
    StepInput {
        step,
        field,
        cluster: ClusterSize::new(k).unwrap(),
        series_bounds: step.bounds(),
        series_range: None,
        precision: aarbf::backend::Precision::FIELD,
    }
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
    // Nothing uploaded: errors, not panics.
    let mut b = b;
    assert!(b.query(&[DVec3::ZERO]).is_err());
    assert!(b.image().is_err());
    assert!(b.build().is_err());
    assert!(b.refit(&FieldSettings::new(None, 1.0)).is_err());
    // More particles than the device can allocate: a clear error naming need and limit.
    let step = std::sync::Arc::new(random_step(10, 1));
    let field = FieldSettings::new(Some("s"), 0.1);
    b.reserve(1 << 40);
    let e = b.upload(&input(&step, &field, 1)).unwrap_err().to_string();
    assert!(
        e.contains("1099511627776 particles") && e.contains("allocates at most"),
        "{e}"
    );
    // An empty step uploads, builds and queries to zero.
    let mut b = backend();
    let empty = Arc::new(Step {
        name: "empty".into(),
        positions: vec![],
        attributes: vec![Attribute {
            name: "s".into(),
            values: vec![],
        }],
    });
    b.upload(&input(&empty, &field, 4)).unwrap();
    b.build().unwrap();
    assert_eq!(b.query(&[DVec3::ZERO]).unwrap(), vec![(0.0, [0.0; 3])]);
    assert_no_validation_messages();
}

/// The box kernel's boxes equal its CPU twin's (`cpu::blas_boxes::blas_boxes`, the same f32
/// rule) to an ulp, contain the CPU's (f64, outward-rounded) cluster boxes and exceed them by
/// no more than the padding; clusters whose particles all have radius 0 get a degenerate box at
/// their first particle; clusters past the step are NaN.
#[test]
fn boxes_match_the_cpu_cluster_boxes() {
    let mut b = backend();
    let step = std::sync::Arc::new(random_step(1237, 1));
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
    assert_no_validation_messages();
}

/// Compares GPU sums with the f64 reference at `points`: Phi and each Theta-numerator
/// component within `1e-4 Phi + 1e-6`. Where that budget goes: f32 local coordinates of
/// particles and queries (d²/r² to ~5e-6 relative, so a term's exp to ~2e-5), f32 sums, and
/// for pre-classification the colour map's 256-sample table, which the GPU interpolates where
/// the reference evaluates the map exactly (measured ≤ 6e-5 for viridis; Phi itself agrees to
/// ~3e-6). A query within 1e-5 r of some particle's radius boundary may legitimately differ by
/// a whole term (f32 decides in or out there); such queries are excused, and must be rare
/// (≤ 0.5%). Returns the largest relative error seen.
fn compare_sums(
    reference: &ReferenceField,
    points: &[DVec3],
    got: &[(f64, [f64; 3])],
    what: &str,
) -> f64 {
    assert_eq!(got.len(), points.len());
    let p = &reference.particles;
    let mut worst: f64 = 0.0;
    let mut excused = 0;
    let mut non_zero = 0;
    for (i, (&x, g)) in points.iter().zip(got).enumerate() {
        let (phi, num) = reference.eval_sums(x);
        if phi > 0.0 {
            non_zero += 1;
        }
        assert!(
            g.0.is_finite() && g.1.iter().all(|v| v.is_finite()),
            "{what}: query {i} at {x}: not finite (unwritten?): {g:?}"
        );
        let tol = 1e-4 * phi + 1e-6;
        let err = (g.0 - phi)
            .abs()
            .max((0..3).map(|c| (g.1[c] - num[c]).abs()).fold(0.0, f64::max));
        if err > tol {
            let near_boundary = (0..p.len()).any(|j| {
                let r = p.radii[j];
                r > 0.0 && ((x - p.origin - p.centers[j]).length() - r).abs() <= 1e-5 * r.max(1e-3)
            });
            assert!(
                near_boundary,
                "{what}: query {i} at {x}: GPU {g:?}, CPU ({phi}, {num:?}), error {err:e} > {tol:e}"
            );
            excused += 1;
            continue;
        }
        worst = worst.max(err / phi.max(1e-30));
    }
    assert!(
        excused * 200 <= points.len(),
        "{what}: {excused} of {} queries differ near a radius boundary",
        points.len()
    );
    assert!(
        non_zero * 2 > points.len(),
        "{what}: most queries see particles ({non_zero} of {})",
        points.len()
    );
    worst
}

/// Query points: every particle centre and as many random points in the bounds.
fn queries(step: &Step, seed: u64) -> Vec<DVec3> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let b = step.bounds();
    let mut q: Vec<DVec3> = step.positions.clone();
    for _ in 0..step.len() {
        let t = DVec3::new(rng.random(), rng.random(), rng.random());
        q.push(b.min + t * (b.max - b.min));
    }
    q
}

#[test]
fn queries_match_the_f64_reference_for_every_cluster_size() {
    let mut b = backend();
    let step = std::sync::Arc::new(random_step(1500, 2));
    let points = queries(&step, 3);
    let mut worst: f64 = 0.0;
    for k in [1, 2, 4, 8, 16] {
        for classification in [Classification::Post, Classification::Pre] {
            let mut field = FieldSettings::new(Some("s"), 0.2);
            field.classification = classification;
            field.radius_map = radius_map_with_zeros();
            if classification == Classification::Post {
                // Per-particle radii (with zeros) and a varying density map.
                field.radius_attribute = Some("h".into());
                field.density_map = DensityMap("0:0.5,1:1".parse().unwrap());
            }
            b.upload(&input(&step, &field, k)).unwrap();
            b.build().unwrap();
            let got = b.query(&points).unwrap();
            let reference = ReferenceField::of_step(
                &step,
                &field,
                ClusterSize::new(k).unwrap(),
                step.bounds(),
                None,
            )
            .unwrap();
            let what = format!("K = {k}, {classification:?}");
            let e = compare_sums(&reference, &points, &got, &what);
            eprintln!("{what}: max relative error {e:.2e}");
            worst = worst.max(e);
        }
    }
    eprintln!("worst relative error over all: {worst:.2e}");
    assert_no_validation_messages();
}

/// The paper's per-particle hit reports (selectable for the traversal study) give what the
/// default per-cluster sums give, on a driver (lavapipe) that calls any-hit for every report
/// of a box; double-single positions in both.
#[test]
fn per_particle_hit_reports_match_per_cluster_sums() {
    use aarbf::backend::ash_rt::HitReports;
    let mut b = backend();
    let step = std::sync::Arc::new(random_step(1200, 21));
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
    assert_no_validation_messages();
}

/// A refit after a radius change (global radius, radius map with zeros moving, radius attribute
/// switched on) gives the field a fresh build gives, and both match the reference.
#[test]
fn refit_after_a_radius_change_equals_a_fresh_build() {
    let mut refitted = backend();
    let mut fresh = backend();
    let step = std::sync::Arc::new(random_step(1400, 4));
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
    assert_no_validation_messages();
}

fn dambreak() -> aarbf::scene::TimeSeries {
    use aarbf::scene::synth::Generator;
    aarbf::scene::TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1))
}

/// A view close to the fluid, so most pixels see it.
fn close_view(series: &aarbf::scene::TimeSeries) -> aarbf::scene::Camera {
    let b = series.bounds();
    aarbf::scene::Camera {
        eye: DVec3::new(0.9, 0.45, 1.1),
        at: DVec3::new(0.55, 0.12, 0.5 * b.max.z),
        up: DVec3::Y,
        fovy: 35.0,
    }
}

/// Mean FLIP between two images (sRGB 8-bit, default viewing distance).
fn flip(reference: &Image, test: &Image) -> (f32, nv_flip::FlipImageFloat) {
    let rgb =
        |i: &Image| nv_flip::FlipImageRgb8::with_data(i.width, i.height, &i.to_srgb8().into_raw());
    let error = nv_flip::flip(
        rgb(reference),
        rgb(test),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&error).mean();
    (mean, error)
}

/// Writes `<name>-actual.png`, `-expected.png` and `-difference.png` (FLIP error through the
/// magma map) under the target directory, and returns where.
fn write_failure(
    name: &str,
    expected: &Image,
    actual: &Image,
    error: &nv_flip::FlipImageFloat,
) -> String {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("ash-images");
    std::fs::create_dir_all(&dir).unwrap();
    aarbf::io::output::write_png(&dir.join(format!("{name}-actual.png")), actual, true).unwrap();
    aarbf::io::output::write_png(&dir.join(format!("{name}-expected.png")), expected, true)
        .unwrap();
    let diff = error.apply_color_lut(&nv_flip::magma_lut());
    image::RgbImage::from_raw(diff.width(), diff.height(), diff.to_vec())
        .unwrap()
        .save(dir.join(format!("{name}-difference.png")))
        .unwrap();
    dir.display().to_string()
}

/// Compares `actual` with `expected` by RMSE and mean FLIP; on failure writes the images.
fn assert_images_close(name: &str, expected: &Image, actual: &Image, max_rmse: f64, max_flip: f32) {
    assert!(
        actual
            .pixels
            .iter()
            .all(|p| p.iter().all(|v| v.is_finite())),
        "{name}: non-finite pixels (unwritten?)"
    );
    let rmse = actual.rmse(expected);
    let (mean_flip, error) = flip(expected, actual);
    eprintln!("{name}: RMSE {rmse:.2e}, mean FLIP {mean_flip:.2e}");
    if rmse > max_rmse || mean_flip > max_flip {
        let dir = write_failure(name, expected, actual, &error);
        panic!(
            "{name}: RMSE {rmse:.3e} (limit {max_rmse:.1e}), mean FLIP {mean_flip:.3e} (limit {max_flip:.1e}); images in {dir}"
        );
    }
}

/// The ash backend's images against the CPU backend's at equal spp and seed, per integrator.
#[test]
fn renders_match_the_cpu_backend() {
    use aarbf::backend::{self, BackendKind};
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::values::{Integrator, NoiseKind};
    let series = dambreak();
    let mut field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let k = ClusterSize::new(4).unwrap();
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    let mut gpu = RenderSession::new(backend::create(BackendKind::Ash).unwrap(), &series);
    assert_eq!(gpu.backend().capabilities().name, "ash");
    // (integrator, noise, classification, frames, blur, RMSE limit, FLIP limit). EA and
    // stochastic marching make the same decisions from the same random numbers on both, so
    // f32-versus-f64 rounding is all that differs (measured: RMSE < 1e-6, FLIP < 1e-4). Delta
    // tracking on the CPU skips empty space between particle boxes (the same distribution from
    // other random numbers per pixel), so it is compared at 64 spp through a 1-pixel Gaussian
    // blur, where what is left is Monte Carlo noise (measured: RMSE ~3e-3).
    let cases = [
        (
            Integrator::Ea,
            NoiseKind::Stbn,
            Classification::Post,
            2,
            false,
            1e-4,
            1e-3,
        ),
        (
            Integrator::Ea,
            NoiseKind::White,
            Classification::Pre,
            2,
            false,
            1e-4,
            1e-3,
        ),
        (
            Integrator::Marching,
            NoiseKind::Stbn,
            Classification::Post,
            2,
            false,
            1e-3,
            5e-3,
        ),
        (
            Integrator::Delta,
            NoiseKind::White,
            Classification::Post,
            64,
            true,
            1e-2,
            4e-2,
        ),
    ];
    for (integrator, noise, classification, frames, blur, max_rmse, max_flip) in cases {
        field.classification = classification;
        let settings = RenderSettings {
            width: 64,
            height: 48,
            integrator,
            noise,
            seed: 3,
            camera: Some(close_view(&series)),
            ..RenderSettings::default()
        };
        cpu.show(&series, 7, &field, k).unwrap();
        gpu.show(&series, 7, &field, k).unwrap();
        let expected = cpu.render(&settings, frames).unwrap();
        let actual = gpu.render(&settings, frames).unwrap();
        let covered = expected.pixels.iter().filter(|p| p[3] > 0.0).count();
        assert!(
            covered > 600,
            "the fluid covers much of the image: {covered} pixels"
        );
        let name = format!("{integrator:?}-{noise:?}-{classification:?}").to_lowercase();
        let (expected, actual) = if blur {
            (expected.blurred(1.0), actual.blurred(1.0))
        } else {
            (expected, actual)
        };
        assert_images_close(&name, &expected, &actual, max_rmse, max_flip);
    }
    assert_no_validation_messages();
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
    assert_no_validation_messages();
}

/// The software traversal on the same device (the LBVH compute pipeline, Fig. 10a's other
/// side) gives the RT pipeline's field and images: same particles, RBF code and integrators.
#[test]
fn lbvh_traversal_on_the_same_device_matches_the_rt_pipeline() {
    use aarbf::backend::ash_rt::Traversal;
    use aarbf::render::{RenderSession, RenderSettings};
    use aarbf::values::{Integrator, NoiseKind};
    let mut b = backend();
    let step = std::sync::Arc::new(random_step(1300, 6));
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
    assert_no_validation_messages();
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
    assert_no_validation_messages();
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
    assert_no_validation_messages();
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
    let step = random_step(1300, 8);
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
    assert_no_validation_messages();
}

/// Preparing a step on the device equals the CPU preparation bit for bit (order, positions
/// with t, lo parts, radius attribute; the order is `hilbert_order`), for a series of awkward,
/// changing counts far from the origin with and without a radius attribute and double-single
/// positions, the outputs poisoned before each step; and after field changes that gather a new
/// radius attribute and lo parts through the kept order. Twice: reading the staged step in
/// place (lavapipe's memory is device-local and host-visible, as an integrated GPU's or one
/// with resizable BAR) and through the copies a discrete GPU needs.
#[test]
fn device_preparation_equals_the_cpu_preparation() {
    let in_place = device_preparation_equals_the_cpu_preparation_on(backend());
    let mut b = backend();
    b.always_copy_staging();
    let copied = device_preparation_equals_the_cpu_preparation_on(b);
    // Same capacity and arrays: the copies' device arrays are the only difference.
    assert!(
        in_place < copied,
        "staging read in place holds {in_place} B, through copies {copied} B"
    );
}

/// Runs the checks; the preparation's bytes at the end.
fn device_preparation_equals_the_cpu_preparation_on(mut b: AshBackend) -> usize {
    use aarbf::accel::hilbert_order;
    use aarbf::backend::Precision;

    let bounds = Bounds {
        min: DVec3::new(1000.0, -50.0, 3.0),
        max: DVec3::new(1002.0, -48.0, 5.0),
    };
    b.reserve(1_000_003);
    let plain = FieldSettings::new(Some("s"), 0.02);
    let mut with_radius = plain.clone();
    with_radius.radius_attribute = Some("h".into());
    let check = |b: &mut AshBackend, input: &StepInput<'_>, what: &str| {
        let (_, cpu) = GpuStepData::prepare(input).unwrap();
        let gpu = b.sorted_particles().unwrap();
        assert!(
            gpu.order == hilbert_order(&input.step.positions, input.series_bounds),
            "{what}: the device's order is not hilbert_order"
        );
        let bits =
            |v: &[[f32; 4]]| -> Vec<[u32; 4]> { v.iter().map(|p| p.map(f32::to_bits)).collect() };
        assert!(bits(&gpu.points) == bits(&cpu.points), "{what}: points");
        assert_eq!(gpu.points_lo.is_some(), cpu.points_lo.is_some(), "{what}");
        if let (Some(g), Some(c)) = (&gpu.points_lo, &cpu.points_lo) {
            assert!(bits(g) == bits(c), "{what}: lo parts");
        }
        assert_eq!(
            gpu.radius_attribute, cpu.radius_attribute,
            "{what}: radius attribute"
        );
    };
    for (i, n) in [65537usize, 0, 1, 255, 257, 1_000_003, 4097]
        .into_iter()
        .enumerate()
    {
        let step = Arc::new(random_step(n, 800 + i as u64));
        let (field, precision) = match i % 3 {
            0 => (&plain, Precision::RENDER),
            1 => (&with_radius, Precision::RENDER),
            _ => (&with_radius, Precision::DoubleSingle),
        };
        let input = StepInput {
            step: &step,
            field,
            cluster: ClusterSize::new(4).unwrap(),
            series_bounds: bounds,
            series_range: Some((-3.0, 5.0)),
            precision,
        };
        if i > 0 {
            b.poison_prepared().unwrap();
        }
        b.upload(&input).unwrap();
        check(&mut b, &input, &format!("step {i} ({n} particles)"));
    }

    let step = Arc::new(random_step(70_001, 900));
    let wide = FieldSettings::new(Some("s"), 0.3);
    let input = |field| StepInput {
        step: &step,
        field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: bounds,
        series_range: Some((-3.0, 5.0)),
        precision: Precision::RENDER,
    };
    b.upload(&input(&wide)).unwrap();
    b.build().unwrap();
    let mut tiny = wide.clone();
    tiny.radius = 1e-5;
    tiny.radius_attribute = Some("h".into());
    b.refit(&tiny).unwrap();
    check(&mut b, &input(&tiny), "after a refit that needs lo parts");
    assert!(
        b.representation().map(|r| r.positions)
            == Some(aarbf::backend::precision::PositionKind::DoubleSingle),
        "the tiny radii need double-single positions"
    );
    assert_no_validation_messages();
    b.memory().preparation_bytes
}

/// The preparation's stages on the ash device against their CPU twins, outputs poisoned
/// first, at awkward sizes: the Hilbert keys of f32 local coordinates far from the origin
/// (bit for bit, with the identity permutation), and the radix sort of random keys and of
/// keys with few distinct values (stability decides their order).
#[test]
fn preparation_stages_equal_their_cpu_twins() {
    use aarbf::accel::HilbertQuantizer;
    use aarbf::backend::shaders::cpu::{hilbert_keys, radix_sort};

    let mut b = backend();
    let bounds = Bounds {
        min: DVec3::new(1000.0, -50.0, 3.0),
        max: DVec3::new(1002.0, -48.0, 5.0),
    };
    let q = HilbertQuantizer::new(bounds);
    for (i, n) in [0usize, 1, 255, 257, 65537, 1_000_003]
        .into_iter()
        .enumerate()
    {
        let step = random_step(n, 1000 + i as u64);
        let points: Vec<[f32; 4]> = step
            .positions
            .iter()
            .map(|&p| {
                let [x, y, z] = q.local(p);
                [x, y, z, 0.25]
            })
            .collect();
        let (keys, values) = b.prepare_hilbert_keys(&points, &q).unwrap();
        assert!(
            keys == hilbert_keys::hilbert_keys(&points, &q),
            "n {n}: keys differ from the twin's"
        );
        assert!(
            values.iter().enumerate().all(|(i, &v)| v as usize == i),
            "n {n}"
        );

        let mut rng = rand_pcg::Pcg64::seed_from_u64(2000 + i as u64);
        for few in [false, true] {
            let keys: Vec<u32> = (0..n)
                .map(|_| match few {
                    false => rng.random(),
                    true => rng.random_range(0..13u32) << 20,
                })
                .collect();
            assert!(
                b.prepare_sort_pairs(&keys).unwrap() == radix_sort::sort_pairs(&keys),
                "n {n}, few distinct keys {few}: the sort differs from its twin"
            );
        }
    }
    assert_no_validation_messages();
}

/// Once the series' maximum is reserved, stepping makes no buffer: the staging memory, the
/// step's arrays, the sort's buffers, the BLAS and its scratch are all made by the first upload
/// and build (one with every optional array: a radius attribute and double-single positions)
/// and reused by steps of any count up to the reserved one.
#[test]
fn stepping_through_a_reserved_series_makes_no_buffers() {
    use aarbf::backend::Precision;

    let mut b = backend();
    b.reserve(20_000);
    let mut f = FieldSettings::new(Some("s"), 0.05);
    f.radius_attribute = Some("h".into());
    let bounds = Bounds {
        min: DVec3::new(1000.0, -50.0, 3.0),
        max: DVec3::new(1002.0, -48.0, 5.0),
    };
    for (i, n) in [20_000usize, 5_003, 19_999, 1, 0, 12_345]
        .into_iter()
        .enumerate()
    {
        let step = Arc::new(random_step(n, 1100 + i as u64));
        let before = ash_rt::resources::buffers_made();
        b.upload(&StepInput {
            step: &step,
            field: &f,
            cluster: ClusterSize::new(2).unwrap(),
            series_bounds: bounds,
            series_range: Some((-3.0, 5.0)),
            precision: Precision::DoubleSingle,
        })
        .unwrap();
        b.build().unwrap();
        let made = ash_rt::resources::buffers_made() - before;
        if i > 0 {
            assert_eq!(made, 0, "step {i} ({n} particles) made {made} buffers");
        } else {
            assert!(made > 0, "the counter counts");
        }
    }
    assert_no_validation_messages();
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
    assert_no_validation_messages();
}
