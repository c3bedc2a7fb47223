//! The field on a regular grid (a volume export, `aarbf slice`, a voxel baseline) from N
//! uniform particles, two ways side by side in one process: a tree query per grid point
//! (`eval_many`, what a grid cost before) and scattering each particle onto the grid points
//! it reaches (`eval_grid`). Radius such that ~50 particles reach a point, as SPH data has;
//! Phi and the normalised attribute (post-classification), f64.
//!
//! cargo bench --bench field_grid -- [N] [G]     (defaults: 1000000 100, a G^3 grid)
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::time::Instant;

use aarbf::accel::ClusterSize;
use aarbf::field::{FieldSettings, ReferenceField, RegularGrid};
use aarbf::scene::synth::Generator;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(1_000_000);
    let g = args.get(1).copied().unwrap_or(100);
    let t = Instant::now();
    let step = Generator::Uniform.generate(n, 1, 1).remove(0);
    eprintln!(
        "generated {n} particles in {:.1} s",
        t.elapsed().as_secs_f64()
    );
    let bounds = step.bounds();
    // N (4/3) pi r^3 = 50 within r of a point, in the data's box.
    let volume = bounds.extent().x * bounds.extent().y * bounds.extent().z;
    let radius = (50.0 * 3.0 * volume / (4.0 * std::f64::consts::PI * n as f64)).cbrt();
    let attribute = step.attributes[0].name.clone();
    let settings = FieldSettings::new(Some(&attribute), radius);
    let field =
        ReferenceField::of_step(&step, &settings, ClusterSize::new(4).unwrap(), bounds, None)
            .unwrap();
    let grid = RegularGrid::cell_centred(bounds.min, bounds.max, [g, g, g]);
    let points = grid.points();

    let (mut per_point, mut scattered) = (Vec::new(), Vec::new());
    let mut agree = 0.0f64;
    for _ in 0..3 {
        let t = Instant::now();
        let a = field.eval_many(&points);
        per_point.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let b = field.eval_grid(&grid);
        scattered.push(t.elapsed().as_secs_f64());
        agree = a
            .iter()
            .zip(&b)
            .map(|(a, b)| (a.phi - b.phi).abs() / a.phi.abs().max(1e-300))
            .fold(agree, f64::max);
    }
    let (q, s) = (median(per_point), median(scattered));
    let m = grid.len() as f64;
    println!(
        "| N | grid | neighbours | query per point (s) | scattered (s) | speed-up | points/s scattered | largest relative Phi difference |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    println!(
        "| {n} | {g}^3 | ~50 | {q:.3} | {s:.3} | {:.1}x | {:.1} M | {agree:.1e} |",
        q / s,
        m / s / 1e6
    );
    println!(
        "\nradius {radius:.5}, K = 4, f64, {} threads, medians of 3",
        rayon::current_num_threads()
    );
}
