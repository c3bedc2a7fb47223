//! The extremes matrix (issue: numerical extremes): every backend against the f64 reference on
//! data no one planned for. Expected: no NaN or Inf in any field value or pixel, bounded work,
//! field values within the backend's tolerance of the reference.

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind, Precision, StepInput};
use aarbf::field::{Classification, FieldSettings, ReferenceField};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{DensityMap, RadiusMap};
use aarbf::values::{Attribute, Step};
use aarbf::values::{Integrator, NoiseKind};
use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common;

/// The backends under test, the precision asked of each, and their relative tolerance against
/// the f64 reference (those the backends' own tests state: the CPU's f64 agrees to rounding;
/// the CPU's f32 kernel within the 1e-5 `aarbf field` asks for, where the scene lets it run;
/// the GPUs compute in f32). A GPU backend that cannot start fails the test.
fn backends() -> Vec<(BackendKind, Precision, f64)> {
    common::capture_driver_messages();
    let mut out = vec![
        (BackendKind::Cpu, Precision::F64, 1e-9),
        (BackendKind::Cpu, Precision::FIELD, 1e-5),
        // f32 whatever the scene: within the error bound the backend states for it.
        (BackendKind::Cpu, Precision::F32, 1e-5),
    ];
    for (kind, tolerance) in [(BackendKind::Wgpu, 5e-4), (BackendKind::Ash, 5e-4)] {
        common::require(&format!("the {kind} backend"), backend::create(kind));
        out.push((kind, Precision::FIELD, tolerance));
    }
    out
}

/// What f32 cannot resolve: the contributions of particles whose sphere's edge lies within
/// 1e-4 of its radius (plus the f32 rounding of the local coordinates) of `x`. A GPU may count
/// such a particle in or out; the phi at an edge is exp(-4.5) w, not small.
fn edge_allowance(reference: &ReferenceField, x: DVec3, origin: DVec3) -> (f64, [f64; 3]) {
    let p = &reference.particles;
    let ulp = 2.0 * f64::from(f32::EPSILON) * (x - origin).abs().max_element().max(1e-30);
    let mut phi = 0.0;
    let mut theta = [0.0; 3];
    for i in 0..p.len() {
        let r = p.radii[i];
        let d = (x - p.origin - p.centers[i]).length();
        if r > 0.0 && (d - r).abs() <= 1e-4 * r + ulp {
            let w = p.weights[i] * (-4.5f64).exp() * 1.01;
            phi += w;
            let t = match &p.theta {
                aarbf::field::Theta::Scalar(t) => [t[i], 0.0, 0.0],
                aarbf::field::Theta::Rgb(c) => c[i],
                aarbf::field::Theta::None => [0.0; 3],
            };
            for c in 0..3 {
                theta[c] += w * t[c].abs();
            }
        }
    }
    (phi, theta)
}

struct Case {
    name: &'static str,
    step: Step,
    field: FieldSettings,
}

