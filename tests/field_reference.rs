//! The f64 reference field against hand-derived values, and brute force against the cells'
//! point queries.

use aarbf::accel::ClusterSize;
use aarbf::field::{Classification, FieldSettings, ReferenceField, Sample};
use aarbf::scene::maps::{ColorMap, DensityMap, RadiusMap};
use aarbf::values::color_space::srgb_to_linear;
use aarbf::values::tables::lookup_colour;
use aarbf::values::{Attribute, Bounds, Step};
use glam::DVec3;
use proptest::prelude::*;

fn step(points: &[(DVec3, f64)]) -> Step {
    Step {
        name: "test".into(),
        positions: points.iter().map(|p| p.0).collect(),
        attributes: vec![Attribute {
            name: "s".into(),
            values: points.iter().map(|p| p.1).collect(),
        }],
    }
}

fn field(step: &Step, settings: &FieldSettings, k: u32) -> ReferenceField {
    ReferenceField::of_step(
        step,
        settings,
        ClusterSize::new(k).unwrap(),
        step.bounds(),
        None,
    )
    .unwrap()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()) || a == b
}

#[test]
fn one_particle_at_the_kernel_landmarks() {
    let s = step(&[(DVec3::new(0.25, -1.0, 3.0), 7.0)]);
    let r = 0.5;
    let f = field(&s, &FieldSettings::new(Some("s"), r), 1);
    let c = DVec3::new(0.25, -1.0, 3.0);
    // Along an axis, so c + d stays exact in f64 for d = r.
    let dir = DVec3::X;
    // phi(d) = exp(-0.5 (3d/r)^2): 1 at d = 0, e^-0.5 at d = r/3, e^-4.5 at d = r, 0 beyond.
    let cases = [
        (0.0, 1.0),
        (r / 3.0, (-0.5f64).exp()),
        (r, (-4.5f64).exp()),
        (r * (1.0 + 1e-7), 0.0),
    ];
    for (d, expected) in cases {
        for sample in [f.eval(c + dir * d), f.eval_brute_force(c + dir * d)] {
            assert!(
                close(sample.phi, expected, 1e-12),
                "d = {d}: {} vs {expected}",
                sample.phi
            );
            let theta = if expected > 0.0 { 7.0 } else { 0.0 };
            assert!(
                close(sample.theta[0], theta, 1e-12),
                "d = {d}: Theta {}",
                sample.theta[0]
            );
        }
    }
}

