//! The wgpu LBVH backend against the CPU backend (rayon + obvhs), side by side in one run, through
//! the `Backend` trait: build and refit times, field queries per second, a 1024x1024 1-spp frame
//! of the demo scene, and structure bytes per particle for each cluster size. Results go to
//! docs/benchmarks.md. On a machine without a GPU, wgpu runs on lavapipe (the same CPU cores).
//!
//! cargo bench --bench wgpu_lbvh -- [N ...] [--queries M] [--frame-size S]
//!     (defaults: N = 100000 1000000 4000000, M = 1000000, S = 1024)
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::time::{Duration, Instant};

use aarbf::accel::{ClusterSize, hilbert_order};
use aarbf::backend::cpu::CpuBackend;
use aarbf::backend::wgpu_lbvh::WgpuBackend;
use aarbf::backend::{Backend, StepInput};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Attribute, Bounds, Step};
use aarbf::values::{Integrator, NoiseKind};
use glam::DVec3;
use rand::{Rng, SeedableRng};

fn uniform_step(n: usize, seed: u64) -> Step {
    let mut r = rand_pcg::Pcg64::seed_from_u64(seed);
    Step {
        name: format!("uniform{n}"),
        positions: (0..n)
            .map(|_| DVec3::new(r.random(), r.random(), r.random()))
            .collect(),
        attributes: vec![Attribute {
            name: "a".into(),
            values: (0..n).map(|_| r.random::<f64>()).collect(),
        }],
    }
}

/// The radius at which ~30 particles reach a point (unit cube).
fn radius_for(n: usize) -> f64 {
    aarbf::study::data::radius_for_overlap(30.0, n)
}

const UNIT: Bounds = Bounds {
    min: DVec3::ZERO,
    max: DVec3::ONE,
};

fn input<'a>(step: &'a std::sync::Arc<Step>, field: &'a FieldSettings, k: u32) -> StepInput<'a> {
    StepInput {
        step,
        field,
        cluster: ClusterSize::new(k).unwrap(),
        series_bounds: UNIT,
        series_range: Some((0.0, 1.0)),
        precision: aarbf::backend::Precision::FIELD,
    }
}

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64()
}

fn ms(s: f64) -> String {
    format!("{:.1}", s * 1e3)
}

/// Upload once, then the median of 3 builds and of 3 refits (radius alternating by 10%).
fn build_and_refit(
    b: &mut dyn Backend,
    step: &std::sync::Arc<Step>,
    field: &FieldSettings,
    k: u32,
) -> [f64; 3] {
    b.upload(&input(step, field, k)).unwrap();
    let upload = (b.timings().prepare + b.timings().upload).as_secs_f64();
    let mut builds = Vec::new();
    for _ in 0..3 {
        b.build().unwrap();
        builds.push(b.timings().build);
    }
    let mut refits = Vec::new();
    let mut f = field.clone();
    for i in 0..3 {
        f.radius = field.radius * if i % 2 == 0 { 1.1 } else { 1.0 };
        b.refit(&f).unwrap();
        refits.push(b.timings().refit);
    }
    [upload, median(builds), median(refits)]
}

