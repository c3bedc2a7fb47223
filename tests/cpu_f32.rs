//! The CPU backend's f32 path (the cell grid and the eight-lane kernel) against the f64
//! reference, on data as simulations write it: f64 positions far from the origin, radii across
//! eight orders of magnitude, awkward counts, a per-particle radius attribute; and its two
//! builds (AVX2 and baseline) against each other, bit for bit.

use aarbf::accel::ClusterSize;
use aarbf::backend::precision::PositionKind;
use aarbf::backend::{self, BackendKind, Precision, Representation, StepInput};
use aarbf::field::f32_kernel;
use aarbf::field::{
    Classification, F32Batch, F32Field, F32Packet, F32Ray, FieldSettings, Particles, ReferenceField,
};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, Bounds, Integrator, NoiseKind, Step};
use glam::DVec3;
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// `n` particles in a cube of side `side` at `offset`, clumped (half of them within a few
/// radii of each other), with an attribute `s` and a smoothing length `h` spread over 4x.
fn step(n: usize, seed: u64, offset: f64, side: f64) -> Step {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let positions: Vec<DVec3> = (0..n)
        .map(|i| {
            let u = DVec3::new(rng.random(), rng.random(), rng.random());
            let u = if i % 2 == 0 { u } else { 0.4 + 0.05 * u };
            DVec3::splat(offset) + u * side
        })
        .collect();
    let s = (0..n).map(|_| rng.random_range(-3.0..5.0)).collect();
    let h = (0..n).map(|_| rng.random_range(0.25..1.0)).collect();
    Step {
        name: format!("seed {seed}"),
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

/// What f32 cannot decide: particles whose sphere's edge lies within the rounding of the f32
/// local coordinates of `x` (a kernel may count them in or out; the phi at an edge is
/// exp(-4.5) w, not small), each at most its kernel at its distance less that rounding.
fn edge_allowance(reference: &ReferenceField, x: DVec3) -> (f64, f64) {
    let p = &reference.particles;
    let local = x - p.origin;
    let mut phi = 0.0;
    let mut num = 0.0;
    for i in 0..p.len() {
        let r = p.radii[i];
        let d = (local - p.centers[i]).length();
        let band = 1e-5 * r
            + 4.0
                * f64::from(f32::EPSILON)
                * (local.abs().max_element() + p.centers[i].abs().max_element());
        if r > 0.0 && (d - r).abs() <= band {
            let nearest = (d - band).max(0.0) / r;
            let w = p.weights[i] * (-4.5 * nearest * nearest).exp() * 1.01;
            phi += w;
            num += w * match &p.theta {
                aarbf::field::Theta::Scalar(t) => t[i].abs(),
                _ => 1.0,
            };
        }
    }
    (phi, num)
}

fn check_against_reference(
    n: usize,
    seed: u64,
    offset: f64,
    radius: f64,
    per_particle: bool,
) -> Result<(), TestCaseError> {
    let step = std::sync::Arc::new(step(n, seed, offset, 1.0));
    let bounds = Bounds::of_points(&step.positions);
    let mut field = FieldSettings::new(Some("s"), radius);
    if per_particle {
        field.radius_attribute = Some("h".into());
    }
    let range = Some((-3.0, 5.0));
    let cluster = ClusterSize::new(4).unwrap();
    let reference = ReferenceField::of_step(&step, &field, cluster, bounds, range).unwrap();
    let mut cpu = backend::create(BackendKind::Cpu).unwrap();
    cpu.upload(&StepInput {
        step: &step,
        field: &field,
        cluster,
        series_bounds: bounds,
        series_range: range,
        precision: Precision::F32,
    })
    .unwrap();
    cpu.build().unwrap();
    let Some(Representation {
        positions: PositionKind::F32,
        bound,
        ..
    }) = cpu.representation()
    else {
        panic!("f32 was asked for: {:?}", cpu.representation());
    };
    let error_bound = bound.phi();
    // Points anywhere, and points within reach of particles (where tiny radii put the field).
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x5eed);
    let mut queries: Vec<DVec3> = (0..200)
        .map(|_| DVec3::splat(offset) + DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    for i in (0..n).step_by((n / 300).max(1)) {
        let u = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
        queries.push(step.positions[i] + u * radius * 0.6);
    }
    let got = cpu.query(&queries).unwrap();
    // The whole bound the backend states: every source of f32 error.
    let tolerance = error_bound;
    for (x, (phi, num)) in queries.iter().zip(got) {
        let (rphi, rnum) = reference.eval_sums(*x);
        let (edge_phi, edge_num) = edge_allowance(&reference, *x);
        prop_assert!(
            (phi - rphi).abs() <= tolerance * rphi + edge_phi + 1e-30,
            "n {n}, offset {offset:e}, radius {radius:e}: Phi {phi} vs {rphi} at {x} (bound {error_bound:e})"
        );
        prop_assert!(
            (num[0] - rnum[0]).abs() <= bound.theta() * rnum[0].abs().max(rphi) + edge_num + 1e-30,
            "n {n}, offset {offset:e}, radius {radius:e}: Theta {} vs {} at {x}",
            num[0],
            rnum[0]
        );
    }
    Ok(())
}

/// Packets of points as neighbouring rays' samples lie: around a centre (near particles, or
/// anywhere), spread from well within a cell to several cells (then the packet falls back to
/// one point at a time), some slots empty; each packet's values against each point evaluated
/// alone, the outputs poisoned first. Returns how many packets were evaluated together, and
/// how many fell back to one point at a time with more than one point in reach of particles.
fn check_packets(
    n: usize,
    seed: u64,
    offset: f64,
    radius: f64,
    channels: Classification,
) -> Result<(usize, usize), TestCaseError> {
    let step = step(n, seed, offset, 1.0);
    let bounds = Bounds::of_points(&step.positions);
    let mut field = FieldSettings::new(Some("s"), radius);
    field.radius_attribute = Some("h".into());
    field.classification = channels;
    let particles = Particles::prepare(&step, &field, bounds, Some((-3.0, 5.0))).unwrap();
    let f32_field = F32Field::new(&particles);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0xbac4);
    let mut packet = F32Packet::default();
    let mut rays: [F32Ray; 8] = Default::default();
    let mut alone = F32Ray::default();
    let (mut shared, mut fell_back) = (0, 0);
    for round in 0..120 {
        let centre = if round % 3 == 0 {
            DVec3::splat(offset) + DVec3::new(rng.random(), rng.random(), rng.random())
        } else {
            step.positions[rng.random_range(0..n)]
        };
        // From a tenth of the radius to the radius (cells are at least as wide as the
        // largest), and every fourth packet spread over the cube, each point near a particle
        // of its own (the packet falls back to one point at a time).
        let spread = [0.1, 0.5, 1.0, 0.1][round % 4] * radius;
        let points: [Option<DVec3>; 8] = std::array::from_fn(|_| {
            let u = DVec3::new(rng.random(), rng.random(), rng.random()) - 0.5;
            let centre = if round % 4 == 3 {
                step.positions[rng.random_range(0..n)]
            } else {
                centre
            };
            (rng.random::<f64>() < 0.85).then_some(centre + u * spread)
        });
        let mut out = [(f64::NAN, [f64::NAN; 3]); 8];
        let together = f32_field.eval_sums_packet(&points, &mut packet, &mut rays, &mut out);
        let live = points.iter().flatten().count();
        let mut reached = 0;
        for (i, point) in points.iter().enumerate() {
            let Some(x) = point else {
                prop_assert!(out[i].0.is_nan(), "an empty slot was written");
                continue;
            };
            let (phi, num) = f32_field.eval_sums(*x, &mut alone);
            reached += usize::from(phi > 0.0);
            let (got_phi, got_num) = out[i];
            // The same f32 terms, summed in another order (the f32 path's arithmetic tolerance).
            prop_assert!(
                (got_phi - phi).abs() <= 1e-5 * phi + 1e-37,
                "Phi {got_phi} in a packet of {live}, {phi} alone at {x} (spread {spread:e})"
            );
            let channels = if channels == Classification::Pre {
                3
            } else {
                1
            };
            for ch in 0..channels {
                prop_assert!(
                    (got_num[ch] - num[ch]).abs() <= 1e-5 * num[ch].abs().max(phi) + 1e-37,
                    "Theta[{ch}] {} in a packet, {} alone at {x}",
                    got_num[ch],
                    num[ch]
                );
            }
        }
        if together > 1 {
            shared += 1;
        } else if reached > 1 {
            fell_back += 1;
        }
    }
    Ok((shared, fell_back))
}

/// Point queries in groups ([`F32Field::eval_sums_many`]) against each point alone: a
/// group's candidates are a superset of each point's, in the same order, so the sums are the
/// same bits, except where f32 counts a particle on the very edge of a point's cells that the
/// point alone never looks at (what f32 cannot decide, `edge_allowance`): at most a few such
/// points, each within one edge term. Queries as `aarbf field` sends them (Hilbert order),
/// then in random order (few groups), with points outside the data. Returns how many points
/// were grouped.
fn check_groups(
    n: usize,
    seed: u64,
    offset: f64,
    radius: f64,
    per_particle: bool,
    channels: Classification,
) -> Result<usize, TestCaseError> {
    let step = step(n, seed, offset, 1.0);
    let bounds = Bounds::of_points(&step.positions);
    let mut field = FieldSettings::new(Some("s"), radius);
    if per_particle {
        field.radius_attribute = Some("h".into());
    }
    field.classification = channels;
    let particles = Particles::prepare(&step, &field, bounds, Some((-3.0, 5.0))).unwrap();
    let f32_field = F32Field::new(&particles);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x9e0);
    let m = 64 + (n * 7) % 1713;
    let queries: Vec<DVec3> = (0..m)
        .map(|i| {
            let u = DVec3::new(rng.random(), rng.random(), rng.random()) - 0.5;
            match i % 5 {
                // Outside the data (no cell, or cells no particle reaches).
                0 => DVec3::splat(offset) + u * 3.0,
                _ => step.positions[rng.random_range(0..n)] + u * radius,
            }
        })
        .collect();
    let order = aarbf::accel::hilbert_order(&queries, Bounds::of_points(&queries));
    let hilbert: Vec<DVec3> = order.iter().map(|&i| queries[i as usize]).collect();
    let mut grouped = 0;
    let mut alone = F32Ray::default();
    let mut batch = F32Batch::default();
    for points in [&hilbert, &queries] {
        let mut out = vec![(f64::NAN, [f64::NAN; 3]); points.len()];
        grouped += f32_field.eval_sums_many(points, &mut batch, &mut out);
        let mut edges = 0;
        for (x, got) in points.iter().zip(&out) {
            let want = f32_field.eval_sums(*x, &mut alone);
            if (got.0.to_bits(), got.1.map(f64::to_bits))
                == (want.0.to_bits(), want.1.map(f64::to_bits))
            {
                continue;
            }
            edges += 1;
            // One edge term at most: w exp(-4.5), w <= 1 here (no density map).
            let edge = (-4.5f64).exp() * (1.0 + 1e-5);
            prop_assert!(
                (got.0 - want.0).abs() <= edge + 1e-5 * want.0,
                "Phi {} in a group, {} alone at {x}",
                got.0,
                want.0
            );
        }
        prop_assert!(
            edges <= 2 + points.len() / 1000,
            "{edges} of {} points differ from their sums alone",
            points.len()
        );
    }
    Ok(grouped)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Point queries in groups equal each point alone, whatever the count, offset, radius,
    /// radii (one level of cells or several) and channels; queries in Hilbert order are
    /// grouped where the AVX2 build runs.
    #[test]
    fn point_queries_in_groups_equal_each_point_alone(
        n in 1usize..2500,
        seed in 0u64..1000,
        offset_exp in prop_oneof![Just(None), (0i32..=6).prop_map(Some)],
        radius_exp in -6.0f64..0.0,
        per_particle in any::<bool>(),
        pre in any::<bool>(),
    ) {
        let offset = offset_exp.map_or(0.0, |e| -(10f64.powi(e)));
        let classification = if pre { Classification::Pre } else { Classification::Post };
        let grouped =
            check_groups(n, seed, offset, 10f64.powf(radius_exp), per_particle, classification)?;
        if f32_kernel::simd_in_use() && n >= 50 {
            prop_assert!(grouped > 0, "no point was evaluated in a group");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// A packet of points evaluated together equals each point evaluated alone (to the order
    /// of summation), whatever the spread, offset, radius and number of channels.
    #[test]
    fn a_packet_equals_its_points_alone(
        n in 1usize..2500,
        seed in 0u64..1000,
        offset_exp in prop_oneof![Just(None), (0i32..=6).prop_map(Some)],
        radius_exp in -6.0f64..0.0,
        pre in any::<bool>(),
    ) {
        let offset = offset_exp.map_or(0.0, |e| -(10f64.powi(e)));
        let classification = if pre { Classification::Pre } else { Classification::Post };
        let (shared, fell_back) =
            check_packets(n, seed, offset, 10f64.powf(radius_exp), classification)?;
        prop_assert!(shared > 0, "no packet was evaluated together");
        // Particles spread over more than two cells a side (the cells are as wide as the
        // largest radius, or wider in a sparse set): the packets over the cube fall back.
        if n >= 200 && radius_exp < -2.0 {
            prop_assert!(fell_back > 0, "no packet fell back with points in reach");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Radii from 1e-6 to 1e2 of the data's extent, offsets up to 1e6, counts that are not
    /// powers of two: the f32 field is within the error bound the backend states.
    #[test]
    fn f32_field_is_within_its_stated_bound_of_the_reference(
        n in 1usize..2500,
        seed in 0u64..1000,
        offset_exp in prop_oneof![Just(None), (0i32..=6).prop_map(Some)],
        radius_exp in -6.0f64..2.0,
        per_particle in any::<bool>(),
    ) {
        let offset = offset_exp.map_or(0.0, |e| -(10f64.powi(e)));
        check_against_reference(n, seed, offset, 10f64.powf(radius_exp), per_particle)?;
    }
}

/// The AVX2 build of the kernel and the baseline one give the same image to their roundings
/// (the dispatch forced off for the second; bit for bit where both are the baseline build);
/// the AVX-512 build gives the AVX2 build's image bit for bit (the same lanes in the same
/// order); and each build is the one used where the CPU has it.
#[test]
fn simd_and_baseline_builds_agree_to_their_roundings() {
    #[cfg(target_arch = "x86_64")]
    {
        let avx2 = std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
            && std::is_x86_feature_detected!("popcnt");
        assert_eq!(
            f32_kernel::simd_in_use(),
            avx2,
            "the dispatch uses AVX2 exactly where the CPU has it"
        );
        assert_eq!(
            f32_kernel::avx512_in_use(),
            avx2 && std::is_x86_feature_detected!("avx512f")
                && std::is_x86_feature_detected!("avx512vl"),
            "the dispatch uses AVX-512 exactly where the CPU has it"
        );
    }
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(2999, 3, 1));
    let mut field = FieldSettings::new(Some("velocity"), 0.02 * series.bounds().diagonal());
    field.classification = Classification::Pre;
    let run = |simd: bool, avx512: bool| {
        f32_kernel::allow_simd(simd);
        f32_kernel::allow_avx512(avx512);
        let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
        s.set_precision(Precision::F32);
        s.show(&series, 2, &field, ClusterSize::new(4).unwrap())
            .unwrap();
        let image = s
            .render(
                &RenderSettings {
                    width: 40,
                    height: 33,
                    integrator: Integrator::Marching,
                    noise: NoiseKind::Stbn,
                    ..RenderSettings::default()
                },
                2,
            )
            .unwrap();
        f32_kernel::allow_simd(true);
        f32_kernel::allow_avx512(true);
        image
    };
    let (fast, avx2, baseline) = (run(true, true), run(true, false), run(false, false));
    let bits = |i: &aarbf::values::Image| -> Vec<u32> {
        i.pixels.iter().flatten().map(|v| v.to_bits()).collect()
    };
    assert!(
        bits(&fast) == bits(&avx2),
        "the AVX-512 and AVX2 builds (or, without AVX-512, the same build) give different images"
    );
    // The AVX2 point kernel fuses its multiply-adds (one rounding where the baseline build
    // has two), so the builds agree to their roundings, not bit for bit: measured 1.5e-8
    // at most on this image.
    let worst = fast
        .pixels
        .iter()
        .flatten()
        .zip(baseline.pixels.iter().flatten())
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(
        worst <= 1e-6,
        "the builds' images differ by up to {worst:e}"
    );
    if !f32_kernel::simd_in_use() {
        assert!(
            bits(&fast) == bits(&baseline),
            "the same build, different images"
        );
    }
    assert!(
        fast.pixels.iter().any(|p| p[3] > 0.3),
        "the fluid is visible"
    );
}

/// The f32 field's point queries give the same bits in the AVX-512 and AVX2 builds of the
/// kernel, in each of its forms: a common radius and weight (broadcast), per-particle radii
/// with a density map (gathered), a scalar attribute and colours (one and three channels).
#[test]
fn avx512_and_avx2_queries_are_the_same_bits() {
    let step = std::sync::Arc::new(step(1999, 17, -1234.5, 1.0));
    let bounds = Bounds::of_points(&step.positions);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(99);
    let queries: Vec<DVec3> = (0..3001)
        .map(|i| {
            let u = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
            step.positions[(i * 7) % step.positions.len()] + 0.02 * u
        })
        .collect();
    for (per_particle, pre) in [(false, false), (true, false), (false, true), (true, true)] {
        let mut field = FieldSettings::new(Some("s"), 0.03);
        if per_particle {
            field.radius_attribute = Some("h".into());
            field.density_map =
                aarbf::scene::maps::DensityMap::new("0:1,1:3".parse().unwrap()).unwrap();
        }
        if pre {
            field.classification = Classification::Pre;
        }
        let mut cpu = backend::create(BackendKind::Cpu).unwrap();
        cpu.upload(&StepInput {
            step: &step,
            field: &field,
            cluster: ClusterSize::new(4).unwrap(),
            series_bounds: bounds,
            series_range: Some((-3.0, 5.0)),
            precision: Precision::F32,
        })
        .unwrap();
        cpu.build().unwrap();
        let mut answers = |avx512: bool| {
            f32_kernel::allow_avx512(avx512);
            let got = cpu.query(&queries).unwrap();
            f32_kernel::allow_avx512(true);
            got.iter()
                .map(|(phi, num)| (phi.to_bits(), num.map(f64::to_bits)))
                .collect::<Vec<_>>()
        };
        let (wide, narrow) = (answers(true), answers(false));
        let reached = wide.iter().filter(|a| f64::from_bits(a.0) > 0.0).count();
        assert!(reached > 2000, "most queries lie in the field ({reached})");
        assert!(
            wide == narrow,
            "per-particle radii {per_particle}, pre-classified {pre}: the builds differ"
        );
    }
}

/// The f32 image of the demo equals the f64 reference's to well below an 8-bit step (the same
/// random numbers drive both: only the field differs).
#[test]
fn f32_and_f64_images_agree() {
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(3001, 4, 1));
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let render = |precision| {
        let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
        s.set_precision(precision);
        s.show(&series, 3, &field, ClusterSize::new(4).unwrap())
            .unwrap();
        let image = s
            .render(
                &RenderSettings {
                    width: 48,
                    height: 37,
                    integrator: Integrator::Ea,
                    noise: NoiseKind::Stbn,
                    ..RenderSettings::default()
                },
                2,
            )
            .unwrap();
        (image, s.backend().representation().map(|r| r.positions))
    };
    let ((f32_image, f32_positions), (f64_image, f64_positions)) =
        (render(Precision::RENDER), render(Precision::F64));
    assert!(
        matches!(f32_positions, Some(PositionKind::F32)),
        "{f32_positions:?}"
    );
    assert_eq!(f64_positions, Some(PositionKind::F64));
    let worst = f32_image
        .pixels
        .iter()
        .zip(&f64_image.pixels)
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "largest pixel difference {worst}");
    assert!(f64_image.pixels.iter().any(|p| p[3] > 0.3));
}

/// Empty-space skipping never skips field: along random rays through a clumped scene, every
/// sample with density lies inside an interval the cell walk reported, and those intervals are
/// ordered and disjoint.
#[test]
fn the_cell_walk_misses_no_density() {
    let step = step(1777, 9, -1234.5, 3.0);
    let bounds = Bounds::of_points(&step.positions);
    let mut field = FieldSettings::new(Some("s"), 0.04);
    field.radius_attribute = Some("h".into());
    let particles = Particles::prepare(&step, &field, bounds, Some((-3.0, 5.0))).unwrap();
    let f32_field = F32Field::new(&particles);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
    let mut scratch = F32Ray::default();
    let mut intervals = Vec::new();
    let mut checked = 0;
    for _ in 0..300 {
        let origin =
            bounds.center() + DVec3::new(rng.random(), rng.random(), rng.random()) * 8.0 - 4.0;
        // Aimed near the clump, some exactly along an axis.
        let mut dir = (bounds.min + (bounds.max - bounds.min) * 0.42 - origin).normalize();
        if checked % 7 == 0 {
            dir = DVec3::X * dir.x.signum();
        }
        let (t0, t1) = (0.0, 12.0);
        intervals.clear();
        f32_field.occupied(origin, dir, t0, t1, &mut intervals);
        for w in intervals.windows(2) {
            assert!(w[0].1 < w[1].0, "ordered and disjoint: {intervals:?}");
        }
        for k in 0..4000 {
            let t = t0 + (t1 - t0) * (f64::from(k) + 0.5) / 4000.0;
            let (phi, _) = f32_field.eval_sums(origin + dir * t, &mut scratch);
            if phi > 0.0 {
                checked += 1;
                assert!(
                    intervals.iter().any(|&(a, b)| a <= t && t <= b),
                    "density {phi} at t = {t} outside {intervals:?}"
                );
            }
        }
    }
    assert!(checked > 1000, "rays met density ({checked} samples)");
}

/// A map change and a radius change give exactly what a fresh upload with the new field gives,
/// on the f32 path and on the f64 reference (both keep copies of the weights and theta in
/// their cells), and the f32 path's structure is smaller than the reference's.
#[test]
fn map_and_radius_changes_equal_a_fresh_upload() {
    let step = std::sync::Arc::new(step(2047, 31, 1e4, 2.0));
    let bounds = Bounds::of_points(&step.positions);
    let range = Some((-3.0, 5.0));
    let cluster = ClusterSize::new(4).unwrap();
    let make = |field: &FieldSettings, precision| {
        let mut b = backend::create(BackendKind::Cpu).unwrap();
        b.upload(&StepInput {
            step: &step,
            field,
            cluster,
            series_bounds: bounds,
            series_range: range,
            precision,
        })
        .unwrap();
        b.build().unwrap();
        b
    };
    let base = FieldSettings::new(Some("s"), 0.3);
    let mut mapped = base.clone();
    mapped.density_map = aarbf::scene::maps::DensityMap::new("ramp".parse().unwrap()).unwrap();
    mapped.color_map = aarbf::scene::maps::ColorMap::preset("viridis").unwrap();
    let mut wider = mapped.clone();
    wider.radius = 0.45;
    let queries: Vec<DVec3> = step.positions.iter().step_by(7).copied().collect();
    for precision in [Precision::F32, Precision::F64] {
        for classification in [Classification::Post, Classification::Pre] {
            let with = |f: &FieldSettings| FieldSettings {
                classification,
                ..f.clone()
            };
            let mut b = make(&with(&base), precision);
            b.update_maps(&with(&mapped)).unwrap();
            assert_eq!(
                b.query(&queries).unwrap(),
                make(&with(&mapped), precision).query(&queries).unwrap(),
                "{precision:?}, {classification:?}: after a map change"
            );
            b.refit(&with(&wider)).unwrap();
            assert_eq!(
                b.query(&queries).unwrap(),
                make(&with(&wider), precision).query(&queries).unwrap(),
                "{precision:?}, {classification:?}: after a radius change"
            );
        }
    }
    let b = make(&wider, Precision::F32);
    let (f32_memory, f64_memory) = (b.memory(), make(&wider, Precision::F64).memory());
    assert!(
        f32_memory.structure_bytes < f64_memory.structure_bytes,
        "cells {} B, BVH {} B",
        f32_memory.structure_bytes,
        f64_memory.structure_bytes
    );
}