fn uniform(n: usize, seed: u64, offset: f64, scale: f64) -> Step {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let positions: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * scale + offset)
        .collect();
    let s = (0..n).map(|_| rng.random_range(0.0..1.0f64)).collect();
    let h = (0..n).map(|_| rng.random_range(0.5..1.5f64)).collect();
    Step {
        name: format!("uniform{n}"),
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

fn with_attribute(mut step: Step, values: Vec<f64>) -> Step {
    step.attributes[0].values = values;
    step
}

fn cases() -> Vec<Case> {
    let diag = 3f64.sqrt();
    let settings = |radius: f64| FieldSettings::new(Some("s"), radius);
    let mut out = Vec::new();
    for (name, frac) in [
        ("radius 1e-6 of the diagonal", 1e-6),
        ("radius 1e-3", 1e-3),
        ("radius 1", 1.0),
        ("radius 1e2", 1e2),
    ] {
        out.push(Case {
            name,
            step: uniform(800, 1, 0.0, 1.0),
            field: settings(frac * diag),
        });
    }
    // Per-particle radii spanning 1e-8..1e-2 of the diagonal in one step.
    let mut step = uniform(800, 2, 0.0, 1.0);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    step.attributes[1].values = (0..800)
        .map(|_| 10f64.powf(rng.random_range(-8.0..-2.0)))
        .collect();
    let mut f = settings(diag);
    f.radius_attribute = Some("h".into());
    out.push(Case {
        name: "per-particle radii 1e-8..1e-2",
        step,
        field: f,
    });
    // Radius 0 for some, most and all particles (radius map over the attribute).
    for (name, zero_below) in [
        ("radius 0 for some", 0.1),
        ("radius 0 for most", 0.9),
        ("radius 0 for all", 1.01),
    ] {
        let mut f = settings(0.05);
        let z: f64 = f64::min(zero_below, 0.999);
        f.radius_map = RadiusMap::new(format!("0:0,{z}:0,1:1").parse().unwrap()).unwrap();
        if zero_below > 1.0 {
            f.radius_map = RadiusMap::new("0".parse().unwrap()).unwrap();
        }
        out.push(Case {
            name,
            step: uniform(800, 4, 0.0, 1.0),
            field: f,
        });
    }
    for n in [0, 1, 2] {
        out.push(Case {
            name: ["N = 0", "N = 1", "N = 2"][n],
            step: uniform(n, 5, 0.0, 1.0),
            field: settings(0.3),
        });
    }
    let mut one_point = uniform(1000, 6, 0.0, 1.0);
    one_point
        .positions
        .iter_mut()
        .for_each(|p| *p = DVec3::splat(0.5));
    out.push(Case {
        name: "1000 particles at one point",
        step: one_point,
        field: settings(0.1),
    });
    for (name, offset) in [("offset 1e3", 1e3), ("offset 1e6", 1e6)] {
        out.push(Case {
            name,
            step: uniform(800, 7, offset, 1.0),
            field: settings(0.1),
        });
    }
    let mut f = settings(0.1);
    f.density_map = DensityMap::new("1e-40".parse().unwrap()).unwrap();
    out.push(Case {
        name: "Phi in the denormal range",
        step: uniform(800, 8, 0.0, 1.0),
        field: f,
    });
    let big: Vec<f64> = (0..800)
        .map(|i| if i % 2 == 0 { 1e30 } else { -1e30 })
        .collect();
    out.push(Case {
        name: "attributes at +-1e30",
        step: with_attribute(uniform(800, 9, 0.0, 1.0), big),
        field: settings(0.1),
    });
    out.push(Case {
        name: "constant attribute",
        step: with_attribute(uniform(800, 10, 0.0, 1.0), vec![3.0; 800]),
        field: settings(0.1),
    });
    let mut f = settings(0.1);
    f.density_map = DensityMap::new("0".parse().unwrap()).unwrap();
    out.push(Case {
        name: "density map 0 everywhere",
        step: uniform(800, 11, 0.0, 1.0),
        field: f,
    });
    out
}

fn queries(step: &Step, seed: u64) -> Vec<DVec3> {
    let b = step.bounds();
    let (lo, ext) = if b.is_empty() {
        (DVec3::ZERO, DVec3::ONE)
    } else {
        (b.min, b.extent().max(DVec3::splat(1e-3)))
    };
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut q: Vec<DVec3> = (0..256)
        .map(|_| lo + DVec3::new(rng.random(), rng.random(), rng.random()) * ext)
        .collect();
    q.extend(step.positions.iter().take(64).copied());
    q
}

#[test]
fn extremes_matrix() {
    let mut times = Vec::new();
    for (kind, precision, tolerance) in backends() {
        for case in cases() {
            let started = std::time::Instant::now();
            for classification in [Classification::Post, Classification::Pre] {
                check_case(kind, precision, tolerance, &case, classification);
            }
            let line = format!(
                "{kind} ({precision:?}) / {}: {:.1} s",
                case.name,
                started.elapsed().as_secs_f64()
            );
            eprintln!("{line}");
            times.push(line);
        }
    }
    eprintln!("{}", times.join("\n"));
    // Extreme data must not provoke API misuse either: wgpu's validation and the Khronos
    // layer on the ash backend (both on in builds with debug assertions) stayed silent.
    common::assert_no_driver_messages();
    let ash_messages = aarbf::backend::ash_rt::validation_messages();
    assert!(ash_messages.is_empty(), "{ash_messages:#?}");
}

fn check_case(
    kind: BackendKind,
    precision: Precision,
    tolerance: f64,
    case: &Case,
    classification: Classification,
) {
    let mut field = case.field.clone();
    field.classification = classification;
    let label = format!(
        "{kind} ({precision:?}) / {} / {classification:?}",
        case.name
    );
    let series = TimeSeries::from_steps(vec![case.step.clone()]);
    let range = series.attribute("s").map(|a| (a.min, a.max));
    let cluster = ClusterSize::new(4).unwrap();
    let reference =
        ReferenceField::of_step(&case.step, &field, cluster, series.bounds(), range).unwrap();
    let mut b = backend::create(kind).unwrap();
    b.upload(&StepInput {
        step: &series.step(0).unwrap(),
        field: &field,
        cluster,
        series_bounds: series.bounds(),
        series_range: range,
        precision,
    })
    .unwrap();
    b.build().unwrap();
    // Forced f32 is held to the whole bound the backend states for this scene.
    let tolerance = match b.representation() {
        // (Infinite where terms leave f32's normal range, as in the denormal case: there the
        // density counts as none, below PHI_EPSILON, and the usual tolerance applies.)
        Some(r) if precision == Precision::F32 && r.bound.phi().is_finite() => {
            tolerance.max(r.bound.phi())
        }
        _ => tolerance,
    };
    let q = queries(&case.step, 1);
    let got = b.query(&q).unwrap();
    let origin = series.bounds().center();
    // Below this a density counts as none (PHI_EPSILON; f32 flushes denormals).
    let floor = 1e-30;
    for (x, (phi, num)) in q.iter().zip(&got) {
        let (rphi, rnum) = reference.eval_sums(*x);
        assert!(
            phi.is_finite() && num.iter().all(|v| v.is_finite()),
            "{label}: non-finite at {x}"
        );
        let (edge_phi, edge_num) = if precision == Precision::F64 {
            (0.0, [0.0; 3])
        } else {
            edge_allowance(&reference, *x, origin)
        };
        assert!(
            (phi - rphi).abs() <= tolerance * rphi.abs() + edge_phi + floor,
            "{label}: Phi {phi} vs {rphi} at {x}"
        );
        for c in 0..3 {
            let allowed = tolerance * rnum[c].abs().max(rphi.abs()) + edge_num[c] + floor;
            assert!(
                (num[c] - rnum[c]).abs() <= allowed,
                "{label}: Theta {num:?} vs {rnum:?} at {x}"
            );
        }
    }
    let mut session = RenderSession::new(b, &series);
    session.show(&series, 0, &field, cluster).unwrap();
    // The GPUs share the integrator code, which the CPU twin and the backends' own image tests
    // cover; here the point is finite pixels and bounded work on extreme data, so they render
    // fewer, smaller frames (lavapipe runs them on the same two cores).
    let (size, integrators): (u32, &[Integrator]) = if kind == BackendKind::Cpu {
        (
            12,
            &[Integrator::Ea, Integrator::Marching, Integrator::Delta],
        )
    } else {
        (6, &[Integrator::Ea, Integrator::Marching])
    };
    for &integrator in integrators {
        let settings = RenderSettings {
            width: size,
            height: size,
            integrator,
            noise: NoiseKind::White,
            ..RenderSettings::default()
        };
        let started = std::time::Instant::now();
        let image = session.render(&settings, 1).unwrap();
        eprintln!(
            "  {label} / {integrator:?}: {:.2} s",
            started.elapsed().as_secs_f64()
        );
        assert!(
            image.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())),
            "{label} / {integrator:?}: non-finite pixel"
        );
        assert!(
            started.elapsed().as_secs() < 60,
            "{label} / {integrator:?}: work per frame must stay bounded"
        );
    }
}
