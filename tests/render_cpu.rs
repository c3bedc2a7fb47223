//! The CPU backend rendering the demo data as a user would, through a RenderSession.

use aarbf::accel::ClusterSize;
use aarbf::backend::{self, BackendKind};
use aarbf::field::{Classification, FieldSettings};
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::synth::Generator;
use aarbf::values::{Integrator, NoiseKind};

fn demo() -> TimeSeries {
    TimeSeries::from_steps(Generator::DambreakDemo.generate(3000, 8, 1))
}

fn field(series: &TimeSeries) -> FieldSettings {
    FieldSettings::new(Some("velocity"), 0.015 * series.bounds().diagonal())
}

fn settings(size: u32, integrator: Integrator, noise: NoiseKind) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        integrator,
        noise,
        ..RenderSettings::default()
    }
}

#[test]
fn a_fixed_seed_reproduces_the_image_bit_for_bit() {
    let series = demo();
    for integrator in [Integrator::Ea, Integrator::Delta, Integrator::Marching] {
        let render = || {
            let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
            s.show(&series, 7, &field(&series), ClusterSize::new(4).unwrap())
                .unwrap();
            s.render(&settings(48, integrator, NoiseKind::Stbn), 3)
                .unwrap()
        };
        let (a, b) = (render(), render());
        assert_eq!(a, b, "{integrator:?}");
        assert!(
            a.pixels.iter().any(|p| p[3] > 0.5),
            "{integrator:?}: the fluid is visible"
        );
        assert!(a.pixels.iter().all(|p| p.iter().all(|v| v.is_finite())));
    }
}

#[test]
fn changes_cost_only_what_they_need_and_restart_accumulation() {
    let series = demo();
    let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    let k = ClusterSize::new(2).unwrap();
    let mut f = field(&series);
    s.show(&series, 5, &f, k).unwrap();
    let base = s
        .render(&settings(32, Integrator::Ea, NoiseKind::White), 2)
        .unwrap();
    assert_eq!(s.frames(), 2);
    // A radius change refits and restarts accumulation.
    f.radius *= 1.5;
    s.show(&series, 5, &f, k).unwrap();
    let wider = s
        .render(&settings(32, Integrator::Ea, NoiseKind::White), 1)
        .unwrap();
    assert_eq!(s.frames(), 1);
    assert!(s.backend().timings().refit > std::time::Duration::ZERO);
    assert_ne!(base, wider);
    // Pre-classification needs a new upload; the image changes.
    f.classification = Classification::Pre;
    s.show(&series, 5, &f, k).unwrap();
    let pre = s
        .render(&settings(32, Integrator::Ea, NoiseKind::White), 1)
        .unwrap();
    assert_ne!(pre, wider);
    // Rendering more frames with the same settings accumulates.
    s.render(&settings(32, Integrator::Ea, NoiseKind::White), 2)
        .unwrap();
    assert_eq!(s.frames(), 3);
    // Another step: upload and build.
    s.show(&series, 6, &f, k).unwrap();
    let other = s
        .render(&settings(32, Integrator::Ea, NoiseKind::White), 1)
        .unwrap();
    assert_eq!(s.frames(), 1);
    assert_ne!(other, pre);
}

/// A view close to the fluid, so most pixels see it.
fn close_view(series: &TimeSeries) -> aarbf::scene::Camera {
    let b = series.bounds();
    aarbf::scene::Camera {
        eye: glam::DVec3::new(0.9, 0.45, 1.1),
        at: glam::DVec3::new(0.55, 0.12, 0.5 * b.max.z),
        up: glam::DVec3::Y,
        fovy: 35.0,
    }
}

#[test]
fn blue_noise_beats_white_noise_at_equal_samples() {
    // Per-pixel error at 1 spp has the same variance for any uniform random number, so the
    // raw 1-spp RMSE of blue and white noise agree; what blue noise changes is where the error
    // lies: at high spatial frequencies (removed by the eye's low-pass, here a Gaussian of
    // 1 pixel) and stratified over frames (so accumulated frames converge faster).
    let series = demo();
    let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    s.show(&series, 7, &field(&series), ClusterSize::new(4).unwrap())
        .unwrap();
    let camera = Some(close_view(&series));
    // EA with a coarse step, where the jitter matters (wood-grain artefacts otherwise).
    let coarse = Some(2.0 * field(&series).radius);
    for (integrator, step_size, reference_spp) in [
        (Integrator::Marching, None, 512),
        (Integrator::Ea, coarse, 256),
    ] {
        let at = |noise, seed| RenderSettings {
            seed,
            camera,
            step_size,
            ..settings(64, integrator, noise)
        };
        let reference = s.render(&at(NoiseKind::White, 99), reference_spp).unwrap();
        let blurred_reference = reference.blurred(1.0);
        let mut errors = |noise| {
            let mut raw = 0.0;
            let mut blurred = 0.0;
            for seed in 0..4 {
                let image = s.render(&at(noise, seed), 1).unwrap();
                raw += image.rmse(&reference) / 4.0;
                blurred += image.blurred(1.0).rmse(&blurred_reference) / 4.0;
            }
            let accumulated = s.render(&at(noise, 5), 8).unwrap().rmse(&reference);
            (raw, blurred, accumulated)
        };
        let (blue, white) = (errors(NoiseKind::Stbn), errors(NoiseKind::White));
        eprintln!(
            "{integrator:?}: RMSE (1 spp, 1 spp seen through a 1-px blur, 8 spp): blue {blue:.5?} white {white:.5?}"
        );
        assert!(
            blue.1 < white.1,
            "{integrator:?}: blurred 1-spp error, blue {blue:?} white {white:?}"
        );
        assert!(
            blue.2 < 0.7 * white.2,
            "{integrator:?}: 8-spp error, blue {blue:?} white {white:?}"
        );
    }
}

/// A viewer abandons a frame when the view changes mid-frame: the frame stops, says so, and
/// leaves the accumulation exactly as it was; `frames_of` tells which settings it holds.
#[test]
fn an_abandoned_frame_leaves_the_accumulation_as_it_was() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    let series = demo();
    let mut s = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    s.show(&series, 4, &field(&series), ClusterSize::new(4).unwrap())
        .unwrap();
    let look = settings(40, Integrator::Ea, NoiseKind::Stbn);
    s.accumulate(&look, 2).unwrap();
    let before = s.image().unwrap();
    assert_eq!(s.frames_of(&look), 2);
    assert_eq!(
        s.frames_of(&settings(41, Integrator::Ea, NoiseKind::Stbn)),
        0
    );
    let flag = Arc::new(AtomicBool::new(true));
    s.backend_mut().set_abandon_flag(Some(flag.clone()));
    let e = s.accumulate(&look, 1).unwrap_err();
    assert!(e.to_string().contains("abandoned"), "{e}");
    assert_eq!(s.frames_of(&look), 2);
    assert_eq!(s.image().unwrap(), before);
    // Lowered, the next frame renders and accumulates as if nothing had happened.
    flag.store(false, Ordering::Relaxed);
    s.accumulate(&look, 1).unwrap();
    let mut fresh = RenderSession::new(backend::create(BackendKind::Cpu).unwrap(), &series);
    fresh
        .show(&series, 4, &field(&series), ClusterSize::new(4).unwrap())
        .unwrap();
    assert_eq!(s.image().unwrap(), fresh.render(&look, 3).unwrap());
}