#[test]
fn two_overlapping_particles_blend_by_weight() {
    // Centres 0.375 apart, radius 0.5; at x = 0.125 from the first: d1 = 0.125, d2 = 0.25
    // (all exact in binary).
    let s = step(&[(DVec3::ZERO, 1.0), (DVec3::new(0.375, 0.0, 0.0), 3.0)]);
    let f = field(&s, &FieldSettings::new(Some("s"), 0.5), 1);
    let x = DVec3::new(0.125, 0.0, 0.0);
    let p1 = (-0.5 * (3.0 * 0.125 / 0.5f64).powi(2)).exp();
    let p2 = (-0.5 * (3.0 * 0.25 / 0.5f64).powi(2)).exp();
    let got = f.eval(x);
    assert!(close(got.phi, p1 + p2, 1e-12));
    // Theta in the attribute's own units: the weighted mean of s.
    assert!(
        close(got.theta[0], (1.0 * p1 + 3.0 * p2) / (p1 + p2), 1e-12),
        "{}",
        got.theta[0]
    );

    // A density map w(t) = t (t = 0 for s = 1, t = 1 for s = 3) silences the first particle.
    let mut settings = FieldSettings::new(Some("s"), 0.5);
    settings.density_map = DensityMap::new("ramp".parse().unwrap()).unwrap();
    let got = field(&s, &settings, 1).eval(x);
    assert!(
        close(got.phi, p2, 1e-12) && close(got.theta[0], 3.0, 1e-12),
        "{got:?}"
    );

    // A radius map m(t) = 0.5 + 0.5 t halves the first particle's radius to 0.25.
    let mut settings = FieldSettings::new(Some("s"), 0.5);
    settings.radius_map = RadiusMap::new("0:0.5,1:1".parse().unwrap()).unwrap();
    let got = field(&s, &settings, 1).eval(x);
    let p1_half = (-0.5 * (3.0 * 0.125 / 0.25f64).powi(2)).exp();
    assert!(close(got.phi, p1_half + p2, 1e-12), "{got:?}");

    // A radius map of 0 for s = 1 removes that particle (and from the tree).
    let mut settings = FieldSettings::new(Some("s"), 0.5);
    settings.radius_map = RadiusMap::new("ramp".parse().unwrap()).unwrap();
    let f0 = field(&s, &settings, 1);
    assert!(
        f0.boxes().boxes[f0.particles.radii.iter().position(|r| *r == 0.0).unwrap()].is_empty()
    );
    assert!(close(f0.eval(x).phi, p2, 1e-12));

    // Pre-classification averages the linear colours of a grayscale map: C(0) = 0, C(1) = 1.
    let mut settings = FieldSettings::new(Some("s"), 0.5);
    settings.classification = Classification::Pre;
    settings.color_map = ColorMap::preset("grayscale").unwrap();
    let got = field(&s, &settings, 1).eval(x);
    let expected = p2 / (p1 + p2);
    assert!(
        got.theta.iter().all(|&c| close(c, expected, 1e-12)),
        "{got:?}"
    );
    // ... and the attribute range may be overridden: s = 1 → t = 0.5, s = 3 → t = 1.5 → C = 1.
    // C(0.5) is the colour map's table at 0.5 (every backend's definition of the map), within
    // the table's interpolation error (1e-5 here) of the exact sRGB midpoint.
    settings.attribute_range = Some((0.0, 2.0));
    let got = field(&s, &settings, 1).eval(x);
    let mid: f64 = lookup_colour(&settings.color_map.bake(), 0.5)[1];
    assert!((mid - srgb_to_linear(0.5)).abs() < 1e-5);
    let expected = (mid * p1 + p2) / (p1 + p2);
    assert!(close(got.theta[1], expected, 1e-12), "{got:?}");
}

#[test]
fn empty_space_has_zero_density_and_zero_theta() {
    let s = step(&[(DVec3::ZERO, 1.0), (DVec3::ONE, 2.0)]);
    let f = field(&s, &FieldSettings::new(Some("s"), 0.1), 4);
    let empty = f.eval(DVec3::splat(0.5));
    assert_eq!(empty, Sample::default());
    assert_eq!(f.eval_brute_force(DVec3::splat(0.5)), Sample::default());
    // A density map of zero everywhere: Phi = 0 and Theta = 0, never NaN.
    let mut settings = FieldSettings::new(Some("s"), 0.1);
    settings.density_map = DensityMap::new("0".parse().unwrap()).unwrap();
    let got = field(&s, &settings, 1).eval(DVec3::ZERO);
    assert_eq!(got, Sample::default());
}

#[test]
fn constant_attribute_and_co_located_particles() {
    let s = step(&[(DVec3::splat(2.0), 5.0); 100]);
    let f = field(&s, &FieldSettings::new(Some("s"), 1.0), 16);
    let got = f.eval(DVec3::splat(2.0));
    assert!(close(got.phi, 100.0, 1e-12));
    assert_eq!(got.theta[0], 5.0, "a constant attribute averages to itself");
}

#[test]
fn every_cluster_size_gives_the_same_field() {
    let steps = aarbf::scene::synth::Generator::Clusters.generate(3000, 1, 3);
    let s = &steps[0];
    let settings = FieldSettings::new(Some("sigma_distance"), 0.05);
    let fields: Vec<_> = ClusterSize::ALL
        .iter()
        .map(|k| field(s, &settings, u32::from(*k)))
        .collect();
    let mut nonzero = 0;
    for i in 0..500 {
        let x = DVec3::new((i % 10) as f64, ((i / 10) % 10) as f64, (i / 100) as f64) / 10.0 + 0.2;
        let reference = fields[0].eval_brute_force(x);
        nonzero += usize::from(reference.phi > 0.0);
        for f in &fields {
            let got = f.eval(x);
            assert!(
                close(got.phi, reference.phi, 1e-12),
                "K = {}: {got:?} vs {reference:?}",
                f.boxes().size
            );
            assert!(close(got.theta[0], reference.theta[0], 1e-12));
        }
    }
    assert!(
        nonzero > 50,
        "the queries should meet particles ({nonzero})"
    );
}

