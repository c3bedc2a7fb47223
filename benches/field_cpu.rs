//! `aarbf field` on the CPU backend at scale: N uniform (Poisson-disk) particles, M uniform
//! queries, radius chosen so ~30 particles overlap a point, for several cluster sizes.
//! Runs the real binary, as a user would. Results go to docs/benchmarks.md.
//!
//! cargo bench --bench field_cpu -- [N] [M]     (defaults: 1000000 1000000)
#![expect(
    clippy::print_stdout,
    reason = "a benchmark prints its table to stdout"
)]

use std::process::Command;
use std::time::Instant;

use aarbf::io::{self, Format, npy};
use aarbf::scene::synth::Generator;
use rand::{Rng, SeedableRng};

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(1_000_000);
    let m = args.get(1).copied().unwrap_or(1_000_000);
    let dir = tempfile::tempdir().unwrap();

    let t = Instant::now();
    let data = Generator::Uniform.generate(n, 1, 1);
    let header =
        io::write_series(dir.path(), "uniform", &data, Format::Particles, "distance").unwrap();
    eprintln!(
        "generated {n} Poisson-disk particles in {:.1} s",
        t.elapsed().as_secs_f64()
    );
    let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
    let queries: Vec<f32> = (0..m * 3).map(|_| rng.random::<f32>()).collect();
    let q = dir.path().join("queries.npy");
    npy::write_matrix(&q, m, 3, &queries).unwrap();

    // N (4/3) pi r^3 = 30 particles within r of a point (unit cube).
    let radius = (30.0 * 3.0 / (4.0 * std::f64::consts::PI * n as f64)).cbrt();
    println!("| K | build (s) | evaluation (s) | queries/s | mean Phi | whole command (s) |");
    println!("|---|---|---|---|---|---|");
    for k in ["1", "4", "16"] {
        let out = dir.path().join(format!("field_{k}.npy"));
        let t = Instant::now();
        let run = Command::new(env!("CARGO_BIN_EXE_aarbf"))
            .args(["field", "--data"])
            .arg(&header)
            .args([
                "--attribute",
                "attribute",
                "--radius",
                &radius.to_string(),
                "--cluster",
                k,
                "--queries",
            ])
            .arg(&q)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let whole = t.elapsed().as_secs_f64();
        let log = String::from_utf8_lossy(&run.stderr);
        assert!(run.status.success(), "{log}");
        let number_after = |key: &str| -> f64 {
            let i = log
                .find(key)
                .unwrap_or_else(|| panic!("no '{key}' in {log}"))
                + key.len();
            log[i..]
                .trim_start()
                .split(|c: char| !(c.is_ascii_digit() || c == '.'))
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let (build, eval) = (number_after("build"), number_after("evaluation"));
        let field = npy::read_matrix(io::At::new(&out, None)).unwrap();
        let mean_phi = (0..field.rows).map(|i| field.row(i)[0]).sum::<f64>() / field.rows as f64;
        println!(
            "| {k} | {build:.3} | {eval:.3} | {:.2} M | {mean_phi:.3} | {whole:.1} |",
            m as f64 / eval / 1e6
        );
    }
    println!(
        "\nN = {n}, M = {m}, radius = {radius:.5} (unit cube), {} threads",
        rayon::current_num_threads()
    );
}
