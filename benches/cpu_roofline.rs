//! How close the CPU backend's field queries run to what this machine can do: the peak rate
//! of RBF terms (w · exp(-4.5 d²/r²) for particles within r) in a tight loop over particles
//! in cache, against the terms per second the backend achieves on N particles × M queries
//! (~30 terms a query), at every thread count up to the machine's. Results go to
//! docs/benchmarks.md.
//!
//! cargo xtask bench cpu_roofline -- [N] [M]     (defaults: 1000000 1000000)
//!
//! Terms: a term is one particle within r of a query (what the field sums). The achieved
//! count is exact: every (query, particle) pair within r, counted on a uniform grid of cell
//! size r independently of the backend's tree.

use std::time::Instant;

use aarbf::accel::ClusterSize;
use aarbf::field::{FieldSettings, ReferenceField};
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
    let reference =
        ReferenceField::of_step(&step, &field, ClusterSize::new(4).unwrap(), bounds, None).unwrap();
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

    // The vectorised exp's error over the kernel's range (d <= r: x in [-4.5, 0]).
    let exp_error = (0..=100_000)
        .map(|i| {
            let x = (-4.5 * f64::from(i) / 100_000.0) as f32;
            let e = wide::f32x8::splat(x).exp().to_array()[0];
            (f64::from(e) / f64::from(x).exp() - 1.0).abs()
        })
        .fold(0.0, f64::max);
    eprintln!("f32x8 exp: largest relative error over [-4.5, 0]: {exp_error:.2e}");
    println!(
        "| threads | peak, f64 scalar exp (G terms/s) | peak, f32x8 with vector exp (G terms/s) | backend field queries (M terms/s) | backend / f64 peak | backend / f32x8 peak |"
    );
    println!("|---|---|---|---|---|---|");
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
    for &k in &threads {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap();
        let (peak64, peak32, achieved) = pool.install(|| {
            let peak64 = best_rate(3, || peak_f64(k));
            let peak32 = best_rate(3, || peak_f32_simd(k));
            let achieved = best_rate(2, || {
                let t = Instant::now();
                let sum: f64 = queries.par_iter().map(|&x| reference.eval_sums(x).0).sum();
                std::hint::black_box(sum);
                (terms, t.elapsed().as_secs_f64())
            });
            (peak64, peak32, achieved)
        });
        achieved_by_threads.push(achieved);
        println!(
            "| {k} | {:.3} | {:.3} | {:.1} | {:.1}% | {:.1}% |",
            peak64 / 1e9,
            peak32 / 1e9,
            achieved / 1e6,
            100.0 * achieved / peak64,
            100.0 * achieved / peak32
        );
    }
    println!(
        "\nN = {n}, M = {m} (Hilbert-ordered), radius = {radius:.5} (unit cube), K = 4, \
         {:.1} terms a query; scaling from 1 to {} threads: {:.2}x",
        terms as f64 / m as f64,
        threads.last().unwrap(),
        achieved_by_threads.last().unwrap() / achieved_by_threads[0]
    );
}

/// The best rate of `runs` runs of `f`, which returns (work, seconds).
fn best_rate(runs: usize, mut f: impl FnMut() -> (u64, f64)) -> f64 {
    (0..runs)
        .map(|_| {
            let (work, s) = f();
            work as f64 / s
        })
        .fold(0.0, f64::max)
}

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

/// Terms a second in f32, eight at a time (`wide::f32x8`, with its vectorised exp; SSE2 pairs
/// on a build for baseline x86-64, AVX2 where the build targets it): the ceiling a
/// vectorised evaluation reaches on this CPU with the instructions this build uses.
fn peak_f32_simd(threads: usize) -> (u64, f64) {
    let (b, queries) = block::<f32>();
    let t = Instant::now();
    let sum: f32 = (0..threads)
        .into_par_iter()
        .map(|_| queries.iter().map(|q| block_sum(&b, *q)).sum::<f32>())
        .sum();
    std::hint::black_box(sum);
    (
        (threads * BLOCK * PEAK_QUERIES) as u64,
        t.elapsed().as_secs_f64(),
    )
}

/// The in-range terms of one query over the block, eight lanes at a time, branch-free (an
/// out-of-range term is blended to 0).
fn block_sum(b: &Block<f32>, q: [f32; 3]) -> f32 {
    use wide::{CmpLe, f32x8};
    let (qx, qy, qz) = (f32x8::splat(q[0]), f32x8::splat(q[1]), f32x8::splat(q[2]));
    let mut acc = f32x8::ZERO;
    for (((x, y), z), w) in
        b.x.chunks_exact(8)
            .zip(b.y.chunks_exact(8))
            .zip(b.z.chunks_exact(8))
            .zip(b.w.chunks_exact(8))
    {
        let lane = |s: &[f32]| f32x8::from(<[f32; 8]>::try_from(s).unwrap());
        let (dx, dy, dz) = (lane(x) - qx, lane(y) - qy, lane(z) - qz);
        let d2 = dx * dx + dy * dy + dz * dz;
        let term = lane(w) * (f32x8::splat(-4.5) * d2).exp();
        acc += d2.cmp_le(f32x8::ONE).blend(term, f32x8::ZERO);
    }
    acc.reduce_add()
}
