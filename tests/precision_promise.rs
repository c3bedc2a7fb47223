//! The precision promise, as a user meets it: `aarbf field` at its default `--precision auto`
//! (tolerance 1e-5) on every backend, over generated scenes that stress every source of f32
//! error at once: 1 to 20,000 particles; radii from 1e-6 of the domain to twice the domain
//! (every particle reaching every query, thousands of terms a sum); offsets up to 1e6;
//! attributes over nine decades; clumps inside halos. The data is written as simulations write
//! it (CSV with 17 significant digits, NumPy float64 files) and the oracle is computed here in
//! f64 (brute force, distances from exact two-term differences), owing nothing to the code
//! under test.
//!
//! Each backend prints the representation `auto` chose and its whole error bound (positions,
//! kernel, terms, summation; Theta's over the attribute's range). On every scene and backend:
//! - the measured error is at most the printed bound (Phi relative, Theta over the range);
//! - the tolerance holds: the measured Phi error is at most 1e-5 (a GPU backend whose most
//!   precise representation cannot promise it must say so, and then still meet its bound);
//! - the bound is honest, not vacuous: on the scene where a backend's error is largest, the
//!   bound is at most 10x the measured error.
//!
//! As for every truncated kernel, a point whose distance to a particle equals its radius to
//! within the rounding of positions is allowed that particle's jump (`w exp(-4.5)`).

use std::path::{Path, PathBuf};

use glam::DVec3;
use rand::{Rng, SeedableRng};

use crate::common;

struct Scene {
    name: String,
    particles: Vec<(DVec3, f64)>,
    /// A smoothing length per particle (the radius is then `radius h`), as SPH codes write.
    h: Option<Vec<f64>>,
    queries: Vec<DVec3>,
    radius: f64,
}

impl Scene {
    fn radius_of(&self, i: usize) -> f64 {
        self.radius * self.h.as_ref().map_or(1.0, |h| h[i])
    }

    /// The scene with a smoothing length per particle, U(0.5, 1.5).
    fn with_smoothing_lengths(mut self, seed: u64) -> Scene {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let n = self.particles.len();
        self.h = Some((0..n).map(|_| rng.random_range(0.5..1.5)).collect());
        self.name.push_str(", radius attribute h");
        self
    }
}

/// A scene: `n` particles in a unit cube at `offset`, a fifth of them in a clump a thousandth
/// of the domain wide (a halo around a dense core), attributes `10^U(-3, 6)`; queries within
/// reach of particles and anywhere in the domain.
fn scene(n: usize, radius: f64, offset: f64, seed: u64) -> Scene {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let mut unit = || DVec3::new(rng.random(), rng.random(), rng.random());
    let core = DVec3::splat(offset) + DVec3::new(0.3, 0.6, 0.45);
    let positions: Vec<DVec3> = (0..n)
        .map(|i| {
            if i % 5 == 0 {
                core + (unit() - 0.5) * 1e-3
            } else {
                DVec3::splat(offset) + unit()
            }
        })
        .collect();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed + 1);
    let particles: Vec<(DVec3, f64)> = positions
        .iter()
        .map(|&p| (p, 10f64.powf(rng.random_range(-3.0..6.0))))
        .collect();
    let reach = radius.min(0.5);
    let mut queries = Vec::new();
    for i in (0..n).step_by((n / 150).max(1)) {
        let d = DVec3::new(rng.random(), rng.random(), rng.random()) * 2.0 - 1.0;
        queries.push(positions[i] + d * 0.55 * reach);
    }
    for _ in 0..60 {
        queries.push(DVec3::splat(offset) + DVec3::new(rng.random(), rng.random(), rng.random()));
    }
    Scene {
        name: format!("n {n}, radius {radius:e}, offset {offset:e}"),
        particles,
        h: None,
        queries,
        radius,
    }
}

/// The scenes: every axis of the space, at its extremes and between.
fn scenes() -> Vec<Scene> {
    vec![
        scene(1, 0.3, 0.0, 1),
        scene(37, 2.0, 1e6, 2),
        scene(1001, 2.0, 0.0, 3),
        scene(4099, 0.05, 1e3, 4),
        scene(20_000, 2.0, 1e3, 5),
        scene(20_000, 2.0, 0.0, 9),
        scene(7919, 1e-6, 1e6, 6),
        scene(5003, 0.01, 0.0, 7),
        scene(2311, 0.3, -1e6, 8),
        scene(3001, 0.05, 0.0, 10).with_smoothing_lengths(11),
        scene(1500, 2.0, 1e3, 12).with_smoothing_lengths(13),
    ]
}

