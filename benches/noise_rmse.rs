//! Blue (STBN) vs white noise on the demo scene: image error against a converged reference
//! at equal samples per pixel, the paper's Fig. 10b question, on the CPU backend.
//!
//! cargo bench --bench noise_rmse -- [SIZE] [REFERENCE_SPP] [SEEDS]   (defaults: 64 16384 2)
//!
//! For each integrator: RMSE of 1, 4, 16, 64, 256 and 1024 accumulated frames against a
//! REFERENCE_SPP render, raw and seen through a 1-pixel Gaussian blur (the eye's low-pass),
//! averaged over SEEDS seeds. The reference is blue noise of another seed: past its first 64
//! frames every cycle reads the mask at a new shift (`BlueNoiseMask::cycle_shift`), so it
//! converges like the estimates it judges, where a white-noise reference of the same cost
//! would be noisier than the 1024-spp blue-noise images.

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Integrator, NoiseKind};

fn main() {
    let args: Vec<u32> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let size = args.first().copied().unwrap_or(64);
    let reference_spp = args.get(1).copied().unwrap_or(16384);
    let seeds = args.get(2).copied().unwrap_or(2);
    let series = TimeSeries::from_steps(Generator::DambreakDemo.generate(20_000, 15, 1));
    let field = FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal());
    let mut session = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    session
        .show(&series, 14, &field, ClusterSize::new(4).unwrap())
        .unwrap();
    let radius = field.radius;
    println!(
        "demo scene (dam break, 20K particles, step 14), {size}x{size}, reference {reference_spp} spp blue noise (seed 1000), {seeds} seeds\n"
    );
    println!(
        "| integrator | spp | RMSE blue | RMSE white | blue/white | blurred RMSE blue | blurred RMSE white | blue/white |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (integrator, step_size, label) in [
        (Integrator::Marching, None, "marching (single scattering)"),
        (
            Integrator::Delta,
            None,
            "delta tracking (single scattering)",
        ),
        (Integrator::Ea, Some(2.0 * radius), "EA, step = 2 R"),
    ] {
        let settings = |noise, seed| RenderSettings {
            width: size,
            height: size,
            integrator,
            noise,
            seed,
            step_size,
            ..RenderSettings::default()
        };
        let reference = session
            .render(&settings(NoiseKind::Stbn, 1000), reference_spp)
            .unwrap();
        let blurred_reference = reference.blurred(1.0);
        let spps = [1, 4, 16, 64, 256, 1024];
        // rows[s] = [blue, white, blurred blue, blurred white] at spps[s], summed over seeds.
        let mut rows = [[0.0f64; 4]; 6];
        for (k, noise) in [NoiseKind::Stbn, NoiseKind::White].into_iter().enumerate() {
            for seed in 0..seeds {
                // One accumulation per seed, read at each spp.
                let mut done = 0;
                for (s, &spp) in spps.iter().enumerate() {
                    let image = session.render(&settings(noise, seed), spp - done).unwrap();
                    done = spp;
                    rows[s][k] += image.rmse(&reference) / f64::from(seeds);
                    rows[s][2 + k] +=
                        image.blurred(1.0).rmse(&blurred_reference) / f64::from(seeds);
                }
            }
        }
        for (&spp, row) in spps.iter().zip(rows) {
            println!(
                "| {label} | {spp} | {:.5} | {:.5} | {:.2} | {:.5} | {:.5} | {:.2} |",
                row[0],
                row[1],
                row[0] / row[1],
                row[2],
                row[3],
                row[2] / row[3]
            );
        }
    }
}
