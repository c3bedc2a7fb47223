//! The ash (Vulkan ray-tracing) backend's measurements, side by side in one run on one device:
//!
//! 1. BLAS build and refit time per cluster size K for N particles (the paper's Table 1), and
//!    the BLAS's bytes per K (Table 2), from GPU timestamps;
//! 2. field queries per second through the RT pipeline and through the LBVH stack traversal
//!    as a compute pipeline on the same device (Fig. 10a: hardware vs software traversal, one
//!    device, one API, one integrator);
//! 3. the 1024 x 1024, 1-spp frame time of the demo scene, both traversals.
//!
//! cargo bench --bench ash_rt -- [N ...]        (default N: 100000 1000000 4000000)
//!
//! Results go to docs/benchmarks.md. On a machine without a GPU, Mesa lavapipe runs all of
//! it on the CPU: the numbers say nothing about RT-hardware speed-ups.
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::sync::Arc;
use std::time::Duration;

use aarbf::accel::ClusterSize;
use aarbf::backend::ash_rt::{AshBackend, Traversal};
use aarbf::backend::{Backend, StepInput};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::Integrator;
use aarbf::values::{Attribute, Step};
use glam::DVec3;
use rand::{Rng, SeedableRng};

const KS: [u32; 5] = [1, 2, 4, 8, 16];
const REPEATS: usize = 3;

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

/// N uniform random particles in the unit cube with a random attribute.
fn uniform(n: usize, seed: u64) -> Step {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    Step {
        name: format!("uniform{n}"),
        positions: (0..n)
            .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
            .collect(),
        attributes: vec![Attribute {
            name: "s".into(),
            values: (0..n).map(|_| rng.random()).collect(),
        }],
    }
}

