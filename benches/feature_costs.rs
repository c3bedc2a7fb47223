//! "Model only what a scene requires", measured: what each optional feature costs in bytes and
//! time on every backend, side by side in one run, so a feature a scene does not use is seen
//! to cost nothing. Results go to docs/benchmarks.md.
//!
//! cargo bench --bench feature_costs -- [N] [--frame-size S] [--summation-only]
//!     (defaults: N = 1000000 particles for the memory and build tables, S = 256;
//!     `--summation-only` runs only the last table)
//!
//! - Memory and build/refit per feature at N uniform particles, K = 1: colouring by density
//!   (no attribute), the attribute post- and pre-classified, a varying radius map, a varying
//!   density map, a per-particle radius attribute.
//! - Boxes and structure bytes per cluster size K (N / K boxes).
//! - Frame time per feature on the demo scene (dam break step 14, 20K particles): emission-
//!   absorption against single scattering (shadow rays), and each map feature on or off.
//!
//! - Plain f32 sums against compensated ones (`--precision f32` and `f32c`) on the GPU
//!   backends: query rate and frame time on the demo scene and on a scene whose radius covers
//!   the whole domain (every particle in every sum), with the error each leaves.
//!
//! Rows marked "+" add one feature to the post-classified baseline (not to the row above).
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::time::Duration;

use aarbf::accel::ClusterSize;
use aarbf::backend::Precision;
use aarbf::backend::{self, Backend, BackendKind, StepInput};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{DensityMap, RadiusMap};
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, Bounds, Step};
use aarbf::values::{Integrator, NoiseKind};
use glam::DVec3;
use rand::{Rng, SeedableRng};

const BACKENDS: [BackendKind; 3] = [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash];

fn uniform_step(n: usize, seed: u64) -> Step {
    let mut r = rand_pcg::Pcg64::seed_from_u64(seed);
    Step {
        name: format!("uniform{n}"),
        positions: (0..n)
            .map(|_| DVec3::new(r.random(), r.random(), r.random()))
            .collect(),
        attributes: vec![
            Attribute {
                name: "a".into(),
                values: (0..n).map(|_| r.random::<f64>()).collect(),
            },
            Attribute {
                name: "h".into(),
                values: (0..n).map(|_| r.random_range(0.5f64..1.5)).collect(),
            },
        ],
    }
}

/// A scene feature: its name and how it changes the field settings.
struct Feature {
    name: &'static str,
    apply: fn(&mut FieldSettings, &str),
}

fn features() -> Vec<Feature> {
    vec![
        Feature {
            name: "density only (no attribute)",
            apply: |f, _| f.attribute = None,
        },
        Feature {
            name: "attribute, post-classified",
            apply: |_, _| {},
        },
        Feature {
            name: "attribute, pre-classified",
            apply: |f, _| f.classification = Classification::Pre,
        },
        Feature {
            name: "+ varying radius map",
            apply: |f, _| f.radius_map = RadiusMap("0:0.5,1:1".parse().unwrap()),
        },
        Feature {
            name: "+ varying density map",
            apply: |f, _| f.density_map = DensityMap("0:0.2,1:1".parse().unwrap()),
        },
        Feature {
            name: "+ per-particle radius",
            apply: |f, h| f.radius_attribute = Some(h.to_owned()),
        },
    ]
}

fn field_for(feature: &Feature, attribute: &str, radius: f64, h: &str) -> FieldSettings {
    let mut f = FieldSettings::new(Some(attribute), radius);
    (feature.apply)(&mut f, h);
    f
}

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64()
}

fn mb(bytes: usize) -> String {
    format!("{:.1}", bytes as f64 / 1e6)
}

