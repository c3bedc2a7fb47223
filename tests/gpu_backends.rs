//! What every GPU backend must do, checked on each (`NAME::ash`, `NAME::wgpu`): prepare a step
//! on the device as the CPU prepares it, stage by stage and as a whole; step through a reserved
//! series without making buffers; refuse misuse with errors; answer queries as the f64
//! reference field does; and render the CPU backend's images. One backend's own mechanisms
//! (ash's BLAS and hit reports, wgpu's tree stages and split bindings) are checked in its own
//! file (`ash_rt`, `wgpu_lbvh`), with the data and checks defined here.
//!
//! Every GPU output the device prepares is poisoned (0xFF bytes) before the run that writes it;
//! inputs are random data of awkward sizes. Each backend's tests share its one device, so each
//! pipeline variant is compiled once; the validation layer is on (the `checked` profile has
//! debug assertions) when installed, and the tests end by asserting that it reported nothing.
//!
//! Tolerances of the queries (why each is what it is), in two scenes:
//! - [`compare_sums`] (particles in a box at 1000): Phi and each Theta-numerator component
//!   within `1e-4 Phi + 1e-6`, from f32 local coordinates of particles and queries (d²/r² to
//!   ~5e-6 relative, so a term's exp to ~2e-5) and f32 sums; a query within 1e-5 r of some
//!   particle's radius boundary is excused (f32 decides in or out there), rarely.
//! - [`check_queries`] (20,000 particles in the unit cube, with maps): |dPhi| <= 3e-4 Phi + 1e-6
//!   w_max and |dnum| <= 3e-4 Phi + 1e-6 w_max, from f32 positions relative to the radius (~1e-5)
//!   times the Gaussian's 4.5 d^2/r^2 slope; a query within 1e-4 r of some particle's sphere
//!   may differ by that particle's whole contribution (it lies on the cut-off in one precision
//!   and not the other), so those are checked against the sum of such contributions instead.

use std::sync::Arc;

