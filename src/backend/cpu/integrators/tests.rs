use super::*;
use std::sync::Arc;

use crate::scene::Camera;
use crate::scene::maps::{ColorMap, PiecewiseLinear};

/// A field given by a closure: Phi(x), with Theta numerator 0.5 Phi (mid attribute).
struct Analytic<F: Fn(DVec3) -> f64 + Sync>(F);

impl<F: Fn(DVec3) -> f64 + Sync> FieldSampler for Analytic<F> {
    type Ray = ();
    type Packet = ();

    fn sample(&self, _: &mut (), x: DVec3) -> (f64, [f64; 3]) {
        let phi = (self.0)(x);
        (phi, [0.5 * phi, 0.0, 0.0])
    }
}

/// A 1-pixel (or n x n) view down -z from (0, 0, 5) onto the origin, box [-1, 1]^3.
fn params(integrator: Integrator, size: u32, dt: f64, density_scale: f64) -> FrameParams {
    let camera = Camera {
        eye: DVec3::new(0.0, 0.0, 5.0),
        at: DVec3::ZERO,
        up: DVec3::Y,
        fovy: 20.0,
    };
    FrameParams {
        width: size,
        height: size,
        frame: 0,
        seed: 7,
        camera: camera.frame(size, size).unwrap(),
        box_min: DVec3::splat(-1.0),
        box_max: DVec3::splat(1.0),
        dt,
        opacity_threshold: 1.0,
        phi_ref: 1.0,
        density_scale,
        majorant: density_scale,
        light_dir: DVec3::new(0.3, 0.8, 0.5).normalize(),
        light_intensity: 1.0,
        ambient: 0.2,
        background: [0.1, 0.2, 0.3],
        integrator,
        noise: NoiseKind::White,
        colour: ColourMode::Post,
        optical_table: Arc::new(PiecewiseLinear::ramp(0.0, 1.0).bake()),
        colour_table: Arc::new(ColorMap::preset("grayscale").unwrap().bake()),
    }
}

#[test]
fn the_half_lattice_looks_along_the_full_images_even_pixels_rays() {
    for (w, h) in [(7, 5), (8, 6), (1, 1), (3, 10), (640, 361)] {
        let mut full = params(Integrator::Ea, 1, 0.1, 1.0);
        let camera = Camera {
            eye: DVec3::new(0.3, -1.0, 5.0),
            at: DVec3::new(0.1, 0.2, 0.0),
            up: DVec3::new(0.1, 1.0, 0.0),
            fovy: 37.0,
        };
        (full.width, full.height) = (w, h);
        full.camera = camera.frame(w, h).unwrap();
        let lattice = full.clone().on_half_lattice();
        assert_eq!(
            (lattice.width, lattice.height),
            (w.div_ceil(2), h.div_ceil(2))
        );
        for j in 0..lattice.height {
            for i in 0..lattice.width {
                let (o, d) = lattice.primary_ray(i, j);
                let (fo, fd) = full.primary_ray(2 * i, 2 * j);
                assert_eq!(o, fo);
                assert!((d - fd).length() < 1e-12, "{w}x{h} ({i}, {j}): {d} vs {fd}");
            }
        }
    }
}

fn mean_pixel(
    p: &mut FrameParams,
    field: &impl FieldSampler,
    x: u32,
    y: u32,
    frames: u32,
) -> [f64; 4] {
    let mut sum = [0.0; 4];
    for f in 0..frames {
        p.frame = f;
        let v = render_pixel(p, field, x, y);
        for c in 0..4 {
            sum[c] += v[c] / f64::from(frames);
        }
    }
    sum
}

/// erf by its Abramowitz–Stegun 7.1.26 approximation is too coarse here; integrate the
/// truncated Gaussian numerically with Simpson's rule instead (error < 1e-12).
fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