fn write_csv(path: &Path, scene: &Scene) {
    let mut text = String::from(if scene.h.is_some() {
        "x,y,z,s,h\n"
    } else {
        "x,y,z,s\n"
    });
    for (i, (p, s)) in scene.particles.iter().enumerate() {
        text.push_str(&format!(
            "{:.16e},{:.16e},{:.16e},{:.16e}",
            p.x, p.y, p.z, s
        ));
        if let Some(h) = &scene.h {
            text.push_str(&format!(",{:.16e}", h[i]));
        }
        text.push('\n');
    }
    std::fs::write(path, text).unwrap();
}

/// The oracle at x: Phi, Theta in [0, 1] of the range, and what particles within `edge` of
/// their radius could add to Phi's and Theta's errors.
struct Truth {
    phi: f64,
    theta: f64,
    edge_phi: f64,
    edge_theta: f64,
}

fn oracle(scene: &Scene, range: (f64, f64), edge: f64, x: DVec3) -> Truth {
    let (mut phi, mut num) = (0.0, 0.0);
    let mut edges = Vec::new();
    for (i, &(c, s)) in scene.particles.iter().enumerate() {
        let radius = scene.radius_of(i);
        let r2 = radius * radius;
        let d2 = common::exact_d2(x, c);
        let t = (s - range.0) / (range.1 - range.0);
        if (d2.sqrt() - radius).abs() <= edge {
            edges.push(t);
        }
        if d2 <= r2 {
            let p = (-4.5 * d2 / r2).exp();
            phi += p;
            num += p * t;
        }
    }
    let theta = if phi > 0.0 { num / phi } else { 0.0 };
    let jump = (-4.5f64).exp();
    let edge_phi = jump * edges.len() as f64;
    let edge_theta = if phi > 0.0 {
        edges.iter().map(|t| jump * (t - theta).abs()).sum::<f64>() / phi
    } else {
        0.0
    };
    Truth {
        phi,
        theta,
        edge_phi,
        edge_theta,
    }
}

/// What a backend printed: its representation's Phi and Theta bounds (0 for the f64
/// reference), and whether it said the tolerance is out of its reach.
struct Stated {
    line: String,
    phi: f64,
    theta: f64,
    above_tolerance: bool,
}

fn stated(stderr: &str, backend: &str) -> Stated {
    let line = stderr
        .lines()
        .find(|l| l.contains(&format!("{backend}: ")) && l.contains(" sums"))
        .unwrap_or_else(|| panic!("{backend} printed no representation:\n{stderr}"))
        .to_string();
    let number_after = |key: &str| -> f64 {
        line.split(key)
            .nth(1)
            .and_then(|rest| rest.split([' ', ',', ')', ';']).next())
            .map(|v| {
                v.parse()
                    .unwrap_or_else(|_| panic!("a number after {key}: {line}"))
            })
            .unwrap_or(0.0)
    };
    Stated {
        phi: number_after("relative Phi error at most "),
        theta: number_after("Theta at most "),
        above_tolerance: line.contains("ABOVE the tolerance"),
        line,
    }
}

fn field(
    data: &Path,
    queries: &Path,
    scene: &Scene,
    backend: &str,
    out: &Path,
) -> (Vec<[f64; 2]>, Stated) {
    let npy = data.extension().is_some_and(|e| e == "npy");
    let (attribute, h) = if npy { ("col3", "col4") } else { ("s", "h") };
    let radius = scene.radius;
    let mut args: Vec<std::ffi::OsString> = vec![
        "--data".into(),
        data.into(),
        "--attribute".into(),
        attribute.into(),
        "--radius".into(),
        format!("{radius:e}").into(),
        "--queries".into(),
        queries.into(),
    ];
    if scene.h.is_some() {
        args.extend(["--radius-attribute".into(), h.into()]);
    }
    let (got, stderr) = common::aarbf_field(&args, backend, out);
    (got, stated(&stderr, backend))
}

/// One backend on one scene: the largest errors (Phi relative, Theta over the range) where no
/// particle sits on the edge, and the queries that broke the stated bound or the tolerance.
struct Measured {
    phi: f64,
    theta: f64,
    over_bound: Vec<String>,
    over_tolerance: usize,
}

fn measure(got: &[[f64; 2]], truth: &[Truth], range: (f64, f64), stated: &Stated) -> Measured {
    let width = range.1 - range.0;
    let mut m = Measured {
        phi: 0.0,
        theta: 0.0,
        over_bound: Vec::new(),
        over_tolerance: 0,
    };
    for (i, (g, t)) in got.iter().zip(truth).enumerate() {
        if t.phi <= 0.0 {
            assert_eq!(
                g[0], 0.0,
                "query {i}: Phi {} where no particle reaches",
                g[0]
            );
            continue;
        }
        let e_phi = (g[0] - t.phi).abs();
        let e_theta = (((g[1] - range.0) / width) - t.theta).abs();
        if t.edge_phi == 0.0 {
            m.phi = m.phi.max(e_phi / t.phi);
            m.theta = m.theta.max(e_theta);
        }
        // The bound, and the tolerance, with a particle's jump allowed at its edge (and the
        // f64 reference's own rounding, some 1e-15, where the stated bound is 0).
        let floor = 1e-12;
        if e_phi > (stated.phi + floor) * t.phi + t.edge_phi
            || e_theta > stated.theta + floor + t.edge_theta
        {
            m.over_bound.push(format!(
                "query {i}: Phi {} vs {} ({:.2e}), Theta error {e_theta:.2e}, edge {:.1e}",
                g[0],
                t.phi,
                e_phi / t.phi,
                t.edge_phi
            ));
        }
        if e_phi > 1e-5 * t.phi + t.edge_phi {
            m.over_tolerance += 1;
        }
    }
    m
}