#[test]
fn setup_errors_are_clear() {
    let s = step(&[(DVec3::ZERO, 1.0)]);
    let prepare = |settings: &FieldSettings| {
        ReferenceField::of_step(&s, settings, ClusterSize::default(), s.bounds(), None)
            .err()
            .unwrap()
            .to_string()
    };
    let e = prepare(&FieldSettings::new(Some("mass"), 0.1));
    assert!(
        e.contains("no attribute 'mass'") && e.contains("it has: s"),
        "{e}"
    );
    assert!(prepare(&FieldSettings::new(Some("s"), 0.0)).contains("positive finite"));
    assert!(prepare(&FieldSettings::new(Some("s"), f64::NAN)).contains("positive finite"));
    let mut settings = FieldSettings::new(None, 0.1);
    settings.radius_map = RadiusMap::new("ramp".parse().unwrap()).unwrap();
    assert!(prepare(&settings).contains("radius map varies with the attribute"));
    let mut settings = FieldSettings::new(Some("s"), 0.1);
    settings.radius_attribute = Some("s".into());
    let neg = step(&[(DVec3::ZERO, -1.0)]);
    let e = ReferenceField::of_step(&neg, &settings, ClusterSize::default(), neg.bounds(), None)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("radius attribute 's' holds -1 for particle 0"),
        "{e}"
    );
}