use aarbf::accel::{ClusterSize, HilbertQuantizer, hilbert_order};
use aarbf::backend::gpu_data::GpuStepData;
use aarbf::backend::precision::PositionKind;
use aarbf::backend::shaders::cpu::lbvh::LBVH_EMPTY_KEY;
use aarbf::backend::shaders::cpu::{hilbert_keys, radix_sort};
use aarbf::backend::wgpu_lbvh::{GpuContext, WgpuBackend};
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::{Classification, FieldSettings, ReferenceField};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::maps::{DensityMap, RadiusMap};
use aarbf::scene::synth::Generator;
use aarbf::scene::{Camera, TimeSeries};
use aarbf::values::{Attribute, Bounds, Image, Integrator, NoiseKind, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::common::{self, Gpu, GpuBackend, assert_no_driver_messages, on_every_gpu};

on_every_gpu!(
    device_preparation_equals_the_cpu_preparation,
    hilbert_keys_equal_their_twin_and_sort_to_the_hilbert_order,
    the_radix_sort_equals_a_stable_sort_by_key,
    stepping_through_a_reserved_series_makes_no_buffers,
    misuse_is_an_error_not_a_panic,
    queries_match_the_f64_reference_for_every_cluster_size,
    images_match_the_cpu_backend_at_equal_samples_and_seed,
);

// Scenes.

/// How a test makes a step of `n` particles from a seed.
pub(crate) type MakeStep = fn(usize, u64) -> Step;

/// `n` random particles in a 2-unit box far from the origin (so local coordinates matter),
/// inside [`BOX_BOUNDS`], with an attribute `s` in -3..5 and a radius attribute `h` (some
/// zeros).
pub(crate) fn box_step(n: usize, seed: u64) -> Step {
    let mut rng = Pcg64::seed_from_u64(seed);
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

/// The series' bounds of the box steps (every step lies inside).
pub(crate) const BOX_BOUNDS: Bounds = Bounds {
    min: DVec3::new(1000.0, -50.0, 3.0),
    max: DVec3::new(1002.0, -48.0, 5.0),
};

pub(crate) fn rng(seed: u64) -> Pcg64 {
    Pcg64::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15)
}

/// `n` particles: uniform in the unit cube, or (clumped) in a few tiny blobs that give many
/// equal Morton keys; attribute `a` uniform in [0, 1], radius factor `h` in [0.5, 1.5].
pub(crate) fn unit_cube_step(n: usize, seed: u64, clumped: bool) -> Step {
    let mut r = rng(seed);
    let centres: Vec<DVec3> = (0..5)
        .map(|_| DVec3::new(r.random(), r.random(), r.random()))
        .collect();
    let positions = (0..n)
        .map(|_| {
            if clumped {
                centres[r.random_range(0..centres.len())]
                    + DVec3::new(r.random(), r.random(), r.random()) * 1e-4
            } else {
                DVec3::new(r.random(), r.random(), r.random())
            }
        })
        .collect();
    Step {
        name: format!("random{n}"),
        positions,
        attributes: vec![
            Attribute {
                name: "a".into(),
                values: (0..n).map(|_| r.random::<f64>()).collect(),
            },
            Attribute {
                name: "h".into(),
                values: (0..n).map(|_| r.random_range(0.5..1.5f64)).collect(),
            },
        ],
    }
}

/// `n` particles as a simulation writes them: f64 positions far from the origin in a box of
/// unequal sides (no f32-exact coordinates), an attribute `a` over [1000, 1001] and a radius
/// attribute `h` in [0.5, 1.5].
pub(crate) fn simulation_step(n: usize, seed: u64) -> Step {
    let mut r = rng(seed);
    let offset = DVec3::new(3.0e6, -1.25e5, 42.0);
    let side = DVec3::new(17.0, 3.5, 9.25);
    Step {
        name: format!("simulation{n}"),
        positions: (0..n)
            .map(|_| offset + DVec3::new(r.random(), r.random(), r.random()) * side)
            .collect(),
        attributes: vec![
            Attribute {
                name: "a".into(),
                values: (0..n).map(|_| 1000.0 + r.random::<f64>()).collect(),
            },
            Attribute {
                name: "h".into(),
                values: (0..n).map(|_| r.random_range(0.5..1.5f64)).collect(),
            },
        ],
    }
}

/// The series' bounds of the simulation steps (every step lies inside).
pub(crate) const SIMULATION_BOUNDS: Bounds = Bounds {
    min: DVec3::new(3.0e6, -1.25e5, 42.0),
    max: DVec3::new(3.0e6 + 17.0, -1.25e5 + 3.5, 42.0 + 9.25),
};

/// A simulation step as a backend receives it: cluster size 4, the series' bounds and range.
pub(crate) fn simulation_input<'a>(
    step: &'a Arc<Step>,
    field: &'a FieldSettings,
    precision: Precision,
) -> StepInput<'a> {
    StepInput {
        step,
        field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: SIMULATION_BOUNDS,
        series_range: Some((1000.0, 1001.0)),
        precision,
    }
}

/// The dam break's demo: 3000 particles, 8 steps.
pub(crate) fn dambreak() -> TimeSeries {
    TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1))
}

/// A view close to the fluid, so most pixels see it.
pub(crate) fn close_view(series: &TimeSeries) -> Camera {
    let b = series.bounds();
    Camera {
        eye: DVec3::new(0.9, 0.45, 1.1),
        at: DVec3::new(0.55, 0.12, 0.5 * b.max.z),
        up: DVec3::Y,
        fovy: 35.0,
    }
}

// Fields and how a backend receives a step.

/// A radius map that is 0 below t = 0.2 (on the 256-sample table grid, so the GPU's table and
/// the CPU's exact map agree).
pub(crate) fn radius_map_with_zeros() -> RadiusMap {
    RadiusMap("0:0,0.2:0,0.6:1,1:0.5".parse().unwrap())
}

/// A field over `a` with radius `radius`; with `varying_maps`, maps whose control points lie
/// off the tables' sample grid (every backend and the reference look maps up in the same
/// tables, so they agree whatever the points), and radius 0 for t < 0.21.
pub(crate) fn maps_field(radius: f64, varying_maps: bool) -> FieldSettings {
    let mut f = FieldSettings::new(Some("a"), radius);
    if varying_maps {
        f.radius_map = RadiusMap::new("0:0,0.21:0,0.633:1,1:0.6".parse().unwrap()).unwrap();
        f.density_map = DensityMap::new("0:0.5,0.333:2,0.71:0.2,1:1".parse().unwrap()).unwrap();
    }
    f
}