fn main() {
    let mut args = std::env::args().skip(1).filter(|a| a != "--bench");
    let mut n = 1_000_000usize;
    let mut frame_size = 256u32;
    let mut summation_only = false;
    while let Some(a) = args.next() {
        if a == "--summation-only" {
            summation_only = true;
        } else if a == "--frame-size" {
            frame_size = args
                .next()
                .and_then(|v| v.parse().ok())
                .expect("--frame-size S");
        } else {
            n = a.parse().expect("N: a particle count");
        }
    }
    let mut backends: Vec<(BackendKind, Box<dyn Backend>)> = Vec::new();
    for kind in BACKENDS {
        match backend::create(kind) {
            Ok(b) => {
                println!("{kind}: {}", b.capabilities().device);
                backends.push((kind, b));
            }
            Err(e) => println!("{kind}: unavailable ({e})"),
        }
    }

    if summation_only {
        summation_costs(&mut backends, frame_size);
        return;
    }
    // Bytes and build times per feature.
    let step = std::sync::Arc::new(uniform_step(n, 7));
    let unit = Bounds {
        min: DVec3::ZERO,
        max: DVec3::ONE,
    };
    let radius = (30.0 * 3.0 / (4.0 * std::f64::consts::PI * n as f64)).cbrt();
    println!("\n### Bytes and build times per feature ({n} uniform particles, K = 1)\n");
    println!(
        "| feature | backend | particle bytes (MB) | B / particle | structure (MB) | upload (ms) | build (ms) | refit (ms) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for feature in features() {
        let field = field_for(&feature, "a", radius, "h");
        for (kind, b) in &mut backends {
            let input = StepInput {
                step: &step,
                field: &field,
                cluster: ClusterSize::new(1).unwrap(),
                series_bounds: unit,
                series_range: Some((0.0, 1.0)),
                precision: Precision::F32,
            };
            b.upload(&input).unwrap();
            // The whole upload: CPU preparation, copy and the preparation on the device.
            let t = b.timings();
            let upload = (t.prepare + t.upload + t.device_prepare).as_secs_f64();
            let mut builds = Vec::new();
            for _ in 0..3 {
                b.build().unwrap();
                builds.push(b.timings().build);
            }
            let mut refits = Vec::new();
            let mut f = field.clone();
            for i in 0..3 {
                f.radius = radius * if i % 2 == 0 { 1.1 } else { 1.0 };
                b.refit(&f).unwrap();
                refits.push(b.timings().refit);
            }
            let m = b.memory();
            println!(
                "| {} | {kind} | {} | {:.1} | {} | {:.0} | {:.1} | {:.1} |",
                feature.name,
                mb(m.particle_bytes),
                m.particle_bytes as f64 / n as f64,
                mb(m.structure_bytes),
                upload * 1e3,
                median(builds) * 1e3,
                median(refits) * 1e3,
            );
        }
    }

    // Boxes per cluster size.
    println!("\n### Structure per cluster size ({n} particles, attribute post-classified)\n");
    println!("| K | boxes (N / K) | backend | structure (MB) | structure B / particle |");
    println!("|---|---|---|---|---|");
    let field = FieldSettings::new(Some("a"), radius);
    for k in [1u32, 2, 4, 8, 16] {
        let cluster = ClusterSize::new(k).unwrap();
        for (kind, b) in &mut backends {
            b.upload(&StepInput {
                step: &step,
                field: &field,
                cluster,
                series_bounds: unit,
                series_range: Some((0.0, 1.0)),
                precision: Precision::F32,
            })
            .unwrap();
            b.build().unwrap();
            let m = b.memory();
            println!(
                "| {k} | {} | {kind} | {} | {:.2} |",
                cluster.clusters_for(n),
                mb(m.structure_bytes),
                m.structure_bytes as f64 / n as f64
            );
        }
    }

    // What double-single positions cost a scene that needs them (and what f32 saves one that
    // does not): the same step, both precisions forced, on the GPU backends.
    let queries = 200_000;
    let mut r = rand_pcg::Pcg64::seed_from_u64(11);
    let points: Vec<DVec3> = (0..queries)
        .map(|_| DVec3::new(r.random(), r.random(), r.random()))
        .collect();
    let points: Vec<DVec3> = aarbf::accel::hilbert_order(&points, unit)
        .iter()
        .map(|&i| points[i as usize])
        .collect();
    println!(
        "\n### Positions: f32 against double-single ({n} particles, K = 1 and 16, {queries} Hilbert-ordered queries; median of 3)\n"
    );
    println!(
        "| K | backend | positions | particle bytes (MB) | B / particle | build (ms) | queries/s |"
    );
    println!("|---|---|---|---|---|---|---|");
    for k in [1u32, 16] {
        for (kind, b) in &mut backends {
            if *kind == BackendKind::Cpu {
                continue;
            }
            for precision in [Precision::F32, Precision::DoubleSingle] {
                b.upload(&StepInput {
                    step: &step,
                    field: &field,
                    cluster: ClusterSize::new(k).unwrap(),
                    series_bounds: unit,
                    series_range: Some((0.0, 1.0)),
                    precision,
                })
                .unwrap();
                b.build().unwrap();
                let build = b.timings().build;
                b.query(&points[..1000]).unwrap();
                let mut times = Vec::new();
                for _ in 0..3 {
                    b.query(&points).unwrap();
                    times.push(b.timings().query);
                }
                let m = b.memory();
                println!(
                    "| {k} | {kind} | {precision:?} | {} | {:.1} | {:.1} | {:.2} M |",
                    mb(m.particle_bytes),
                    m.particle_bytes as f64 / n as f64,
                    build.as_secs_f64() * 1e3,
                    queries as f64 / median(times) / 1e6
                );
            }
        }
    }
    drop(step);

    // Frame time per feature and integrator on the demo scene.
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(20_000, 15, 1));
    let demo_radius = 0.015 * series.bounds().diagonal();
    // Frame time with each precision forced on the GPU backends.
    println!(
        "\n### Frame time with f32 or double-single positions ({frame_size}x{frame_size}, 1 spp, dam break step 14, K = 4; median of 3 after a warm-up)\n"
    );
    println!("| integrator | backend | f32 (ms) | double-single (ms) | ds / f32 |");
    println!("|---|---|---|---|---|");
    let field = FieldSettings::new(Some("velocity"), demo_radius);
    for integrator in [Integrator::Ea, Integrator::Marching] {
        let settings = RenderSettings {
            width: frame_size,
            height: frame_size,
            integrator,
            noise: NoiseKind::Stbn,
            ..RenderSettings::default()
        };
        for kind in [BackendKind::Wgpu, BackendKind::Ash] {
            let Ok(b) = backend::create(kind) else {
                continue;
            };
            let mut s = RenderSession::new(b, &series);
            let mut ms = Vec::new();
            for precision in [Precision::F32, Precision::DoubleSingle] {
                s.set_precision(precision);
                s.show(&series, 14, &field, ClusterSize::new(4).unwrap())
                    .unwrap();
                s.render(&settings, 1).unwrap();
                let mut frames = Vec::new();
                for _ in 0..3 {
                    s.render(&settings, 1).unwrap();
                    frames.push(s.backend().timings().frame);
                }
                ms.push(median(frames) * 1e3);
            }
            println!(
                "| {integrator:?} | {kind} | {:.0} | {:.0} | {:.2} |",
                ms[0],
                ms[1],
                ms[1] / ms[0]
            );
        }
    }

    println!(
        "\n### Frame time per feature ({frame_size}x{frame_size}, 1 spp, STBN, dam break step 14, 20K particles, K = 4; median of 3 after a warm-up)\n"
    );
    println!("| feature | integrator | cpu (ms) | wgpu (ms) | ash (ms) |");
    println!("|---|---|---|---|---|");
    let mut sessions: Vec<(BackendKind, RenderSession)> = BACKENDS
        .iter()
        .filter_map(|&k| Some((k, RenderSession::new(backend::create(k).ok()?, &series))))
        .collect();
    for feature in features() {
        // The demo data has no smoothing length: its own attribute stands in as h.
        let field = field_for(&feature, "velocity", demo_radius, "velocity");
        // EA against the single-scattering reference, which is the same march plus one shadow
        // ray per sample: the difference is what shadow rays cost, and EA does not pay it.
        for integrator in [
            Integrator::Ea,
            Integrator::SsReference,
            Integrator::Marching,
        ] {
            let settings = RenderSettings {
                width: frame_size,
                height: frame_size,
                integrator,
                noise: NoiseKind::Stbn,
                colour_by_density: field.attribute.is_none(),
                ..RenderSettings::default()
            };
            let mut row = format!("| {} | {integrator:?} |", feature.name);
            for kind in BACKENDS {
                let Some((_, s)) = sessions.iter_mut().find(|(k, _)| *k == kind) else {
                    row.push_str(" – |");
                    continue;
                };
                s.show(&series, 14, &field, ClusterSize::new(4).unwrap())
                    .unwrap();
                s.render(&settings, 1).unwrap();
                let mut frames = Vec::new();
                for _ in 0..3 {
                    s.render(&settings, 1).unwrap();
                    frames.push(s.backend().timings().frame);
                }
                row.push_str(&format!(" {:.0} |", median(frames) * 1e3));
            }
            println!("{row}");
        }
    }
    drop(sessions);
    summation_costs(&mut backends, frame_size);
    println!(
        "\n{} rayon threads. Builds and refits are medians of 3; GPU times include submission and the wait for the device.",
        rayon::current_num_threads()
    );
}