/// A random particle set: n particles in a cube of side `extent` at `offset`, radii from
/// `r_lo` to `r_hi` (log-uniform, as fractions of the extent), some radii zero.
fn random_set(
    seed: u64,
    n: usize,
    extent: f64,
    offset: f64,
    r_lo: f64,
    r_hi: f64,
) -> (Step, Vec<DVec3>) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut positions = Vec::new();
    let mut s = Vec::new();
    let mut h = Vec::new();
    for _ in 0..n {
        let p = DVec3::new(rng.random(), rng.random(), rng.random()) * extent + offset;
        positions.push(p);
        s.push(rng.random_range(-5.0..5.0f64));
        let r = if rng.random_bool(0.1) {
            0.0
        } else {
            (rng.random_range(r_lo.ln()..=r_hi.ln())).exp() * extent
        };
        h.push(r);
    }
    // Queries: near particle centres (so many hit), and uniform in the box.
    let queries = (0..200)
        .map(|i| {
            if i % 2 == 0 {
                let c = positions[rng.random_range(0..n)];
                c + DVec3::new(rng.random(), rng.random(), rng.random()) * (h[i % n] + 1e-9)
            } else {
                DVec3::new(rng.random(), rng.random(), rng.random()) * extent + offset
            }
        })
        .collect();
    let step = Step {
        name: "random".into(),
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
    };
    (step, queries)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Brute force and the point queries agree to 1e-12 relative for random sets, radii
    /// spanning 1e-6 to 1e+3 of the domain, coordinates offset by up to 1e6, and every cluster
    /// size.
    #[test]
    fn brute_force_equals_the_point_queries(
        seed in any::<u64>(),
        n in 1usize..400,
        offset_exp in -1.0f64..6.0,
        r_lo_exp in -6.0f64..0.0,
        r_span in 0.0f64..9.0,
        k in prop::sample::select(vec![1u32, 2, 4, 8, 16]),
        pre in any::<bool>(),
    ) {
        let r_lo = 10f64.powf(r_lo_exp);
        let r_hi = 10f64.powf((r_lo_exp + r_span).min(3.0));
        let extent = 1.0;
        let offset = 10f64.powf(offset_exp);
        let (step, queries) = random_set(seed, n, extent, offset, r_lo, r_hi);
        let mut settings = FieldSettings::new(Some("s"), 1.0);
        settings.radius_attribute = Some("h".into());
        settings.radius_map = RadiusMap::new("0:0.2,1:1".parse().unwrap()).unwrap();
        settings.density_map = DensityMap::new("0:1,1:3".parse().unwrap()).unwrap();
        if pre {
            settings.classification = Classification::Pre;
        }
        let f = ReferenceField::of_step(&step, &settings, ClusterSize::new(k).unwrap(), Bounds::of_points(&step.positions), None).unwrap();
        for x in queries {
            let (a, b) = (f.eval(x), f.eval_brute_force(x));
            prop_assert!(close(a.phi, b.phi, 1e-12), "Phi {} vs {} at {x}", a.phi, b.phi);
            // Theta is a weighted mean of values up to `scale` in magnitude (attributes in
            // -5..5 after post-classification, colours in 0..1 before): summing in another
            // order moves it by a few ulps of `scale`, so a mean near 0 is compared on that
            // scale, not relative to itself (cancellation, not disagreement).
            let scale = if pre { 1.0 } else { 5.0 };
            for c in 0..3 {
                let (ta, tb) = (a.theta[c], b.theta[c]);
                prop_assert!((ta - tb).abs() <= 1e-12 * ta.abs().max(tb.abs()).max(scale), "Theta {:?} vs {:?}", a.theta, b.theta);
            }
            prop_assert!(a.phi.is_finite() && a.theta.iter().all(|t| t.is_finite()));
        }
    }

    /// The point queries compute each term exactly as the brute-force sum does: where at most
    /// two particles reach a point (IEEE addition commutes, so the order of two terms cannot
    /// matter) the two agree bit for bit, at offsets to 1e6 and radii from 1e-6; and the
    /// kernel's baseline and AVX2 builds agree bit for bit everywhere.
    #[test]
    fn point_queries_are_the_reference_term_for_term(
        seed in any::<u64>(),
        n in 1usize..300,
        offset_exp in -1.0f64..6.0,
        r_lo_exp in -6.0f64..-1.0,
        r_span in 0.0f64..4.0,
        pre in any::<bool>(),
    ) {
        // Radii up to a tenth of the domain, so that some points meet at most two particles.
        let r_lo = 10f64.powf(r_lo_exp);
        let r_hi = 10f64.powf((r_lo_exp + r_span).min(-1.0));
        let (step, queries) = random_set(seed, n, 1.0, 10f64.powf(offset_exp), r_lo, r_hi);
        let mut settings = FieldSettings::new(Some("s"), 1.0);
        settings.radius_attribute = Some("h".into());
        settings.density_map = DensityMap::new("0:1,1:3".parse().unwrap()).unwrap();
        if pre {
            settings.classification = Classification::Pre;
        }
        let f = ReferenceField::of_step(&step, &settings, ClusterSize::default(), Bounds::of_points(&step.positions), None).unwrap();
        let bits = |s: Sample| (s.phi.to_bits(), s.theta.map(f64::to_bits));
        let mut exact = 0;
        for x in queries {
            aarbf::field::f32_kernel::allow_simd(false);
            let baseline = f.eval(x);
            aarbf::field::f32_kernel::allow_simd(true);
            let got = f.eval(x);
            prop_assert_eq!(bits(got), bits(baseline), "AVX2 {:?} vs baseline {:?} at {}", got, baseline, x);
            let l = x - f.particles.origin;
            let reached = (0..f.particles.len())
                .filter(|&i| {
                    let r = f.particles.radii[i];
                    r > 0.0 && (l - f.particles.centers[i]).length_squared() <= r * r
                })
                .count();
            if reached <= 2 {
                exact += 1;
                let brute = f.eval_brute_force(x);
                prop_assert_eq!(bits(got), bits(brute), "{} particles reach {}: {:?} vs {:?}", reached, x, got, brute);
            }
        }
        prop_assert!(exact > 0, "some query should meet at most two particles");
    }
}
