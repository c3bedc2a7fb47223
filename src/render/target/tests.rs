use super::*;
use crate::noise::BlueNoiseMask;
use crate::values::NoiseKind;

#[test]
fn the_noise_falls_at_its_measured_rate() {
    let blue = Convergence::of((4, 0.1), (16, 0.025));
    assert!((blue.rate - 1.0).abs() < 1e-12);
    assert!((blue.frames_for(0.0125) - 32.0).abs() < 1e-9);
    let white = Convergence::of((16, 0.05), (4, 0.1));
    assert!((white.rate - 0.5).abs() < 1e-12);
    assert!((white.noise_at(64.0) - 0.025).abs() < 1e-12);
    // Rates outside what sampling gives are clamped.
    assert_eq!(Convergence::of((4, 0.1), (16, 0.001)).rate, 1.0);
    assert_eq!(Convergence::of((4, 0.1), (16, 0.2)).rate, 0.5);
}

/// A pixel value with Gaussian noise of standard deviation `sigma` (Box-Muller).
fn noisy(rng: &mut rand_pcg::Pcg64, value: f64, sigma: f64) -> f32 {
    use rand::Rng;
    let (u, v): (f64, f64) = (rng.random_range(1e-12..1.0), rng.random());
    (value + sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
}

fn noisy_image(rng: &mut rand_pcg::Pcg64, w: u32, h: u32, sigma: f64) -> Image {
    Image {
        width: w,
        height: h,
        pixels: (0..w * h)
            .map(|k| {
                // A smooth picture under the noise.
                let v = 0.5 + 0.3 * (f64::from(k % w) * 0.1).sin();
                [0, 1, 2, 3].map(|c| if c == 3 { 1.0 } else { noisy(rng, v, sigma) })
            })
            .collect(),
    }
}

#[test]
fn whole_cycles_measure_the_noise_of_their_mean() {
    use rand::SeedableRng;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    let (w, h, d, sigma) = (61, 47, 4, 0.02);
    let mut sequence = Sequence::with_cycles(1, d);
    assert_eq!(sequence.chunk_room(), d);
    for k in 1..=6u32 {
        // Each cycle's mean carries independent noise of `sigma`, in chunks of 3 and 1
        // frames whose own noise cancels over the cycle (stratified frames).
        let cycle = noisy_image(&mut rng, w, h, sigma);
        let spread = noisy_image(&mut rng, w, h, 0.3);
        let first = cycle.offset_by(&spread, &cycle, 1.0 / 3.0);
        let last = cycle.offset_by(&spread, &cycle, -1.0);
        sequence.add(&first, 3);
        assert_eq!(sequence.chunk_room(), 1);
        assert_eq!(sequence.whole_cycles_noise(), None, "within a cycle");
        sequence.add(&last, 1);
        let noise = sequence.whole_cycles_noise();
        if k < 2 {
            assert_eq!(noise, None, "one cycle has no spread");
            continue;
        }
        let want = sigma / f64::from(k).sqrt();
        let noise = noise.expect("whole cycles");
        assert!(
            (noise / want - 1.0).abs() < 0.05,
            "{k} cycles: {noise:.4e}, want {want:.4e}"
        );
    }
    // A sequence that keeps no cycles measures nothing by them.
    let mut plain = Sequence::new(1);
    plain.add(&noisy_image(&mut rng, w, h, sigma), 8);
    assert_eq!(plain.whole_cycles_noise(), None);
}

#[test]
fn the_lattice_measures_the_noise_of_the_whole_image() {
    use rand::SeedableRng;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    for (w, h) in [(96, 64), (97, 33)] {
        let sigma = 0.01;
        let image = noisy_image(&mut rng, w, h, sigma);
        // The lattice's own sequence: the same picture at the even pixels, its own noise.
        let independent = noisy_image(&mut rng, w, h, sigma).half_lattice();
        let estimate = noise_on_lattice(&image, &independent);
        assert!(
            (estimate / sigma - 1.0).abs() < 0.1,
            "{w}x{h}: {estimate:.4e}"
        );
    }
}

#[test]
fn blue_noise_sequences_stop_at_whole_mask_cycles() {
    let d = Some(64);
    // Early in the first cycle: where the prediction says.
    assert_eq!(stop_at(12, 4, d), 12);
    assert_eq!(stop_at(47, 8, d), 47);
    // Most of the first cycle or beyond it: its end first, whatever the power law says.
    assert_eq!(stop_at(48, 8, d), 64);
    assert_eq!(stop_at(70, 8, d), 64);
    assert_eq!(stop_at(500, 2, d), 64);
    // Past it, whole cycles only.
    assert_eq!(stop_at(65, 64, d), 128);
    assert_eq!(stop_at(128, 64, d), 128);
    assert_eq!(stop_at(129, 128, d), 192);
    // White noise has no cycle.
    assert_eq!(stop_at(70, 8, None), 70);
    assert_eq!(stop_at(65, 64, None), 65);
    // The cycle of the settings: the built-in mask's depth, for blue noise only.
    let blue = RenderSettings::default();
    assert_eq!(mask_cycle(&blue), Some(BlueNoiseMask::builtin().depth));
    let white = RenderSettings {
        noise: NoiseKind::White,
        ..blue
    };
    assert_eq!(mask_cycle(&white), None);
}

#[test]
fn targets_are_checked() {
    let ok = Target {
        error: Some(0.01),
        time_budget: None,
        metric: ErrorMetric::Rmse,
        max_spp: 64,
    };
    assert!(ok.check().is_ok());
    for bad in [
        Target { error: None, ..ok },
        Target {
            error: Some(-1.0),
            ..ok
        },
        Target {
            error: Some(f64::NAN),
            ..ok
        },
        Target { max_spp: 4, ..ok },
        Target {
            error: None,
            time_budget: Some(Duration::ZERO),
            ..ok
        },
    ] {
        assert!(bad.check().is_err(), "{bad:?}");
    }
}