#[test]
fn every_backend_meets_its_printed_bound_and_the_tolerance_on_generated_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let mut table = Vec::new();
    let mut failures = Vec::new();
    // Per backend: (measured Phi error, bound, scene) of each scene.
    type Results = Vec<(f64, f64, String)>;
    let mut per_backend: Vec<(&str, Results)> =
        ["cpu", "wgpu", "ash"].map(|b| (b, Vec::new())).into();
    for (k, scene) in scenes().iter().enumerate() {
        let range = scene
            .particles
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p.1), hi.max(p.1))
            });
        let data: PathBuf = if k % 2 == 0 {
            let p = dir.path().join(format!("scene{k}.csv"));
            write_csv(&p, scene);
            p
        } else {
            let p = dir.path().join(format!("scene{k}.npy"));
            let cols = 4 + usize::from(scene.h.is_some());
            let flat: Vec<f64> = scene
                .particles
                .iter()
                .enumerate()
                .flat_map(|(i, (c, s))| {
                    [c.x, c.y, c.z, *s]
                        .into_iter()
                        .chain(scene.h.as_ref().map(|h| h[i]))
                })
                .collect();
            common::write_numpy(&p, scene.particles.len(), cols, &flat);
            p
        };
        let queries = dir.path().join(format!("queries{k}.npy"));
        let flat: Vec<f64> = scene.queries.iter().flat_map(|q| q.to_array()).collect();
        common::write_numpy(&queries, scene.queries.len(), 3, &flat);
        // Which side of a radius a point falls on is the positions' rounding's choice: f32
        // local coordinates (the domain is a unit cube about its centre), or a double-single
        // pair's hi part.
        let widest = scene.radius * scene.h.as_ref().map_or(1.0, |_| 1.5);
        let local = 1.0 + widest.min(1.0);
        let edge = 8.0 * f64::from(f32::EPSILON) * (widest + local);
        let truth: Vec<Truth> = scene
            .queries
            .iter()
            .map(|&x| oracle(scene, range, edge, x))
            .collect();
        for (backend, results) in per_backend.iter_mut() {
            let out = dir.path().join(format!("out{k}-{backend}.npy"));
            let (got, stated) = field(&data, &queries, scene, backend, &out);
            let m = measure(&got, &truth, range, &stated);
            table.push(format!(
                "| {} | {backend} | {} | {:.1e} / {:.1e} | {:.1e} / {:.1e} |",
                scene.name,
                stated
                    .line
                    .split(": relative")
                    .next()
                    .unwrap_or("")
                    .split(&format!("{backend}: "))
                    .nth(1)
                    .unwrap_or(""),
                stated.phi,
                stated.theta,
                m.phi,
                m.theta
            ));
            if !m.over_bound.is_empty() {
                failures.push(format!(
                    "{} on {backend}: {} queries over the printed bound ({})\n  {}",
                    scene.name,
                    m.over_bound.len(),
                    stated.line,
                    m.over_bound[..m.over_bound.len().min(3)].join("\n  ")
                ));
            }
            if m.over_tolerance > 0 && !stated.above_tolerance {
                failures.push(format!(
                    "{} on {backend}: {} queries over the tolerance 1e-5 that auto promised ({})",
                    scene.name, m.over_tolerance, stated.line
                ));
            }
            if *backend == "cpu" && stated.above_tolerance {
                failures.push(format!(
                    "{} on cpu: auto should have taken f64 ({})",
                    scene.name, stated.line
                ));
            }
            results.push((m.phi, stated.phi, scene.name.clone()));
        }
    }
    eprintln!(
        "| scene | backend | representation | bound Phi / Theta | measured Phi / Theta |\n|---|---|---|---|---|\n{}",
        table.join("\n")
    );
    // Honest, not vacuous: where a backend's error is largest, its bound is within 10x of it.
    for (backend, results) in &per_backend {
        let (err, bound, name) = results
            .iter()
            .filter(|r| r.1 > 0.0)
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .cloned()
            .unwrap_or((0.0, 0.0, String::new()));
        if bound > 0.0 && bound > 10.0 * err {
            failures.push(format!(
                "{backend}: on its worst scene ({name}) the bound {bound:.1e} is over 10x the error {err:.1e}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