#[test]
fn one_particle_optical_depth_through_its_centre() {
    // One particle of radius r at the origin: along a ray through the centre the optical
    // depth is scale * ∫_{-r}^{r} exp(-4.5 s² / r²) ds (the truncated Gaussian integral).
    let r = 0.5;
    let field = Analytic(|x: DVec3| {
        let d2 = x.length_squared();
        if d2 <= r * r {
            (-4.5 * d2 / (r * r)).exp()
        } else {
            0.0
        }
    });
    let scale = 3.0;
    let tau = scale * simpson(|s| (-4.5 * s * s / (r * r)).exp(), -r, r, 10_000);
    assert!(
        (tau / scale - r * (std::f64::consts::PI / 4.5).sqrt() * 0.997_300_2).abs() < 1e-6,
        "closed form: r sqrt(pi/4.5) erf(sqrt 4.5)"
    );
    let mut p = params(Integrator::Ea, 1, r / 200.0, scale);
    let got = mean_pixel(&mut p, &field, 0, 0, 64);
    let expected_alpha = 1.0 - (-tau).exp();
    assert!(
        (got[3] - expected_alpha).abs() < 1e-5,
        "alpha {} vs {expected_alpha}",
        got[3]
    );
    // The colour: grayscale C(0.5) emitted, background behind.
    let grey = ColorMap::preset("grayscale").unwrap().linear_rgb(0.5)[0];
    let expected_red = expected_alpha * grey + (1.0 - expected_alpha) * 0.1;
    assert!(
        (got[0] - expected_red).abs() < 1e-4,
        "red {} vs {expected_red}",
        got[0]
    );
}

#[test]
fn homogeneous_slab_transmittance() {
    // sigma = 2 for |z| < 0.25 (Phi = 1): T = exp(-2 * 0.5).
    let field = Analytic(|x: DVec3| if x.z.abs() < 0.25 { 1.0 } else { 0.0 });
    let mut p = params(Integrator::Ea, 1, 0.01, 2.0);
    let got = mean_pixel(&mut p, &field, 0, 0, 256);
    let expected = 1.0 - (-1.0f64).exp();
    assert!((got[3] - expected).abs() < 2e-3, "{} vs {expected}", got[3]);
}

#[test]
fn early_exit_and_empty_rays() {
    let field = Analytic(|_| 1.0);
    let mut p = params(Integrator::Ea, 1, 0.01, 50.0);
    p.opacity_threshold = 0.99;
    let v = render_pixel(&p, &field, 0, 0);
    assert!(v[3] >= 0.99 && v[3] < 0.9999, "stops once opaque: {}", v[3]);
    let empty = Analytic(|_| 0.0);
    for integrator in [
        Integrator::Ea,
        Integrator::Delta,
        Integrator::Marching,
        Integrator::SsReference,
    ] {
        let v = render_pixel(&params(integrator, 1, 0.01, 1.0), &empty, 0, 0);
        assert_eq!(
            v,
            [0.1, 0.2, 0.3, 0.0],
            "{integrator:?}: an empty volume shows the background"
        );
    }
}

/// RMSE over an image between an estimator at `spp` and a reference.
fn rmse(p: &mut FrameParams, field: &impl FieldSampler, spp: u32, reference: &[[f64; 4]]) -> f64 {
    let n = p.width;
    let mut err = 0.0;
    for y in 0..n {
        for x in 0..n {
            let v = mean_pixel(p, field, x, y, spp);
            let r = reference[(y * n + x) as usize];
            err += (0..3).map(|c| (v[c] - r[c]).powi(2)).sum::<f64>();
        }
    }
    (err / f64::from(3 * n * n)).sqrt()
}

#[test]
fn delta_tracking_and_stochastic_marching_converge_to_the_marched_reference() {
    // A Gaussian blob, lit from above: the marched single-scattering reference (every
    // sample shaded, a shadow ray each) against the one-shade-point estimators.
    let field = Analytic(|x: DVec3| 1.5 * (-x.length_squared() / (2.0 * 0.3f64.powi(2))).exp());
    let (size, dt, scale) = (6, 0.02, 4.0);
    let mut reference_params = params(Integrator::SsReference, size, dt, scale);
    let reference: Vec<[f64; 4]> = (0..size * size)
        .map(|i| mean_pixel(&mut reference_params, &field, i % size, i / size, 32))
        .collect();
    for integrator in [Integrator::Delta, Integrator::Marching] {
        let mut p = params(integrator, size, dt, scale);
        p.majorant = scale * 1.5;
        let errors: Vec<f64> = [16, 256, 4096]
            .iter()
            .map(|&spp| rmse(&mut p, &field, spp, &reference))
            .collect();
        eprintln!("{integrator:?}: RMSE at 16, 256, 4096 spp = {errors:?}");
        assert!(
            errors[1] < errors[0] * 0.5 && errors[2] < errors[1] * 0.5,
            "{integrator:?}: {errors:?}"
        );
        assert!(errors[2] < 0.01, "{integrator:?} converges: {errors:?}");
    }
}