/// `step` as a backend receives it alone: its own bounds, no series range, cluster size `k`.
pub(crate) fn input<'a>(step: &'a Arc<Step>, field: &'a FieldSettings, k: u32) -> StepInput<'a> {
    StepInput {
        step,
        field,
        cluster: ClusterSize::new(k).unwrap(),
        series_bounds: step.bounds(),
        series_range: None,
        precision: Precision::FIELD,
    }
}

/// The step's bounds, or the unit cube for an empty step.
pub(crate) fn bounds_of(step: &Step) -> Bounds {
    let b = step.bounds();
    if b.is_empty() {
        Bounds {
            min: DVec3::ZERO,
            max: DVec3::ONE,
        }
    } else {
        b
    }
}

/// Uploads a unit-cube step (attribute range [0, 1]) with cluster size `k`.
pub(crate) fn upload(backend: &mut dyn Backend, step: &Arc<Step>, field: &FieldSettings, k: u32) {
    backend
        .upload(&StepInput {
            step,
            field,
            cluster: ClusterSize::new(k).unwrap(),
            series_bounds: bounds_of(step),
            series_range: Some((0.0, 1.0)),
            precision: Precision::FIELD,
        })
        .unwrap();
}

// Checks.

/// What the device prepared (read back) equals the CPU preparation bit for bit: order,
/// positions with t, lo parts, radius attribute, and (wgpu, which shows it) the step's data;
/// the order is `hilbert_order`.
pub(crate) fn assert_prepared_like_the_cpu(b: &mut GpuBackend, input: &StepInput<'_>, what: &str) {
    let (data, cpu) = GpuStepData::prepare(input).unwrap();
    let gpu = b.sorted_particles();
    assert!(
        gpu.order == hilbert_order(&input.step.positions, input.series_bounds),
        "{what}: the device's order is not hilbert_order"
    );
    assert!(gpu.order == cpu.order, "{what}: order");
    let bits =
        |v: &[[f32; 4]]| -> Vec<[u32; 4]> { v.iter().map(|p| p.map(f32::to_bits)).collect() };
    assert!(bits(&gpu.points) == bits(&cpu.points), "{what}: points");
    assert_eq!(
        gpu.points_lo.is_some(),
        cpu.points_lo.is_some(),
        "{what}: lo parts"
    );
    if let (Some(g), Some(c)) = (&gpu.points_lo, &cpu.points_lo) {
        assert!(bits(g) == bits(c), "{what}: lo parts");
    }
    assert_eq!(
        gpu.radius_attribute, cpu.radius_attribute,
        "{what}: radius attribute"
    );
    if let GpuBackend::Wgpu(w) = b {
        assert_eq!(w.step_data(), Some(&data), "{what}: step data");
    }
}

/// Whether the backend holds its positions as double-single pairs.
fn double_single(b: &GpuBackend) -> bool {
    b.representation().map(|r| r.positions) == Some(PositionKind::DoubleSingle)
}

/// Compares GPU sums with the f64 reference at `points`: Phi and each Theta-numerator
/// component within `1e-4 Phi + 1e-6`. Where that budget goes: f32 local coordinates of
/// particles and queries (d²/r² to ~5e-6 relative, so a term's exp to ~2e-5), f32 sums, and
/// for pre-classification the colour map's 256-sample table, which the GPU interpolates where
/// the reference evaluates the map exactly (measured ≤ 6e-5 for viridis; Phi itself agrees to
/// ~3e-6). A query within 1e-5 r of some particle's radius boundary may legitimately differ by
/// a whole term (f32 decides in or out there); such queries are excused, and must be rare
/// (≤ 0.5%). Returns the largest relative error seen.
pub(crate) fn compare_sums(
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
pub(crate) fn queries(step: &Step, seed: u64) -> Vec<DVec3> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let b = step.bounds();
    let mut q: Vec<DVec3> = step.positions.clone();
    for _ in 0..step.len() {
        let t = DVec3::new(rng.random(), rng.random(), rng.random());
        q.push(b.min + t * (b.max - b.min));
    }
    q
}

