//! How close the CPU backend's field queries run to what this machine can do: the peak rate
//! of RBF terms (w · exp(-4.5 d²/r²) for particles within r) in a tight loop over particles
//! in cache (a scalar f64 loop as the reference evaluates a term; the f32 kernel's AVX-512,
//! AVX2 and baseline builds: the widest the CPU has is its peak), against the terms per second
//! the backend achieves on N particles × M queries (~30 terms a query) in f64 and in f32 (in
//! each build of the f32 kernel), at every thread count up to the machine's. Each rate is the
//! best run of a stretch of runs, and each peak is measured before and after the backend, the
//! higher kept: what the machine does when no other process holds its cores.
//! Results go to docs/benchmarks.md.
//!
//! cargo xtask bench cpu_roofline -- [N] [M]     (defaults: 1000000 1000000)
//!
//! Terms: a term is one particle within r of a query (what the field sums). The achieved
//! count is exact: every (query, particle) pair within r, counted on a uniform grid of cell
//! size r independently of the backend's tree.
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::time::Instant;

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, Backend, BackendKind, Precision, StepInput};
use aarbf::field::FieldSettings;
use aarbf::field::f32_kernel::{self, Packed};
use aarbf::scene::synth::Generator;
use aarbf::values::Bounds;
use glam::DVec3;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Particles in the in-cache block of the peak loops (f64: 4 arrays x 32 KiB).
const BLOCK: usize = 4096;
/// Query points each peak loop evaluates against the block.
const PEAK_QUERIES: usize = 256;

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(1_000_000);
    let m = args.get(1).copied().unwrap_or(1_000_000);
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());

    let t = Instant::now();
    let step = Generator::Uniform.generate(n, 1, 1).remove(0);
    // N (4/3) pi r^3 = 30 particles within r of a point (unit cube).
    let radius = (30.0 * 3.0 / (4.0 * std::f64::consts::PI * n as f64)).cbrt();
    let field = FieldSettings::new(None, radius);
    let bounds = Bounds::of_points(&step.positions);
    let step = std::sync::Arc::new(step);
    let backend_with = |precision| -> Box<dyn Backend> {
        let mut b = backend::create(BackendKind::Cpu).unwrap();
        b.upload(&StepInput {
            step: &step,
            field: &field,
            cluster: ClusterSize::new(4).unwrap(),
            series_bounds: bounds,
            series_range: None,
            precision,
        })
        .unwrap();
        b.build().unwrap();
        b
    };
    let mut f64_backend = backend_with(Precision::F64);
    let mut f32_backend = backend_with(Precision::F32);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let mut queries: Vec<DVec3> = (0..m)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    // Hilbert order, as `aarbf field` queries.
    let order = aarbf::accel::hilbert_order(&queries, Bounds::of_points(&queries));
    queries = order.iter().map(|&i| queries[i as usize]).collect();
    let terms = count_terms(&step.positions, &queries, radius);
    eprintln!(
        "prepared {n} particles, {m} queries, {terms} terms ({:.1} a query) in {:.1} s",
        terms as f64 / m as f64,
        t.elapsed().as_secs_f64()
    );

    println!(
        "| threads | peak, f64 scalar exp (G terms/s) | peak, f32 kernel AVX-512 (G terms/s) | peak, f32 kernel AVX2 (G terms/s) | peak, f32 kernel baseline (G terms/s) | backend f64 (M terms/s) | backend f32 (M terms/s) | backend f32, AVX2 build (M terms/s) | backend f32, baseline build (M terms/s) | f64 / f64 peak | f32 / f32 peak | f32 / f64 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut threads = vec![1];
    let mut t = 2;
    while t <= cores {
        threads.push(t);
        t *= 2;
    }
    if *threads.last().unwrap() != cores {
        threads.push(cores);
    }
    let mut achieved_by_threads = Vec::new();
    // Each row's widest peak, to check that the peaks grew with the threads.
    let mut widest_peaks = Vec::new();
    let simd = f32_kernel::simd_in_use();
    let avx512 = f32_kernel::avx512_in_use();
    for &k in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap();
        let row = pool.install(|| {
            // Every build's peak: the widest the CPU has (AVX-512 where it has it: the
            // machine's peak), then AVX2 and baseline.
            let peaks = || {
                let peak64 = best_rate(PEAK_SECONDS, || peak_f64(k));
                let peak_widest = best_rate(PEAK_SECONDS, || peak_f32_kernel(k));
                f32_kernel::allow_avx512(false);
                let peak_avx2 = best_rate(PEAK_SECONDS, || peak_f32_kernel(k));
                f32_kernel::allow_avx512(true);
                f32_kernel::allow_simd(false);
                let peak_baseline = best_rate(PEAK_SECONDS, || peak_f32_kernel(k));
                f32_kernel::allow_simd(true);
                [peak64, peak_widest, peak_avx2, peak_baseline]
            };
            let before = peaks();
            let achieved = |b: &mut Box<dyn Backend>| {
                best_rate(BACKEND_SECONDS, || {
                    let t = Instant::now();
                    let sum: f64 = b.query(&queries).unwrap().iter().map(|s| s.0).sum();
                    std::hint::black_box(sum);
                    (terms, t.elapsed().as_secs_f64())
                })
            };
            let a64 = achieved(&mut f64_backend);
            let a32 = achieved(&mut f32_backend);
            // What a CPU with AVX2 and no AVX-512 gets.
            f32_kernel::allow_avx512(false);
            let a32_avx2 = achieved(&mut f32_backend);
            f32_kernel::allow_avx512(true);
            // What a CPU without AVX2 gets (the dispatch forced off).
            f32_kernel::allow_simd(false);
            let a32_baseline = achieved(&mut f32_backend);
            f32_kernel::allow_simd(true);
            // The peaks again after the backend, the higher of each kept: a peak read while
            // another process held a core would make every share of it too high.
            let after = peaks();
            let peaks = [0, 1, 2, 3].map(|i| before[i].max(after[i]));
            (peaks, a64, a32, a32_avx2, a32_baseline)
        });
        let ([peak64, peak_widest, peak_avx2, peak_baseline], a64, a32, a32_avx2, a32_baseline) =
            row;
        achieved_by_threads.push((a64, a32));
        widest_peaks.push(peak_widest);
        let rate = |available: bool, v: f64| {
            if available {
                format!("{:.3}", v / 1e9)
            } else {
                "-".into()
            }
        };
        println!(
            "| {k} | {:.3} | {} | {} | {:.3} | {:.1} | {:.1} | {} | {:.1} | {:.1}% | {:.1}% | {:.1}x |",
            peak64 / 1e9,
            rate(avx512, peak_widest),
            rate(simd, peak_avx2),
            peak_baseline / 1e9,
            a64 / 1e6,
            a32 / 1e6,
            if simd {
                format!("{:.1}", a32_avx2 / 1e6)
            } else {
                "-".into()
            },
            a32_baseline / 1e6,
            100.0 * a64 / peak64,
            // Against the widest build's peak: what this CPU can do.
            100.0 * a32 / peak_widest,
            a32 / a64
        );
    }
    let (first, last) = (achieved_by_threads[0], *achieved_by_threads.last().unwrap());
    println!(
        "\nN = {n}, M = {m} (Hilbert-ordered), radius = {radius:.5} (unit cube), K = 4, \
         {:.1} terms a query; scaling from 1 to {} threads: {:.2}x (f64), {:.2}x (f32)",
        terms as f64 / m as f64,
        threads.last().unwrap(),
        last.0 / first.0,
        last.1 / first.1
    );
    // Peak loops over data in cache scale with the cores: a k-thread peak well off k times the
    // 1-thread one is what another process holding a core gives (too low a peak makes every
    // share of it too high), or threads that share a core's units.
    let one = widest_peaks[0];
    for (&k, &peak) in threads.iter().zip(&widest_peaks).skip(1) {
        let grew = peak / (k as f64 * one);
        if !(0.9..=1.1).contains(&grew) {
            println!(
                "WARNING: the {k}-thread peak of the widest build is {grew:.2} of {k} times the \
                 1-thread one. Another process held a core while the {} row was measured, so \
                 its shares (and the scaling) are not this machine's: run it again. (Or the \
                 threads share cores' units: SMT.)",
                if grew < 1.0 {
                    format!("{k}-thread")
                } else {
                    "1-thread".into()
                }
            );
        }
    }
}

