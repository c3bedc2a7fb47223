//! Smoothing lengths from neighbours (`--smoothing knn:K`, `scene::smoothing::knn_lengths`):
//! N points uniform in the unit cube (f64, seeded), h = the distance to the K-th nearest
//! other point, best of R runs; beside SciPy's `cKDTree(x).query(x, k=K + 1, workers=-1)` on
//! the same points (`benches/peers/scipy_knn.py`, which writes and reads them the same way).
//!
//! cargo bench --profile checked --bench knn -- [N] [K] [R]     (defaults: 1000000 32 3)
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::time::Instant;

use aarbf::scene::smoothing::knn_lengths;
use glam::DVec3;
use rand::{Rng, SeedableRng};

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(1_000_000);
    let k = args.get(1).copied().unwrap_or(32);
    let runs = args.get(2).copied().unwrap_or(3).max(1);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
    let points: Vec<DVec3> = (0..n)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let mut best = f64::INFINITY;
    let mut mean_h = 0.0;
    for _ in 0..runs {
        let t = Instant::now();
        let h = knn_lengths(&points, k);
        best = best.min(t.elapsed().as_secs_f64());
        mean_h = h.iter().sum::<f64>() / n as f64;
    }
    println!(
        "aarbf knn_lengths: {n} points, K = {k}, {} rayon threads: best of {runs} {:.0} ms (mean h {mean_h:.5})",
        rayon::current_num_threads(),
        best * 1e3
    );
}