/// The radius at which ~30 particles of N uniform ones in the unit cube overlap a point.
fn radius_for_30(n: usize) -> f64 {
    aarbf::study::data::radius_for_overlap(30.0, n)
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

fn structures(b: &mut AshBackend, sizes: &[usize]) {
    println!("## BLAS build and refit (Table 1), BLAS size (Table 2)\n");
    println!(
        "GPU timestamps, median of {REPEATS}; refit after a global-radius change. The box kernel \
         writes one AABB per cluster from positions, radius map and radius.\n"
    );
    println!(
        "| N | K | boxes | upload, CPU (ms) | box kernel (ms) | BLAS build (ms) | BLAS refit (ms) | TLAS (ms) | BLAS (MB) | BLAS bytes / particle | particle bytes |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for &n in sizes {
        let step = Arc::new(uniform(n, 7));
        let radius = radius_for_30(n);
        let field = FieldSettings::new(Some("s"), radius);
        let mut wider = field.clone();
        wider.radius *= 1.25;
        for k in KS {
            b.reserve(n);
            b.upload(&input(&step, &field, k)).unwrap();
            let mut build = Vec::new();
            let mut refit = Vec::new();
            let mut kernel = Vec::new();
            let mut tlas = Vec::new();
            for r in 0..REPEATS {
                b.build().unwrap();
                let t = b.structure_timings();
                build.push(t.blas);
                kernel.push(t.boxes);
                tlas.push(t.tlas);
                b.refit(if r % 2 == 0 { &wider } else { &field }).unwrap();
                refit.push(b.structure_timings().blas);
            }
            let bytes = b.blas_bytes();
            println!(
                "| {n} | {k} | {} | {:.0} | {:.2} | {:.1} | {:.1} | {:.3} | {:.1} | {:.1} | {} |",
                b.blas_boxes(),
                ms(b.timings().prepare + b.timings().upload + b.timings().device_prepare),
                ms(median(kernel)),
                ms(median(build)),
                ms(median(refit)),
                ms(median(tlas)),
                bytes as f64 / 1048576.0,
                bytes as f64 / n as f64,
                b.memory().particle_bytes,
            );
        }
    }
    println!();
}

/// `m` random points in the data's bounds, Hilbert-sorted (as `aarbf field` sorts its queries).
fn query_points(m: usize, bounds: aarbf::values::Bounds) -> Vec<DVec3> {
    aarbf::study::query_points(m, bounds, 11)
}

fn queries(b: &mut AshBackend, m: usize) {
    println!("## Field queries per second: RT pipeline vs LBVH compute (Fig. 10a)\n");
    println!(
        "{m} uniform random points in the data's bounds, Hilbert-sorted; GPU time of the launches \
         (best of {REPEATS}); both traversals on the same device, same particles, same RBF code. \
         For context, the CPU backend (f64, rayon over the queries, obvhs BVH over the same \
         cluster boxes; wall time).\n"
    );
    println!(
        "| data | N | radius | K | RT pipeline (M queries/s) | LBVH compute (M queries/s) | RT / LBVH | CPU backend (M queries/s) | mean Phi |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let demo = Generator::DambreakDemo
        .generate(20_000, 15, 1)
        .swap_remove(14);
    let uniform = Generator::Uniform.generate(60_000, 1, 1).swap_remove(0);
    let random = Generator::Random.generate(60_000, 1, 1).swap_remove(0);
    let sets = [
        (
            "Uniform (Poisson disk)",
            uniform,
            "distance",
            radius_for_30(60_000),
        ),
        ("Random", random, "distance", radius_for_30(60_000)),
        ("dam break (step 14)", demo, "velocity", 0.0),
    ];
    for (name, step, attribute, radius) in sets {
        let step = Arc::new(step);
        let radius = if radius > 0.0 {
            radius
        } else {
            0.015 * step.bounds().diagonal()
        };
        let field = FieldSettings::new(Some(attribute), radius);
        let points = query_points(m, step.bounds());
        for k in [1, 4, 16] {
            b.upload(&input(&step, &field, k)).unwrap();
            b.build().unwrap();
            let mut rate = [0.0; 2];
            let mut mean_phi = [0.0; 2];
            for (i, traversal) in [Traversal::RtPipeline, Traversal::Lbvh]
                .into_iter()
                .enumerate()
            {
                b.set_traversal(traversal);
                // Warm-up: compiles the pipeline variant (and builds the LBVH).
                b.query(&points[..1024]).unwrap();
                let mut best = Duration::MAX;
                for _ in 0..REPEATS {
                    let out = b.query(&points).unwrap();
                    best = best.min(b.timings().query);
                    mean_phi[i] = out.iter().map(|s| s.0).sum::<f64>() / m as f64;
                }
                rate[i] = m as f64 / best.as_secs_f64() / 1e6;
            }
            b.set_traversal(Traversal::RtPipeline);
            assert!((mean_phi[0] - mean_phi[1]).abs() <= 1e-4 * mean_phi[0]);
            let mut cpu = aarbf::backend::cpu::CpuBackend::new();
            cpu.upload(&input(&step, &field, k)).unwrap();
            cpu.build().unwrap();
            let mut best = Duration::MAX;
            for _ in 0..REPEATS {
                cpu.query(&points).unwrap();
                best = best.min(cpu.timings().query);
            }
            println!(
                "| {name} | {} | {radius:.4} | {k} | {:.3} | {:.3} | {:.2} | {:.3} | {:.3} |",
                step.len(),
                rate[0],
                rate[1],
                rate[0] / rate[1],
                m as f64 / best.as_secs_f64() / 1e6,
                mean_phi[0]
            );
        }
    }
    println!();
}

fn frames() {
    println!("## Demo scene, 1024 x 1024, 1 spp: RT pipeline vs LBVH compute\n");
    println!(
        "The dam break (20K particles) at step 14, radius 1.5% of the diagonal, K = 4, the default \
         camera, STBN; GPU time of one frame, after a 16 x 16 warm-up frame that compiles the \
         pipeline variant. For context, the CPU backend's wall time for the same frame (f64, \
         rayon, with empty-space skipping along rays, which the GPU integrators do not do).\n"
    );
    println!(
        "| integrator | RT pipeline (s) | LBVH compute (s) | LBVH / RT time | CPU backend (s) |"
    );
    println!("|---|---|---|---|---|");
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(20_000, 15, 1));
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let k = ClusterSize::new(4).unwrap();
    // Frame constants as a session derives them; the CPU session also gives the context column.
    let mut session = RenderSession::new(
        aarbf::backend::create(aarbf::backend::BackendKind::Cpu).unwrap(),
        &series,
    );
    session.show(&series, 14, &field, k).unwrap();
    let mut b = AshBackend::new().unwrap();
    let step = series.step(14).unwrap();
    let range = series.attribute("velocity").map(|a| (a.min, a.max));
    b.upload(&StepInput {
        step: &step,
        field: &field,
        cluster: k,
        series_bounds: series.bounds(),
        series_range: range,
        precision: aarbf::backend::Precision::FIELD,
    })
    .unwrap();
    b.build().unwrap();
    for integrator in [Integrator::Ea, Integrator::Marching, Integrator::Delta] {
        let settings = RenderSettings {
            width: 1024,
            height: 1024,
            integrator,
            ..RenderSettings::default()
        };
        let warm_up = RenderSettings {
            width: 16,
            height: 16,
            ..settings.clone()
        };
        let mut time = [Duration::ZERO; 2];
        for (i, traversal) in [Traversal::RtPipeline, Traversal::Lbvh]
            .into_iter()
            .enumerate()
        {
            b.set_traversal(traversal);
            b.reset();
            b.render(&session.frame_params(&warm_up, 0).unwrap())
                .unwrap();
            b.reset();
            b.render(&session.frame_params(&settings, 0).unwrap())
                .unwrap();
            time[i] = b.timings().frame;
        }
        let started = std::time::Instant::now();
        session.render(&settings, 1).unwrap();
        let cpu = started.elapsed();
        println!(
            "| {integrator:?} | {:.1} | {:.1} | {:.2} | {:.1} |",
            time[0].as_secs_f64(),
            time[1].as_secs_f64(),
            time[1].as_secs_f64() / time[0].as_secs_f64(),
            cpu.as_secs_f64()
        );
    }
    println!();
}

fn main() {
    let sizes: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let sizes = if sizes.is_empty() {
        vec![100_000, 1_000_000, 4_000_000]
    } else {
        sizes
    };
    let mut b = match AshBackend::new() {
        Ok(b) => b,
        Err(e) => {
            eprintln!("no Vulkan ray-tracing device: {e}");
            return;
        }
    };
    println!(
        "Device: {}; {} CPU threads.\n",
        b.capabilities().device,
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    structures(&mut b, &sizes);
    queries(&mut b, 200_000);
    frames();
}