/// The best rate of runs of `f` (which returns work and seconds) over `seconds`, at least
/// three runs. The machine is shared: three runs, of under a millisecond each for a peak loop,
/// once let a peak be read while another process held a core (the 2-thread AVX-512 peak read
/// half the machine's, and the share of it printed twice the true one:
/// docs/notes/2026-12-06-cpu-point-queries.md); the best of many is the machine's.
fn best_rate(seconds: f64, mut f: impl FnMut() -> (u64, f64)) -> f64 {
    let started = Instant::now();
    let mut best: f64 = 0.0;
    let mut runs = 0;
    while runs < 3 || started.elapsed().as_secs_f64() < seconds {
        let (work, s) = f();
        best = best.max(work as f64 / s);
        runs += 1;
    }
    best
}

/// Seconds of runs each peak loop is given (runs of about a millisecond).
const PEAK_SECONDS: f64 = 0.25;

/// Seconds of runs each of the backend's rates is given (runs of 0.05-0.5 s).
const BACKEND_SECONDS: f64 = 1.0;

/// Every (query, particle) pair within `r`, counted on a grid of cells of side r.
fn count_terms(points: &[DVec3], queries: &[DVec3], r: f64) -> u64 {
    let cells = (1.0 / r).ceil() as i64;
    let cell = |p: DVec3| -> [i64; 3] {
        [p.x, p.y, p.z].map(|c| ((c / r).floor() as i64).clamp(0, cells - 1))
    };
    let index = |c: [i64; 3]| ((c[2] * cells + c[1]) * cells + c[0]) as usize;
    let mut start = vec![0usize; (cells * cells * cells) as usize + 1];
    for &p in points {
        start[index(cell(p)) + 1] += 1;
    }
    for i in 1..start.len() {
        start[i] += start[i - 1];
    }
    let mut fill = start.clone();
    let mut sorted = vec![DVec3::ZERO; points.len()];
    for &p in points {
        let i = index(cell(p));
        sorted[fill[i]] = p;
        fill[i] += 1;
    }
    let r2 = r * r;
    queries
        .par_iter()
        .map(|&q| {
            let c = cell(q);
            let mut n = 0u64;
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let d = [c[0] + dx, c[1] + dy, c[2] + dz];
                        if d.iter().any(|&v| v < 0 || v >= cells) {
                            continue;
                        }
                        let i = index(d);
                        n += sorted[start[i]..start[i + 1]]
                            .iter()
                            .filter(|p| (**p - q).length_squared() <= r2)
                            .count() as u64;
                    }
                }
            }
            n
        })
        .sum()
}