fn main() {
    let mut sizes = Vec::new();
    let mut queries = 1_000_000usize;
    let mut frame_size = 1024u32;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--queries" => queries = args.next().and_then(|v| v.parse().ok()).unwrap(),
            "--frame-size" => frame_size = args.next().and_then(|v| v.parse().ok()).unwrap(),
            _ => {
                if let Ok(n) = a.parse() {
                    sizes.push(n);
                }
            }
        }
    }
    if sizes.is_empty() {
        sizes = vec![100_000, 1_000_000, 4_000_000];
    }
    let mut wgpu = WgpuBackend::new().expect("a wgpu adapter (lavapipe: cargo xtask setup)");
    let mut cpu = CpuBackend::new();
    println!(
        "wgpu: {}; cpu: {}\n",
        wgpu.capabilities().device,
        cpu.capabilities().device
    );

    // Warm-up: compile every pipeline the runs below use (lavapipe JIT-compiles on creation).
    {
        let step = std::sync::Arc::new(uniform_step(10_000, 9));
        let f = FieldSettings::new(Some("a"), radius_for(10_000));
        for k in [1, 4, 16] {
            build_and_refit(&mut wgpu, &step, &f, k);
            wgpu.query(&[DVec3::splat(0.5)]).unwrap();
        }
    }

    println!(
        "### Build and refit (K = 1, uniform random particles, ~30 within reach of a point)\n"
    );
    println!(
        "| N | cpu upload (ms) | cpu build (ms) | cpu refit (ms) | wgpu upload (ms) | wgpu build (ms) | wgpu refit (ms) | wgpu refit / build |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &n in &sizes {
        let step = std::sync::Arc::new(uniform_step(n, 1));
        let f = FieldSettings::new(Some("a"), radius_for(n));
        let c = build_and_refit(&mut cpu, &step, &f, 1);
        let g = build_and_refit(&mut wgpu, &step, &f, 1);
        println!(
            "| {n} | {} | {} | {} | {} | {} | {} | {:.2} |",
            ms(c[0]),
            ms(c[1]),
            ms(c[2]),
            ms(g[0]),
            ms(g[1]),
            ms(g[2]),
            g[2] / g[1]
        );
    }

    let n = *sizes
        .iter()
        .min_by_key(|&&s| s.abs_diff(1_000_000))
        .unwrap();
    let step = std::sync::Arc::new(uniform_step(n, 2));
    let f = FieldSettings::new(Some("a"), radius_for(n));
    let mut r = rand_pcg::Pcg64::seed_from_u64(3);
    let points: Vec<DVec3> = (0..queries)
        .map(|_| DVec3::new(r.random(), r.random(), r.random()))
        .collect();
    // As `aarbf field` does: queries in Hilbert order (faster on both backends).
    let sorted: Vec<DVec3> = hilbert_order(&points, UNIT)
        .iter()
        .map(|&i| points[i as usize])
        .collect();
    println!(
        "\n### Field queries ({n} particles, {queries} uniform queries in Hilbert order, radius {:.5})\n",
        f.radius
    );
    println!(
        "| K | cpu (M queries/s) | wgpu (M queries/s) | wgpu / cpu | mean Phi cpu | mean Phi wgpu |"
    );
    println!("|---|---|---|---|---|---|");
    let mut memory = Vec::new();
    for k in [1u32, 2, 4, 8, 16] {
        let mut rates = [0.0; 2];
        let mut means = [0.0; 2];
        for (i, b) in [&mut cpu as &mut dyn Backend, &mut wgpu]
            .into_iter()
            .enumerate()
        {
            b.upload(&input(&step, &f, k)).unwrap();
            b.build().unwrap();
            if [1, 4, 16].contains(&k) {
                let started = Instant::now();
                let out = b.query(&sorted).unwrap();
                rates[i] = queries as f64 / started.elapsed().as_secs_f64() / 1e6;
                means[i] = out.iter().map(|v| v.0).sum::<f64>() / queries as f64;
            }
            memory.push((k, i, b.memory()));
        }
        if [1, 4, 16].contains(&k) {
            println!(
                "| {k} | {:.3} | {:.3} | {:.2} | {:.4} | {:.4} |",
                rates[0],
                rates[1],
                rates[1] / rates[0],
                means[0],
                means[1]
            );
        }
    }

    println!("\n### Structure bytes per particle ({n} particles)\n");
    println!(
        "| K | wgpu structure (B/particle) | wgpu structure / particle bytes | wgpu build scratch (B/particle) | cpu structure (B/particle) |"
    );
    println!("|---|---|---|---|---|");
    for k in [1u32, 2, 4, 8, 16] {
        let c = memory.iter().find(|m| m.0 == k && m.1 == 0).unwrap().2;
        let g = memory.iter().find(|m| m.0 == k && m.1 == 1).unwrap().2;
        // Sort scratch: keys and values twice (4 x 4 B a cluster) and the digit histogram.
        let clusters = ClusterSize::new(k).unwrap().clusters_for(n);
        let scratch = 16 * clusters + 64 * clusters.div_ceil(4096);
        println!(
            "| {k} | {:.2} | {:.3} | {:.2} | {:.2} |",
            g.structure_bytes as f64 / n as f64,
            g.structure_bytes as f64 / g.particle_bytes as f64,
            scratch as f64 / n as f64,
            c.structure_bytes as f64 / n as f64,
        );
    }

    // The demo scene as `cargo xtask demo` renders it (dam break step 14, radius 1.5%,
    // stochastic marching on blue noise), 1 spp at frame_size^2.
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(20_000, 48, 1));
    let f = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    println!(
        "\n### Demo frame ({frame_size}x{frame_size}, 1 spp, dam break step 14, 20K particles, stochastic marching, STBN)\n"
    );
    println!("| K | cpu frame (s) | wgpu frame (s) | wgpu / cpu |");
    println!("|---|---|---|---|");
    let settings = RenderSettings {
        width: frame_size,
        height: frame_size,
        integrator: Integrator::Marching,
        noise: NoiseKind::Stbn,
        ..RenderSettings::default()
    };
    for k in [1u32, 4] {
        let mut times = [0.0; 2];
        for (i, backend) in [
            Box::new(CpuBackend::new()) as Box<dyn Backend>,
            Box::new(WgpuBackend::new().unwrap()),
        ]
        .into_iter()
        .enumerate()
        {
            let mut s = RenderSession::new(backend, &series);
            s.show(&series, 14, &f, ClusterSize::new(k).unwrap())
                .unwrap();
            // A warm-up frame (pipeline compilation), then the timed frames.
            s.render(&settings, 1).unwrap();
            let mut frames = Vec::new();
            for _ in 0..3 {
                s.render(&settings, 1).unwrap();
                frames.push(s.backend().timings().frame);
            }
            times[i] = median(frames);
        }
        println!(
            "| {k} | {:.3} | {:.3} | {:.2} |",
            times[0],
            times[1],
            times[1] / times[0]
        );
    }
    println!(
        "\n{} rayon threads; medians of 3 (builds, refits, frames); wgpu timings include the wait for the device and the readback of the build's counters.",
        rayon::current_num_threads()
    );
}
