//! Blue-noise accumulation keeps converging past the mask's 64 frames, on every backend: each
//! 64-frame cycle reads the mask at a new toroidal shift (`BlueNoiseMask::cycle_shift`), so the
//! image at 256 and at 1024 samples per pixel is closer to the converged one than at 64 (and
//! differs from it at all: without the shift, frames f and f + 64 repeat each other and the
//! mean stops changing).
//!
//! The converged image is exact here, not estimated: one particle, stochastic ray marching
//! with ambient light only (the light's intensity 0), so a pixel's expected colour for a march
//! jitter u is `c (1 - exp(-τ(u))) + bg exp(-τ(u))` with τ(u) the marched optical depth; the
//! test integrates it over u by a fine quadrature, with the backends' own frame constants.

use aarbf::accel::ClusterSize;
use aarbf::backend::cpu::integrators::ray_box;
use aarbf::backend::{self, BackendKind};
use aarbf::field::FieldSettings;
use aarbf::render::{RenderSession, RenderSettings};
use aarbf::scene::TimeSeries;
use aarbf::scene::maps::{ColorMap, OpticalDensityMap, PiecewiseLinear};
use aarbf::values::{Attribute, FrameParams, Image, Integrator, Light, NoiseKind, Step};
use glam::DVec3;

use crate::common;

const RADIUS: f64 = 0.3;
const CENTRE: DVec3 = DVec3::new(0.5, 0.45, 0.55);

fn series() -> TimeSeries {
    TimeSeries::from_steps(vec![Step {
        name: "one".into(),
        positions: vec![CENTRE, CENTRE + DVec3::splat(1e-3)],
        attributes: vec![Attribute {
            name: "s".into(),
            values: vec![1.0, 1.0],
        }],
    }])
}

fn settings() -> RenderSettings {
    RenderSettings {
        width: 20,
        height: 20,
        integrator: Integrator::Marching,
        noise: NoiseKind::Stbn,
        seed: 5,
        step_size: Some(RADIUS / 6.0),
        phi_ref: Some(1.0),
        optical: OpticalDensityMap::new(PiecewiseLinear::ramp(0.0, 1.0), Some(2.5)).unwrap(),
        light: Light {
            intensity: 0.0,
            ambient: 1.0,
            ..Light::default()
        },
        background: [0.1, 0.2, 0.3],
        ..RenderSettings::default()
    }
}

/// The field of the two (nearly coincident) particles at `x`, in f64.
fn phi(x: DVec3) -> f64 {
    [CENTRE, CENTRE + DVec3::splat(1e-3)]
        .iter()
        .map(|c| {
            let d2 = (x - *c).length_squared();
            if d2 <= RADIUS * RADIUS {
                (-4.5 * d2 / (RADIUS * RADIUS)).exp()
            } else {
                0.0
            }
        })
        .sum()
}

/// The expected image: per pixel, the mean over the march jitter u (a 2048-point midpoint
/// rule) of the expectation over the free-flight number.
fn converged(p: &FrameParams) -> Image {
    let quadrature = 2048;
    let mut pixels = Vec::new();
    for y in 0..p.height {
        for x in 0..p.width {
            let (origin, dir) = p.primary_ray(x, y);
            let bg = p.background;
            let Some((t0, t1)) = ray_box(origin, dir, p.box_min, p.box_max) else {
                pixels.push([bg[0] as f32, bg[1] as f32, bg[2] as f32, 0.0]);
                continue;
            };
            let mut sum = [0.0f64; 3];
            let mut colour = [0.0; 3];
            for j in 0..quadrature {
                let u = (f64::from(j) + 0.5) / f64::from(quadrature);
                let mut tau = 0.0;
                let mut k = 0.0;
                loop {
                    let t = t0 + (k + u) * p.dt;
                    if t >= t1 {
                        break;
                    }
                    let f = phi(origin + dir * t);
                    // A constant attribute normalises to t = 0.5.
                    let (sigma, rgb) = p.shade(f, [0.5 * f, 0.0, 0.0]);
                    if f > 0.0 {
                        colour = rgb;
                    }
                    tau += sigma * p.dt;
                    k += 1.0;
                }
                let hit = 1.0 - (-tau).exp();
                for c in 0..3 {
                    sum[c] += colour[c] * hit + bg[c] * (1.0 - hit);
                }
            }
            let n = f64::from(quadrature);
            pixels.push([
                (sum[0] / n) as f32,
                (sum[1] / n) as f32,
                (sum[2] / n) as f32,
                0.0,
            ]);
        }
    }
    Image {
        width: p.width,
        height: p.height,
        pixels,
    }
}

#[test]
fn blue_noise_keeps_converging_past_64_frames_on_every_backend() {
    common::capture_driver_messages();
    let series = series();
    let mut field = FieldSettings::new(Some("s"), RADIUS);
    field.color_map = ColorMap::preset("grayscale").unwrap();
    let settings = settings();
    let mut reference = None;
    let mut report = Vec::new();
    for kind in [BackendKind::Cpu, BackendKind::Wgpu, BackendKind::Ash] {
        let b = common::require(&format!("the {kind} backend"), backend::create(kind));
        let mut session = RenderSession::new(b, &series);
        session
            .show(&series, 0, &field, ClusterSize::new(1).unwrap())
            .unwrap();
        let reference = reference
            .get_or_insert_with(|| converged(&session.frame_params(&settings, 0).unwrap()));
        let mut errors = Vec::new();
        let mut images = Vec::new();
        let mut done = 0;
        for spp in [64u32, 128, 256, 1024] {
            let image = session.render(&settings, spp - done).unwrap();
            done = spp;
            errors.push(image.rmse(reference));
            images.push(image);
        }
        report.push(format!(
            "{kind}: RMSE at 64, 128, 256, 1024 spp = {errors:.5?}"
        ));
        assert_ne!(
            images[0], images[1],
            "{kind}: 128 spp repeat 64 (the mask's cycle does not move)"
        );
        assert!(
            errors[2] < 0.75 * errors[0] && errors[3] < 0.75 * errors[2],
            "{kind}: the blue-noise error stops falling past 64 spp: {errors:?}"
        );
    }
    eprintln!("{}", report.join("\n"));
    common::assert_no_driver_messages();
}