/// Plain f32 sums against compensated ones on the GPU backends (the CPU's f32 kernel sums
/// blocks of eight terms a lane and adds them in f64 always: its row is for scale): the query
/// rate, the largest relative Phi error against the CPU's f64 reference, and the frame time, on
/// the demo scene (tens of terms a sum) and on 2,000 particles whose radius is twice the domain
/// (2,000 terms a sum).
fn summation_costs(backends: &mut [(BackendKind, Box<dyn Backend>)], frame_size: u32) {
    let demo = TimeSeries::from_steps(Generator::DambreakDemo.generate(20_000, 15, 1));
    let demo_radius = 0.015 * demo.bounds().diagonal();
    let whole = TimeSeries::from_steps(vec![uniform_step(2000, 13)]);
    let scenes = [
        (
            "dam break step 14 (20K)",
            &demo,
            14,
            "velocity",
            demo_radius,
        ),
        (
            "2,000 particles, radius 2x the domain",
            &whole,
            0,
            "a",
            2.0 * whole.bounds().diagonal(),
        ),
    ];
    println!(
        "\n### Summation: plain f32 against compensated ({frame_size}x{frame_size} EA frames, 1 spp; 20,000 Hilbert-ordered queries near particles; K = 4; medians of 3)\n"
    );
    println!("| scene | backend | sums | queries/s | worst relative Phi error | frame (ms) |");
    println!("|---|---|---|---|---|---|");
    let cluster = ClusterSize::new(4).unwrap();
    for (name, series, step_index, attribute, radius) in scenes {
        let step = series.step(step_index).unwrap();
        let field = FieldSettings::new(Some(attribute), radius);
        let mut r = rand_pcg::Pcg64::seed_from_u64(5);
        let reach = radius.min(0.5 * series.bounds().diagonal());
        let points: Vec<DVec3> = (0..20_000)
            .map(|i| {
                let d = DVec3::new(r.random(), r.random(), r.random()) * 2.0 - 1.0;
                step.positions[i % step.len()] + d * 0.3 * reach
            })
            .collect();
        let range = series.attribute(attribute).map(|a| (a.min, a.max));
        let input = |precision| StepInput {
            step: &step,
            field: &field,
            cluster,
            series_bounds: series.bounds(),
            series_range: range,
            precision,
        };
        let mut reference = backend::create(BackendKind::Cpu).unwrap();
        reference.upload(&input(Precision::F64)).unwrap();
        reference.build().unwrap();
        let truth = backend::query_in_hilbert_order(reference.as_mut(), &points, |_| {}).unwrap();
        for (kind, b) in backends.iter_mut() {
            let precisions: &[Precision] = if *kind == BackendKind::Cpu {
                &[Precision::F32]
            } else {
                &[Precision::F32, Precision::F32Compensated]
            };
            for &precision in precisions {
                b.upload(&input(precision)).unwrap();
                b.build().unwrap();
                let mut times = Vec::new();
                let mut got = Vec::new();
                for _ in 0..3 {
                    got = backend::query_in_hilbert_order(b.as_mut(), &points, |_| {}).unwrap();
                    times.push(b.timings().query);
                }
                let worst = got
                    .iter()
                    .zip(&truth)
                    .filter(|(_, t)| t.0 > 0.0)
                    .map(|(g, t)| (g.0 / t.0 - 1.0).abs())
                    .fold(0.0, f64::max);
                let sums = match b.representation().map(|r| r.summation) {
                    Some(aarbf::backend::precision::Summation::Compensated { .. }) => "compensated",
                    Some(aarbf::backend::precision::Summation::Blocked { .. }) => "blocked (f64)",
                    _ => "plain f32",
                };
                let frame = {
                    let Ok(fresh) = backend::create(*kind) else {
                        continue;
                    };
                    let mut s = RenderSession::new(fresh, series);
                    s.set_precision(precision);
                    s.show(series, step_index, &field, cluster).unwrap();
                    let settings = RenderSettings {
                        width: frame_size,
                        height: frame_size,
                        integrator: Integrator::Ea,
                        noise: NoiseKind::Stbn,
                        ..RenderSettings::default()
                    };
                    s.render(&settings, 1).unwrap();
                    let mut frames = Vec::new();
                    for _ in 0..3 {
                        s.render(&settings, 1).unwrap();
                        frames.push(s.backend().timings().frame);
                    }
                    median(frames) * 1e3
                };
                println!(
                    "| {name} | {kind} | {sums} | {:.2} M | {worst:.1e} | {frame:.0} |",
                    points.len() as f64 / median(times) / 1e6
                );
            }
        }
    }
}