/// Uploads the unit-cube `step` to `b` (fresh), builds, and compares queries at random points
/// and at particle centres with the f64 reference.
pub(crate) fn check_queries(
    b: &mut dyn Backend,
    step: &Arc<Step>,
    f: &FieldSettings,
    k: u32,
    what: &str,
) {
    let cluster = ClusterSize::new(k).unwrap();
    upload(b, step, f, k);
    b.build().unwrap();
    let reference =
        ReferenceField::of_step(step, f, cluster, bounds_of(step), Some((0.0, 1.0))).unwrap();
    let mut r = rng(u64::from(k) * 7 + 3);
    let mut points: Vec<DVec3> = (0..6000)
        .map(|_| DVec3::new(r.random(), r.random(), r.random()) * 1.1 - DVec3::splat(0.05))
        .collect();
    points.extend(step.positions.iter().step_by(7).copied());
    let got = b.query(&points).unwrap();
    assert_eq!(got.len(), points.len());
    let p = &reference.particles;
    let w_max = p.weights.iter().fold(0.0f64, |m, w| m.max(*w));
    let mut nonzero = 0;
    let mut ambiguous = 0;
    for (x, (phi, num)) in points.iter().zip(&got) {
        let (rphi, rnum) = reference.eval_sums(*x);
        if rphi > 0.0 {
            nonzero += 1;
        }
        let tol_phi = 3e-4 * rphi + 1e-6 * w_max;
        let tol_num = 3e-4 * rphi + 1e-6 * w_max;
        let ok =
            (phi - rphi).abs() <= tol_phi && (0..3).all(|c| (num[c] - rnum[c]).abs() <= tol_num);
        if ok {
            continue;
        }
        // On a sphere's edge in one precision and not the other: bound by those particles.
        let edge: f64 = (0..p.len())
            .filter(|&i| {
                let d = (*x - p.origin - p.centers[i]).length();
                p.radii[i] > 0.0 && (d - p.radii[i]).abs() <= 1e-4 * p.radii[i]
            })
            .map(|i| p.weights[i] * (-4.5f64).exp() * 1.01)
            .sum();
        assert!(
            edge > 0.0 && (phi - rphi).abs() <= tol_phi + edge,
            "{what}: at {x}: gpu ({phi}, {num:?}) vs reference ({rphi}, {rnum:?})"
        );
        ambiguous += 1;
    }
    if !step.is_empty() {
        assert!(
            nonzero > points.len() / 4,
            "{what}: most queries see particles ({nonzero})"
        );
    }
    assert!(
        ambiguous < points.len() / 100,
        "{what}: {ambiguous} edge cases"
    );
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
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("gpu-images");
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

/// Compares `actual` with `expected` by RMSE (linear RGB) and mean FLIP; on failure writes the
/// images.
pub(crate) fn assert_images_close(
    name: &str,
    expected: &Image,
    actual: &Image,
    max_rmse: f64,
    max_flip: f32,
) {
    assert!(
        actual
            .pixels
            .iter()
            .all(|p| p.iter().all(|v| v.is_finite())),
        "{name}: non-finite pixels (unwritten?)"
    );
    let rmse = actual.rmse(expected);
    let (mean_flip, error) = flip(expected, actual);
    eprintln!(
        "{name}: RMSE {rmse:.2e} (limit {max_rmse:.1e}), mean FLIP {mean_flip:.2e} (limit {max_flip:.1e})"
    );
    if rmse > max_rmse || mean_flip > max_flip {
        let dir = write_failure(name, expected, actual, &error);
        panic!(
            "{name}: RMSE {rmse:.3e} (limit {max_rmse:.1e}), mean FLIP {mean_flip:.3e} (limit {max_flip:.1e}); images in {dir}"
        );
    }
}

// The tests.

/// A backend of `gpu` that copies every step from staging memory to device memory before
/// preparing it, as a discrete GPU must, even where the device could read the staging memory
/// in place (lavapipe's memory is device-local and host-visible, as an integrated GPU's or one
/// with resizable BAR).
fn copying_staging(gpu: Gpu) -> GpuBackend {
    match gpu {
        Gpu::Ash => {
            let mut b = gpu.backend();
            if let GpuBackend::Ash(ash) = &mut b {
                ash.always_copy_staging();
            }
            b
        }
        Gpu::Wgpu => {
            let shared = common::wgpu_context();
            let mut copying = GpuContext::with_limits(shared.limits.clone()).unwrap();
            copying.unified_memory = false;
            GpuBackend::Wgpu(Box::new(WgpuBackend::with_context(Arc::new(copying))))
        }
    }
}

/// A series the preparation is checked on: its steps, bounds and range, and its fields
/// without and with a radius attribute, and wide for a first build.
struct PreparedSeries {
    name: &'static str,
    step: MakeStep,
    first_seed: u64,
    refit_seed: u64,
    bounds: Bounds,
    range: (f64, f64),
    plain: FieldSettings,
    with_radius: FieldSettings,
    wide: FieldSettings,
}

fn prepared_series() -> [PreparedSeries; 2] {
    let plain = FieldSettings::new(Some("s"), 0.02);
    let mut with_radius = plain.clone();
    with_radius.radius_attribute = Some("h".into());
    let in_a_box = PreparedSeries {
        name: "box",
        step: box_step,
        first_seed: 800,
        refit_seed: 900,
        bounds: BOX_BOUNDS,
        range: (-3.0, 5.0),
        plain,
        with_radius,
        wide: FieldSettings::new(Some("s"), 0.3),
    };
    let mut with_radius = maps_field(0.01, true);
    with_radius.attribute_range = None;
    with_radius.radius_attribute = Some("h".into());
    let simulation = PreparedSeries {
        name: "simulation",
        step: simulation_step,
        first_seed: 400,
        refit_seed: 600,
        bounds: SIMULATION_BOUNDS,
        range: (1000.0, 1001.0),
        plain: FieldSettings::new(Some("a"), 0.01),
        with_radius,
        wide: FieldSettings::new(Some("a"), 0.2),
    };
    [in_a_box, simulation]
}

/// Preparing a step on the device equals the CPU preparation bit for bit (order, positions
/// with t, lo parts, radius attribute; the order is `hilbert_order`), for series of awkward,
/// changing counts far from the origin with and without a radius attribute and double-single
/// positions, the buffers reused (reserved for the largest) and poisoned before each step; and
/// after field changes that gather a new radius attribute and lo parts through the kept order.
/// Twice: reading the staged step in place where the device can, and through the copies a
/// discrete GPU needs.
fn device_preparation_equals_the_cpu_preparation(gpu: Gpu) {
    for series in prepared_series() {
        let in_place = preparation_bytes_of(gpu.backend(), &series);
        let copied = preparation_bytes_of(copying_staging(gpu), &series);
        // Same capacity and arrays: the copies' device arrays are the only difference.
        assert!(
            in_place < copied,
            "{}: staging read in place holds {in_place} B, through copies {copied} B",
            series.name
        );
    }
    assert_no_driver_messages();
}

/// Runs the preparation's checks on `series`; the preparation's bytes at the end.
fn preparation_bytes_of(mut b: GpuBackend, series: &PreparedSeries) -> usize {
    let name = series.name;
    b.reserve(1_000_003);
    for (i, n) in [65537usize, 0, 1, 255, 257, 1_000_003, 4097]
        .into_iter()
        .enumerate()
    {
        let step = Arc::new((series.step)(n, series.first_seed + i as u64));
        let (field, precision) = match i % 3 {
            0 => (&series.plain, Precision::RENDER),
            1 => (&series.with_radius, Precision::RENDER),
            _ => (&series.with_radius, Precision::DoubleSingle),
        };
        let input = StepInput {
            step: &step,
            field,
            cluster: ClusterSize::new(4).unwrap(),
            series_bounds: series.bounds,
            series_range: Some(series.range),
            precision,
        };
        if i > 0 {
            b.poison_prepared();
        }
        b.upload(&input).unwrap();
        assert_prepared_like_the_cpu(&mut b, &input, &format!("{name}: step {i} ({n} particles)"));
    }

    // Field changes keep the particles: a radius attribute appears, and radii small enough
    // to need double-single positions; the device gathers both through the order it kept.
    let step = Arc::new((series.step)(70_001, series.refit_seed));
    let input = |field| StepInput {
        step: &step,
        field,
        cluster: ClusterSize::new(4).unwrap(),
        series_bounds: series.bounds,
        series_range: Some(series.range),
        precision: Precision::RENDER,
    };
    b.upload(&input(&series.wide)).unwrap();
    b.build().unwrap();
    assert!(!double_single(&b), "{name}");
    let mut tiny = series.wide.clone();
    tiny.radius = 1e-5;
    tiny.radius_attribute = Some("h".into());
    b.refit(&tiny).unwrap();
    assert!(
        double_single(&b),
        "{name}: the tiny radii need double-single positions"
    );
    assert_prepared_like_the_cpu(
        &mut b,
        &input(&tiny),
        &format!("{name}: after a refit that needs lo parts"),
    );
    b.memory().preparation_bytes
}

/// Preparing a step on the device, stage 1: the Hilbert keys of the f32 local coordinates
/// equal their twin's bit for bit (outputs poisoned first), the permutation is the identity,
/// and sorting the twin's keys is `hilbert_order` of the f64 positions; in a box at 1000 and
/// as a simulation writes them.
fn hilbert_keys_equal_their_twin_and_sort_to_the_hilbert_order(gpu: Gpu) {
    let mut b = gpu.backend();
    let series: [(MakeStep, Bounds, u64); 2] = [
        (box_step, BOX_BOUNDS, 1000),
        (simulation_step, SIMULATION_BOUNDS, 300),
    ];
    for (make, bounds, first_seed) in series {
        let quantizer = HilbertQuantizer::new(bounds);
        for (i, n) in [0usize, 1, 255, 257, 65537, 1_000_003]
            .into_iter()
            .enumerate()
        {
            let step = make(n, first_seed + i as u64);
            let points: Vec<[f32; 4]> = step
                .positions
                .iter()
                .map(|&p| {
                    let [x, y, z] = quantizer.local(p);
                    [x, y, z, 0.5]
                })
                .collect();
            let (keys, values) = b.hilbert_keys(&points, &quantizer);
            let twin = hilbert_keys::hilbert_keys(&points, &quantizer);
            let differing = keys.iter().zip(&twin).filter(|(g, c)| g != c).count();
            assert_eq!(differing, 0, "n {n}: GPU keys differ from the twin's");
            assert_eq!(keys.len(), n);
            assert!(
                values.iter().enumerate().all(|(i, &v)| v as usize == i),
                "n {n}"
            );
            let mut order: Vec<u32> = (0..n as u32).collect();
            order.sort_by_key(|&i| twin[i as usize]);
            assert!(
                order == hilbert_order(&step.positions, bounds),
                "n {n}: the twin's keys do not sort to hilbert_order"
            );
        }
    }
    // A series flat in z (zero extent: scale 0 on that axis), and points outside the grid
    // (clamped), far from the origin.
    let flat = Bounds {
        min: DVec3::new(-7.0e7, 2.0, 5.5),
        max: DVec3::new(-7.0e7 + 1.0e3, 2.0 + 1.0e-3, 5.5),
    };
    let q = HilbertQuantizer::new(flat);
    let mut r = rng(399);
    let points: Vec<[f32; 4]> = (0..4099)
        .map(|_| {
            let p = flat.min
                + DVec3::new(r.random_range(-0.1..1.1), r.random_range(-0.1..1.1), 0.0)
                    * (flat.max - flat.min + DVec3::Z);
            let [x, y, z] = q.local(p);
            [x, y, z, 0.0]
        })
        .collect();
    let (keys, _) = b.hilbert_keys(&points, &q);
    assert!(
        keys == hilbert_keys::hilbert_keys(&points, &q),
        "flat series"
    );
    assert_no_driver_messages();
}

/// The preparation's radix sort (scratch poisoned first) equals a stable sort by key at awkward
/// sizes: random keys, few distinct keys in low and in high bits (stability decides their
/// order), and 30-bit keys with empty markers as the tree sorts them.
fn the_radix_sort_equals_a_stable_sort_by_key(gpu: Gpu) {
    let mut b = gpu.backend();
    for (i, n) in [0usize, 1, 2, 255, 256, 257, 4095, 4097, 65537, 1_000_003]
        .into_iter()
        .enumerate()
    {
        let mut r = rng(100 + i as u64);
        let kinds: &[u32] = if n > 100_000 { &[0, 2] } else { &[0, 1, 2, 3] };
        for &kind in kinds {
            let keys: Vec<u32> = (0..n)
                .map(|_| match kind {
                    0 => r.random(),
                    1 => r.random_range(0..17u32) << 9,
                    2 => r.random_range(0..13u32) << 20,
                    _ => {
                        if r.random_range(0..8) == 0 {
                            LBVH_EMPTY_KEY
                        } else {
                            r.random_range(0..1u32 << 30)
                        }
                    }
                })
                .collect();
            assert!(
                b.sort_pairs(&keys) == radix_sort::sort_pairs(&keys),
                "n {n}, keys kind {kind}: the GPU sort differs from sort_by_key"
            );
        }
    }
    assert_no_driver_messages();
}

/// Once the series' maximum is reserved, stepping makes no buffer: the staging memory, the
/// step's arrays, the sort's buffers and the structure are all made by the first upload (and
/// on ash its build; one with every optional array: a radius attribute and double-single
/// positions) and reused by steps of any count up to the reserved one; in a box at 1000
/// (cluster size 2) and as a simulation writes them (cluster size 4).
fn stepping_through_a_reserved_series_makes_no_buffers(gpu: Gpu) {
    let series = [
        (box_step as MakeStep, "s", 1100, BOX_BOUNDS, (-3.0, 5.0), 2),
        (
            simulation_step,
            "a",
            700,
            SIMULATION_BOUNDS,
            (1000.0, 1001.0),
            4,
        ),
    ];
    for (make, attribute, first_seed, bounds, range, k) in series {
        let mut b = gpu.backend();
        b.reserve(20_000);
        let mut f = FieldSettings::new(Some(attribute), 0.05);
        f.radius_attribute = Some("h".into());
        for (i, n) in [20_000usize, 5_003, 19_999, 1, 0, 12_345]
            .into_iter()
            .enumerate()
        {
            let step = Arc::new(make(n, first_seed + i as u64));
            let before = gpu.buffers_made();
            b.upload(&StepInput {
                step: &step,
                field: &f,
                cluster: ClusterSize::new(k).unwrap(),
                series_bounds: bounds,
                series_range: Some(range),
                precision: Precision::DoubleSingle,
            })
            .unwrap();
            let made_by_upload = gpu.buffers_made() - before;
            b.build().unwrap();
            let made = match gpu {
                Gpu::Ash => gpu.buffers_made() - before,
                // wgpu's build reads its tree's report back through a buffer it makes each
                // time: only its upload is counted.
                Gpu::Wgpu => made_by_upload,
            };
            if i > 0 {
                assert_eq!(
                    made, 0,
                    "K = {k}: step {i} ({n} particles) made {made} buffers"
                );
            } else {
                assert!(made > 0, "the counter counts");
            }
        }
    }
    assert_no_driver_messages();
}

/// Nothing uploaded, or uploaded and not built, and bad radii: errors, not panics. An empty
/// step uploads, builds and queries to zero.
fn misuse_is_an_error_not_a_panic(gpu: Gpu) {
    let mut b = gpu.backend();
    assert!(b.query(&[DVec3::ZERO]).is_err());
    assert!(b.build().is_err());
    assert!(b.image().is_err());
    assert!(b.refit(&FieldSettings::new(None, 1.0)).is_err());
    let step = Arc::new(unit_cube_step(100, 2, false));
    upload(&mut *b, &step, &maps_field(0.1, false), 1);
    assert!(b.query(&[DVec3::ZERO]).is_err(), "uploaded but not built");
    b.build().unwrap();
    assert!(
        b.refit(&maps_field(-1.0, false)).is_err(),
        "a negative radius"
    );
    assert!(b.query(&[]).unwrap().is_empty());

    let mut b = gpu.backend();
    let empty = Arc::new(Step {
        name: "empty".into(),
        positions: vec![],
        attributes: vec![Attribute {
            name: "s".into(),
            values: vec![],
        }],
    });
    let field = FieldSettings::new(Some("s"), 0.1);
    b.upload(&input(&empty, &field, 4)).unwrap();
    b.build().unwrap();
    assert_eq!(b.query(&[DVec3::ZERO]).unwrap(), vec![(0.0, [0.0; 3])]);
    assert_no_driver_messages();
}

/// Queries against the f64 reference at every cluster size: in a box at 1000 with zero radii
/// ([`compare_sums`]: post-classified with per-particle radii and a varying density map, and
/// pre-classified); and in the unit cube ([`check_queries`]: off-grid maps, pre-classification,
/// density alone with a radius attribute, no particles).
fn queries_match_the_f64_reference_for_every_cluster_size(gpu: Gpu) {
    let mut b = gpu.backend();
    let step = Arc::new(box_step(1500, 2));
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

    let step = Arc::new(unit_cube_step(20_000, 31, false));
    // About 30 particles within reach of a point.
    let radius = 0.07;
    for k in [1u32, 2, 4, 8, 16] {
        check_queries(
            &mut *gpu.backend(),
            &step,
            &maps_field(radius, true),
            k,
            &format!("post, maps, K {k}"),
        );
    }
    let mut pre = maps_field(radius, false);
    pre.classification = Classification::Pre;
    check_queries(&mut *gpu.backend(), &step, &pre, 4, "pre-classification");
    let mut density = FieldSettings::new(None, radius);
    density.radius_attribute = Some("h".into());
    check_queries(
        &mut *gpu.backend(),
        &step,
        &density,
        2,
        "density only, radius attribute",
    );
    let empty = Arc::new(unit_cube_step(0, 1, false));
    check_queries(
        &mut *gpu.backend(),
        &empty,
        &maps_field(radius, false),
        1,
        "no particles",
    );
    assert_no_driver_messages();
}

/// The backend's images against the CPU backend's at equal samples and seed, per integrator,
/// through a `RenderSession` as a user drives it. EA and stochastic marching make the same
/// decisions from the same random numbers on both (the same integrator code, GLSL twin of the
/// Rust), so f32-versus-f64 rounding is all that differs, except where rounding flips a
/// free-flight decision (a few pixels). Delta tracking on the CPU skips empty space between
/// particle boxes (the same distribution from other random numbers per pixel), so it is
/// compared at more samples through a Gaussian blur, where what is left is Monte Carlo noise.
/// On failure the images and the FLIP error map are written to the target directory.
fn images_match_the_cpu_backend_at_equal_samples_and_seed(gpu: Gpu) {
    let series = dambreak();
    let mut field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let k = ClusterSize::new(4).unwrap();
    let mut cpu = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    let mut device = RenderSession::new(gpu.backend().boxed(), &series);
    assert_eq!(device.backend().capabilities().name, gpu.to_string());
    let camera = Some(close_view(&series));
    use Classification::{Post, Pre};
    use Integrator::{Delta, Ea, Marching, SsReference};
    use NoiseKind::{Stbn, White};
    // (step, integrator, noise, classification, frames, blur, RMSE limit, FLIP limit).
    // Measured on lavapipe: RMSE < 5e-6 and FLIP < 1e-4 for EA, marching and the SS reference;
    // delta tracking RMSE ~3e-3 at 64 spp with a 1-pixel blur, 0.0026 (FLIP 0.033) at 32 spp
    // with a 1.5-pixel blur.
    let cases = [
        (7, Ea, Stbn, Post, 2, 0.0, 1e-4, 1e-3),
        (7, Ea, White, Pre, 2, 0.0, 1e-4, 1e-3),
        (7, Marching, Stbn, Post, 2, 0.0, 1e-3, 5e-3),
        (7, Delta, White, Post, 64, 1.0, 1e-2, 4e-2),
        (5, Ea, Stbn, Post, 2, 0.0, 1e-4, 1e-3),
        (5, Ea, White, Post, 2, 0.0, 1e-4, 1e-3),
        (5, Marching, Stbn, Post, 4, 0.0, 5e-3, 0.01),
        (5, SsReference, Stbn, Post, 1, 0.0, 1e-4, 1e-3),
        (5, Delta, Stbn, Post, 32, 1.5, 0.008, 0.06),
    ];
    for (step, integrator, noise, classification, frames, blur, max_rmse, max_flip) in cases {
        field.classification = classification;
        let settings = RenderSettings {
            width: 64,
            height: 48,
            integrator,
            noise,
            seed: 3,
            camera,
            ..RenderSettings::default()
        };
        cpu.show(&series, step, &field, k).unwrap();
        device.show(&series, step, &field, k).unwrap();
        let expected = cpu.render(&settings, frames).unwrap();
        let actual = device.render(&settings, frames).unwrap();
        let covered = expected.pixels.iter().filter(|p| p[3] > 0.0).count();
        assert!(
            covered > 600,
            "the fluid covers much of the image: {covered} pixels"
        );
        let name =
            format!("{gpu}-step{step}-{integrator:?}-{noise:?}-{classification:?}-{frames}spp")
                .to_lowercase();
        let (expected, actual) = if blur > 0.0 {
            (expected.blurred(blur), actual.blurred(blur))
        } else {
            (expected, actual)
        };
        assert_images_close(&name, &expected, &actual, max_rmse, max_flip);
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
    let expected = cpu.render_frames_on_half_lattice(&settings, 0, 2).unwrap();
    let actual = device
        .render_frames_on_half_lattice(&settings, 0, 2)
        .unwrap();
    assert_eq!((actual.width, actual.height), (32, 24));
    assert_images_close(&format!("{gpu}-lattice"), &expected, &actual, 1e-4, 1e-3);
    assert_no_driver_messages();
}
