use super::*;

#[test]
fn errors_are_relative_and_count_what_is_not_finite() {
    let reference = [
        (2.0, [1.0, 0.0, 0.0]),
        (1.0, [0.5, 0.0, 0.0]),
        (0.0, [0.0; 3]),
        (1.0, [1.0, 0.0, 0.0]),
    ];
    let got = [
        (2.0 + 2e-6, [1.0, 0.0, 0.0]),
        (1.0, [0.25, 0.0, 0.0]),
        (0.0, [0.0; 3]),
        (f64::NAN, [1.0, 0.0, 0.0]),
    ];
    let e = errors(&reference, &got);
    assert!((e.phi_max - 1e-6).abs() < 1e-12, "{e:?}");
    assert_eq!(e.phi_median, 0.0);
    // Theta 0.5 -> 0.25 at the second point.
    assert!((e.theta_max - 0.25).abs() < 1e-12, "{e:?}");
    assert_eq!(e.nonfinite, 1);
    // Density where the reference has none is wholly wrong; none where it has some too.
    let e = errors(
        &[(0.0, [0.0; 3]), (1.0, [0.0; 3])],
        &[(1e-30, [0.0; 3]), (0.0, [0.0; 3])],
    );
    assert_eq!(e.phi_max, 1.0);
}

#[test]
fn f32_exact_inputs_are_exact_in_local_coordinates() {
    let case = Case {
        offset: 1e6,
        radius_fraction: 1e-6,
        ..Case::moderate(Family::Offset)
    };
    let scene = Scene::generate(&case, Inputs::F32Exact, 500, 3).unwrap();
    let origin = scene.bounds.center();
    for &p in scene.step.positions.iter().chain(&scene.queries) {
        let local = p - origin;
        for c in local.to_array() {
            assert_eq!(f64::from(c as f32), c, "{p}");
        }
    }
    assert_eq!(f64::from(scene.field.radius as f32), scene.field.radius);
    // The f64 inputs are not: most coordinates lose digits in f32.
    let scene = Scene::generate(&case, Inputs::F64, 500, 3).unwrap();
    let origin = scene.bounds.center();
    let inexact = scene
        .step
        .positions
        .iter()
        .filter(|&&p| {
            let l = p - origin;
            f64::from(l.x as f32) != l.x
        })
        .count();
    assert!(inexact > 450, "{inexact}");
}

#[test]
fn query_points_lie_near_particles() {
    let case = Case {
        radius_fraction: 1e-6,
        ..Case::moderate(Family::Radius)
    };
    for inputs in Inputs::BOTH {
        let scene = Scene::generate(&case, inputs, 300, 4).unwrap();
        let reference = scene.reference().unwrap();
        assert_eq!(reference.len(), QUERIES);
        assert!(reference.iter().all(|(phi, _)| *phi > 0.0));
    }
}

#[test]
fn sweeps_are_checked_and_named() {
    let o = Options::default();
    assert!(check_sweeps(&o).is_ok());
    assert_eq!(cases(&o).len(), 9 + 4 + o.phi_weights.len());
    for bad in [
        Options {
            radius_fractions: vec![0.0],
            ..Options::default()
        },
        Options {
            offsets: vec![1e12],
            ..Options::default()
        },
        Options {
            phi_weights: vec![1e-50],
            ..Options::default()
        },
    ] {
        assert!(check_sweeps(&bad).is_err());
    }
    assert_eq!(short(1e-6), "1e-6");
    assert_eq!(short(0.05), "0.05");
    assert_eq!(short(1e2), "1e2");
    assert!(reaches_denormals(1e-37) && !reaches_denormals(1e-30));
}
