//! Smoothing lengths from neighbours (`--smoothing knn:K`) against a brute-force computation,
//! on sets of awkward sizes and shapes, and as a series' per-particle radius, cached beside the
//! data.

use std::path::Path;

use aarbf::io::{self, Format};
use aarbf::scene::smoothing::{self, Smoothing};
use aarbf::scene_file::resolve::{DataArgs, FieldOptions, resolve};
use aarbf::values::{Attribute, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

/// The rule as documented, by sorting every distance: the K-th nearest other particle (K
/// clipped), 0 replaced by the smallest positive length, or 1 where there is none.
fn brute_force(points: &[DVec3], k: usize) -> Vec<f64> {
    let n = points.len();
    let mut h: Vec<f64> = (0..n)
        .map(|i| {
            let mut d: Vec<f64> = (0..n)
                .filter(|&j| j != i)
                .map(|j| points[i].distance(points[j]))
                .collect();
            d.sort_by(f64::total_cmp);
            let k = k.min(n - 1);
            if k == 0 { 0.0 } else { d[k - 1] }
        })
        .collect();
    let floor = h
        .iter()
        .copied()
        .filter(|v| *v > 0.0)
        .fold(f64::INFINITY, f64::min);
    let floor = if floor.is_finite() { floor } else { 1.0 };
    for v in &mut h {
        if *v <= 0.0 {
            *v = floor;
        }
    }
    h
}

fn check(points: &[DVec3], k: usize, what: &str) {
    let fast = smoothing::knn_lengths(points, k);
    let slow = brute_force(points, k);
    assert_eq!(fast.len(), points.len(), "{what}");
    for (i, (a, b)) in fast.iter().zip(&slow).enumerate() {
        assert!(a.is_finite() && *a > 0.0, "{what}: h[{i}] = {a}");
        assert!(
            (a - b).abs() <= 1e-12 * b.max(1.0),
            "{what}: h[{i}] = {a}, brute force {b}"
        );
    }
}

#[test]
fn knn_lengths_equal_brute_force_on_awkward_sets() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(46);
    let mut random = |n: usize| -> Vec<DVec3> {
        (0..n)
            .map(|_| {
                DVec3::new(
                    rng.random(),
                    rng.random::<f64>() * 3.0,
                    rng.random::<f64>() - 7.0,
                )
            })
            .collect()
    };
    assert!(smoothing::knn_lengths(&[], 32).is_empty());
    assert_eq!(
        smoothing::knn_lengths(&[DVec3::new(5.0, 1.0, 2.0)], 32),
        [1.0]
    );
    check(&random(2), 32, "two particles");
    check(&random(19), 32, "fewer than K");
    check(&random(33), 32, "exactly K + 1");
    check(&random(1237), 32, "random");
    check(&random(301), 5, "K = 5");
    // Co-located: every particle at one point, and groups of copies among others.
    check(&[DVec3::splat(0.25); 40], 32, "all co-located");
    let mut copies = random(60);
    for i in 0..60 {
        copies.push(copies[i % 7]);
    }
    check(&copies, 32, "copies");
    let mut lattice = Vec::new();
    for i in 0..7 {
        for j in 0..5 {
            for k in 0..3 {
                lattice.push(
                    DVec3::new(1e4, -2e3, 0.0) + 0.1 * DVec3::new(i as f64, j as f64, k as f64),
                );
            }
        }
    }
    check(&lattice, 32, "lattice");
    check(&lattice, 6, "lattice, K = 6");
}

fn data_args(data: &Path, smoothing: Smoothing) -> DataArgs {
    DataArgs {
        scene: None,
        data: Some(data.to_path_buf()),
        format: None,
        step: Some(1),
        time: None,
        cache_mib: 64,
        particle_type: None,
        physical: false,
        smoothing: Some(smoothing),
        rescan: false,
        periodic: None,
        no_periodic: false,
    }
}

#[test]
fn knn_lengths_are_the_series_radius_attribute_and_cached_beside_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let steps: Vec<Step> = [150, 211]
        .into_iter()
        .enumerate()
        .map(|(s, n)| Step {
            name: format!("s{s}"),
            positions: (0..n)
                .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
                .collect(),
            attributes: vec![Attribute {
                name: "mass".into(),
                values: vec![1.0; n],
            }],
        })
        .collect();
    let first = io::write_series(dir.path(), "nbody", &steps, Format::Npy, "mass").unwrap();
    let smoothing: Smoothing = "knn:12".parse().unwrap();
    let field = FieldOptions {
        attribute: Some("col3".into()),
        ..FieldOptions::default()
    };
    let resolved = resolve(&data_args(&first, smoothing), &field).unwrap();
    assert_eq!(resolved.field.radius_attribute.as_deref(), Some("h_knn12"));
    let step = resolved.series.step(1).unwrap();
    let h = &step.attribute("h_knn12").unwrap().values;
    let positions = io::read_step(
        &io::list_steps(&first, None).unwrap()[1],
        &io::AttributeSelection::All,
    )
    .unwrap()
    .positions;
    assert_eq!(*h, brute_force(&positions, 12));

    // Cached beside the data: one file per step, and a second open reads them.
    let cache = dir.path().join(smoothing::CACHE_DIR);
    let cached: Vec<_> = std::fs::read_dir(&cache).unwrap().flatten().collect();
    assert_eq!(cached.len(), 2, "{cached:?}");
    let again = resolve(&data_args(&first, smoothing), &field).unwrap();
    assert_eq!(
        again
            .series
            .step(1)
            .unwrap()
            .attribute("h_knn12")
            .unwrap()
            .values,
        *h
    );

    // A scene file written from it says how the lengths were made: opened with no flag but
    // the scene, it has the same radius attribute with the same lengths.
    let (data, field_section) = resolved.scene_sections();
    assert_eq!(data.smoothing, Some(smoothing));
    let scene = aarbf::scene_file::SceneFile {
        data,
        field: field_section,
        ..Default::default()
    };
    let path = dir.path().join("knn.toml");
    scene.save(&path, false).unwrap();
    let from_scene = DataArgs {
        scene: Some(path),
        data: None,
        smoothing: None,
        ..data_args(&first, smoothing)
    };
    let reopened = resolve(&from_scene, &FieldOptions::default()).unwrap();
    assert_eq!(reopened.field.radius_attribute.as_deref(), Some("h_knn12"));
    let step = reopened.series.step(1).unwrap();
    assert_eq!(step.attribute("h_knn12").unwrap().values, *h);
}