/// A block of particles all within r of every query point (so every term counts), in
/// structure-of-arrays form.
struct Block<T> {
    x: Vec<T>,
    y: Vec<T>,
    z: Vec<T>,
    w: Vec<T>,
}

fn block<T: From<f32>>() -> (Block<T>, Vec<[T; 3]>) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
    let mut coordinate = || T::from(rng.random::<f32>() * 0.5);
    let b = Block {
        x: (0..BLOCK).map(|_| coordinate()).collect(),
        y: (0..BLOCK).map(|_| coordinate()).collect(),
        z: (0..BLOCK).map(|_| coordinate()).collect(),
        w: (0..BLOCK).map(|_| T::from(1.0)).collect(),
    };
    let q = (0..PEAK_QUERIES)
        .map(|_| [coordinate(), coordinate(), coordinate()])
        .collect();
    (b, q)
}

/// Terms a second in a scalar f64 loop with the standard library's exp, on `threads`
/// threads: how the reference evaluates a term, with the traversal taken away.
fn peak_f64(threads: usize) -> (u64, f64) {
    let (b, queries) = block::<f64>();
    // Radius 1 covers the block (coordinates in [0, 0.5]).
    let inv_r2 = 1.0;
    let t = Instant::now();
    let sum: f64 = (0..threads)
        .into_par_iter()
        .map(|_| {
            let mut total = 0.0;
            for q in &queries {
                let mut phi = 0.0;
                for i in 0..BLOCK {
                    let d2 =
                        (b.x[i] - q[0]).powi(2) + (b.y[i] - q[1]).powi(2) + (b.z[i] - q[2]).powi(2);
                    if d2 * inv_r2 <= 1.0 {
                        phi += b.w[i] * (-4.5 * d2 * inv_r2).exp();
                    }
                }
                total += phi;
            }
            total
        })
        .sum();
    std::hint::black_box(sum);
    (
        (threads * BLOCK * PEAK_QUERIES) as u64,
        t.elapsed().as_secs_f64(),
    )
}

/// Terms a second of the f32 kernel's arithmetic over the block in cache, every particle's term
/// computed with no test of which reach (`f32_kernel::dense_sums`), in whichever build
/// (AVX-512, AVX2 or baseline) the dispatch allows now: the ceiling of the kernel on this CPU.
fn peak_f32_kernel(threads: usize) -> (u64, f64) {
    let (b, queries) = block::<f32>();
    let mut packed = Packed {
        x: b.x,
        y: b.y,
        z: b.z,
        // Radius 1 covers the block.
        r2: vec![1.0; BLOCK],
        k: vec![4.5; BLOCK],
        w: b.w,
        theta: [Vec::new(), Vec::new(), Vec::new()],
        channels: 0,
        // one_radius and same_w: set by `pad`.
        ..Packed::default()
    };
    packed.pad();
    let t = Instant::now();
    let sum: f64 = (0..threads)
        .into_par_iter()
        .map(|_| {
            queries
                .iter()
                .map(|q| f32_kernel::dense_sums(&packed, 0, BLOCK, *q))
                .sum::<f64>()
        })
        .sum();
    std::hint::black_box(sum);
    (
        (threads * BLOCK * PEAK_QUERIES) as u64,
        t.elapsed().as_secs_f64(),
    )
}
