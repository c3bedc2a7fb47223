//! The integrators, per pixel: the CPU twin of `shaders_glsl/shared/integrators.glsl`.
//!
//! A primary ray is clipped to the march box (the series' bounds grown by twice the radius).
//! Samples lie at `t_enter + (k + jitter) dt`. Each sample's extinction is
//! `sigma = density_scale * D(Phi / Phi_ref)` and its colour C(Theta), Theta or
//! C(Phi / Phi_ref) by colour mode.
//!
//! - Emission–absorption: front-to-back Beer–Lambert compositing, `alpha = 1 - exp(-sigma dt)`,
//!   stopping at the opacity threshold.
//! - Single scattering: one shade point per ray, chosen by delta tracking (majorant
//!   `density_scale * max D`) or by stochastic marching (march until `Σ sigma dt` exceeds
//!   `-ln(1 - xi)`); then one shadow ray with transmittance `exp(-Σ sigma dt)` to the light.
//!   Radiance `albedo * (intensity * T_shadow + ambient)`, albedo the sample colour.
//!
//! Random numbers: dimension 0 drives the primary decision (the EA jitter or the free-flight
//! xi), 1 the stochastic-marching jitter, 2 the shadow-ray jitter: each comes from the blue
//! noise mask (shifted per seed and per 64-frame cycle, `BlueNoiseMask::cycle_shift`, so
//! accumulation keeps converging past a cycle) or the white hash. Delta tracking's further steps use white noise (dimensions
//! 3, 4, ...), since only the first decision can keep the blue-noise structure.

use glam::DVec3;

use crate::backend::BrickShare;
use crate::noise::{BlueNoiseMask, white::white};
use crate::values::frame::{ColourMode, Integrator, NoiseKind};
use crate::values::shader_constants::{NOISE_OFFSETS, PHI_EPSILON};
use crate::values::tables::{lookup, lookup_colour};
use crate::values::{Bounds, FrameParams, HalfOpenBox};

/// The field as an integrator sees it: sampled along rays, each at increasing distances (every
/// integrator marches or tracks forward), so a sampler may keep what one sample found for the
/// next ([`crate::field::F32Ray`]).
pub trait FieldSampler: Sync {
    /// What sampling along one ray keeps between samples; one per ray in flight (a pixel has
    /// its primary ray and a shadow ray), made once per thread and reused.
    type Ray: Default + Send;

    /// Starts the ray `origin + t dir` over `[t0, t1]` and appends to `occupied` the ordered
    /// sub-intervals where the field may be non-zero (outside them Phi is 0, and the
    /// integrators skip that space when density 0 has no extinction, see `march_intervals`).
    /// The default is all of it, for a sampler that does not know where its particles are.
    fn begin(
        &self,
        _ray: &mut Self::Ray,
        _origin: DVec3,
        _dir: DVec3,
        t0: f64,
        t1: f64,
        occupied: &mut Vec<(f64, f64)>,
    ) {
        occupied.push((t0, t1));
    }

    /// Phi and the Theta numerator (Σ theta_i phi_i: normalised attribute in `[0]`, or
    /// linear RGB) at `x`, the ray's point `origin + t dir` at or after its last sample.
    fn sample(&self, ray: &mut Self::Ray, x: DVec3) -> (f64, [f64; 3]);

    /// What sampling a packet of rays together keeps ([`FieldSampler::sample_packet`]).
    type Packet: Default + Send;

    /// [`FieldSampler::sample`] at the next sample of each ray of a packet (neighbouring
    /// pixels, marched in step: their samples lie close together), `None` for a ray that has
    /// none. The default samples each ray alone; a sampler whose cost is in finding
    /// candidates shares that work between the rays.
    fn sample_packet(
        &self,
        _packet: &mut Self::Packet,
        rays: &mut [Self::Ray; PACKET],
        points: &[Option<DVec3>; PACKET],
        out: &mut [(f64, [f64; 3]); PACKET],
    ) {
        for ((ray, x), out) in rays.iter_mut().zip(points).zip(out) {
            if let Some(x) = x {
                *out = self.sample(ray, *x);
            }
        }
    }
}

/// Rays marched together: a 4 x 2 block of pixels (neighbouring rays' samples at the same
/// step share their candidates), as many as the f32 kernel has lanes.
pub const PACKET: usize = crate::field::f32_kernel::LANES;

/// The block of pixels a packet covers.
pub const PACKET_SIZE: (u32, u32) = (4, 2);

/// The integrator math on a frame (kept here, beside its only users, rather than with the
/// plain value type).
impl FrameParams {
    /// A random number in [0, 1) for pixel (x, y), this frame, dimension `dim`.
    pub fn random(&self, x: u32, y: u32, dim: u32) -> f64 {
        match self.noise {
            NoiseKind::Stbn if (dim as usize) < NOISE_OFFSETS.len() => {
                let o = NOISE_OFFSETS[dim as usize];
                let mask = BlueNoiseMask::builtin();
                // A shift per seed and per cycle of the mask's depth: different seeds give
                // different (equally blue) noise, and every cycle new numbers.
                let s = BlueNoiseMask::cycle_shift(self.seed, self.frame, mask.depth);
                f64::from(mask.get(
                    x.wrapping_add(o[0]).wrapping_add(s[0]),
                    y.wrapping_add(o[1]).wrapping_add(s[1]),
                    self.frame,
                ))
            }
            _ => f64::from(white(x, y, self.frame, dim, self.seed)),
        }
    }

    /// Stochastic marching's numbers for pixel (x, y): the lattice's jitter (dimension 1) and
    /// the free-flight depth `-ln(1 - xi)` it scatters past (dimension 0).
    pub fn free_flight(&self, x: u32, y: u32) -> (f64, f64) {
        (self.random(x, y, 1), -(1.0 - self.random(x, y, 0)).ln())
    }

    /// The primary ray of pixel (x, y): origin and unit direction.
    pub fn primary_ray(&self, x: u32, y: u32) -> (DVec3, DVec3) {
        let sx = (2.0 * (f64::from(x) + 0.5) / f64::from(self.width)) - 1.0;
        let sy = 1.0 - (2.0 * (f64::from(y) + 0.5) / f64::from(self.height));
        let c = &self.camera;
        (c.eye, (c.forward + c.right * sx + c.up * sy).normalize())
    }

    /// Extinction and colour of a sample with density `phi` and Theta numerator `num`.
    pub fn shade(&self, phi: f64, num: [f64; 3]) -> (f64, [f64; 3]) {
        let x = phi / self.phi_ref;
        let sigma = self.density_scale * lookup(&self.optical_table, x);
        let rgb = match self.colour {
            ColourMode::Density => lookup_colour(&self.colour_table, x),
            _ if phi < PHI_EPSILON => [0.0; 3],
            ColourMode::Post => lookup_colour(&self.colour_table, num[0] / phi),
            ColourMode::Pre => num.map(|c| c / phi),
        };
        (sigma, rgb)
    }
}

/// Where a ray meets a box: `(t_enter, t_exit)` clipped to t >= 0, if it does.
pub fn ray_box(origin: DVec3, dir: DVec3, lo: DVec3, hi: DVec3) -> Option<(f64, f64)> {
    let inv = dir.recip();
    let t1 = (lo - origin) * inv;
    let t2 = (hi - origin) * inv;
    let t_enter = t1.min(t2).max_element().max(0.0);
    let t_exit = t1.max(t2).min_element();
    // As the GLSL twin: an inverted or unbounded box is missed.
    (t_enter < t_exit && t_exit.is_finite() && !lo.cmpgt(hi).any()).then_some((t_enter, t_exit))
}

/// The march samples `t = t0 + (k + jitter) dt` (k >= 0) that lie in one of a ray's ordered,
/// disjoint intervals and before `t1`, in order: the one rule every marching integrator
/// samples by, kept as a cursor so that rays of a packet can advance in step.
#[derive(Clone, Copy, Debug)]
pub(super) struct MarchSamples {
    t0: f64,
    t1: f64,
    dt: f64,
    jitter: f64,
    interval: usize,
    /// The next k to try in the current interval (None: start the interval).
    k: Option<f64>,
}

impl MarchSamples {
    pub(super) fn new(t0: f64, t1: f64, dt: f64, jitter: f64) -> MarchSamples {
        MarchSamples {
            t0,
            t1,
            dt,
            jitter,
            interval: 0,
            k: None,
        }
    }

    /// The next sample in `intervals` (the same ones at every call), if any.
    pub(super) fn next(&mut self, intervals: &[(f64, f64)]) -> Option<f64> {
        while let Some(&(a, b)) = intervals.get(self.interval) {
            let b = b.min(self.t1);
            let mut k = self
                .k
                .unwrap_or_else(|| ((a - self.t0) / self.dt - self.jitter).ceil().max(0.0));
            loop {
                let t = self.t0 + (k + self.jitter) * self.dt;
                if t >= b {
                    break;
                }
                k += 1.0;
                if t >= a {
                    self.k = Some(k);
                    return Some(t);
                }
            }
            self.interval += 1;
            self.k = None;
        }
        None
    }
}

/// Starts sampling `ray` and gives the sub-intervals of `[t0, t1]` along it to march: those
/// where the field has particles, when space without particles is truly empty (the optical
/// map's D(0) is 0); otherwise the whole interval, since extinction there is `scale · D(0)`
/// (and its colour may show). The GPU backends march every sample; skipping changes no result
/// where it is done. Returns whether empty space is clear: then a sample where Phi is 0 adds
/// nothing and need not be shaded.
#[allow(clippy::too_many_arguments)]
pub(super) fn march_intervals<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    ray: &mut F::Ray,
    origin: DVec3,
    dir: DVec3,
    t0: f64,
    t1: f64,
    out: &mut Vec<(f64, f64)>,
) -> bool {
    field.begin(ray, origin, dir, t0, t1, out);
    let clear = p.shade(0.0, [0.0; 3]).0 <= 0.0;
    if !clear {
        out.clear();
        out.push((t0, t1));
    }
    clear
}

/// Transmittance from `x` towards the light to the march box's exit: `exp(-Σ sigma dt)`.
/// In a brick, marched to the brick's exit, plus the depth nearer the light that the bricks
/// before it left ([`BrickShare::light`]).
/// (Shadow rays marched as packets were measured and not kept: a packet's scattering points
/// lie at different depths, so their samples rarely share cells.)
fn shadow<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    brick: Option<&BrickShare<'_>>,
    ray: &mut F::Ray,
    x: DVec3,
    jitter: f64,
    scratch: &mut Vec<(f64, f64)>,
) -> f64 {
    let march_box = p.march_box();
    let (exit_box, mut tau) = match brick {
        Some(b) => (b.owned.clipped_to(march_box), b.light_depth_at(x)),
        None => (march_box, 0.0),
    };
    let Some((_, t_exit)) = ray_box(x, p.light_dir, exit_box.min, exit_box.max) else {
        return (-tau).exp();
    };
    scratch.clear();
    let clear_where_empty = march_intervals(p, field, ray, x, p.light_dir, 0.0, t_exit, scratch);
    let mut samples = MarchSamples::new(0.0, t_exit, p.dt, jitter);
    while let Some(t) = samples.next(scratch) {
        let (phi, num) = field.sample(ray, x + p.light_dir * t);
        if phi == 0.0 && clear_where_empty {
            continue;
        }
        tau += p.shade(phi, num).0 * p.dt;
        // Beyond this the light is gone to f64 precision; stop marching.
        if tau >= 745.0 {
            break;
        }
    }
    (-tau).exp()
}

/// What a packet's rays keep while they are marched (their samplers' state and their
/// intervals, the packet's shared state, a shadow ray), made once per thread and reused.
pub struct PixelScratch<F: FieldSampler> {
    pub(super) primary: [F::Ray; PACKET],
    pub(super) intervals: [Vec<(f64, f64)>; PACKET],
    pub(super) packet: F::Packet,
    shadow: F::Ray,
    shadow_intervals: Vec<(f64, f64)>,
}

impl<F: FieldSampler> Default for PixelScratch<F> {
    fn default() -> Self {
        PixelScratch {
            primary: std::array::from_fn(|_| F::Ray::default()),
            intervals: std::array::from_fn(|_| Vec::new()),
            packet: F::Packet::default(),
            shadow: F::Ray::default(),
            shadow_intervals: Vec::new(),
        }
    }
}

/// The radiance of pixel (x, y) in this frame: linear RGB and opacity (scratch made for the
/// call; [`render_pixel_with`] reuses it).
pub fn render_pixel<F: FieldSampler>(p: &FrameParams, field: &F, x: u32, y: u32) -> [f64; 4] {
    render_pixel_with(p, field, x, y, &mut PixelScratch::default())
}

/// The radiance of each of `pixels` (at most [`PACKET`], neighbours: a block of
/// [`PACKET_SIZE`]) into `out`: the marching integrators march them as one packet, the others
/// one pixel at a time. Each pixel's value is what [`render_pixel_with`] gives it, up to the
/// order a sampler sums a sample's terms in.
pub fn render_pixels_with<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    pixels: &[(u32, u32)],
    scratch: &mut PixelScratch<F>,
    out: &mut [[f64; 4]],
) {
    match p.integrator {
        Integrator::Ea | Integrator::SsReference | Integrator::Marching => {
            march_packet(p, field, None, pixels, scratch, out)
        }
        Integrator::Delta => {
            for (o, &(x, y)) in out.iter_mut().zip(pixels) {
                *o = delta_tracking(p, field, None, x, y, scratch);
            }
        }
    }
}

/// A brick's share of each of `pixels` ([`crate::backend::Backend::render_owned`]): the
/// frame's samples (the same lattice `t_enter + (k + jitter) dt` from the march box's entry as
/// the whole frame's) whose points lie in the brick's half-open box, as premultiplied colour
/// and the transmittance left, `[r, g, b, T]`, with no background. Boxes that tile space split
/// every pixel's samples between them, each sample to one box, so compositing their values in
/// the order a ray meets the boxes (`C = C_front + T_front C`, `T = T_front T`) gives the
/// whole frame's emission–absorption up to rounding, and exactly its value for a box holding
/// all of space. Early termination applies per box, from the bound of the transmittance in
/// front where the share gives a depth in front ([`BrickShare::depth_in_front`]). Single scattering gives `[L, 0]` where
/// the pixel scatters in this brick and `[0, 0, 0, 1]` elsewhere: stochastic marching starts
/// from the depth in front of the brick, delta tracking tracks the brick's segment, and
/// shadow rays add the depth nearer the light ([`BrickShare`]).
pub fn render_owned_pixels_with<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    brick: &BrickShare<'_>,
    pixels: &[(u32, u32)],
    scratch: &mut PixelScratch<F>,
    out: &mut [[f64; 4]],
) {
    match p.integrator {
        Integrator::Ea | Integrator::SsReference | Integrator::Marching => {
            march_packet(p, field, Some(brick), pixels, scratch, out)
        }
        Integrator::Delta => {
            for (o, &(x, y)) in out.iter_mut().zip(pixels) {
                *o = delta_tracking(p, field, Some(brick), x, y, scratch);
            }
        }
    }
}

/// Keeps of a ray's `intervals` the part where it can meet `owned` within the march box. The
/// box is grown by a step first, so that no rounding of where the ray crosses its faces drops
/// a sample: which samples are owned is decided by their points, not by these bounds.
pub(super) fn clip_to_owned(
    p: &FrameParams,
    owned: &HalfOpenBox,
    origin: DVec3,
    dir: DVec3,
    intervals: &mut Vec<(f64, f64)>,
) {
    clip_to_box(
        owned.clipped_to(p.march_box()).grown(p.dt),
        origin,
        dir,
        intervals,
    );
}

/// Keeps of a ray's `intervals` the part inside `b`.
fn clip_to_box(b: Bounds, origin: DVec3, dir: DVec3, intervals: &mut Vec<(f64, f64)>) {
    match ray_box(origin, dir, b.min, b.max) {
        None => intervals.clear(),
        Some((a, e)) => intervals.retain_mut(|(s, t)| {
            *s = s.max(a);
            *t = t.min(e);
            *s < *t
        }),
    }
}

/// Light reaching `at` (shadowed by the field, plus ambient) times `albedo`.
#[allow(clippy::too_many_arguments)]
fn radiance<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    brick: Option<&BrickShare<'_>>,
    shadow_ray: &mut F::Ray,
    scratch: &mut Vec<(f64, f64)>,
    at: DVec3,
    albedo: [f64; 3],
    shadow_jitter: f64,
) -> [f64; 3] {
    let light = p.light_intensity * shadow(p, field, brick, shadow_ray, at, shadow_jitter, scratch)
        + p.ambient;
    albedo.map(|a| a * light)
}

/// A ray of a marched packet: where it is and what it has gathered.
#[derive(Clone, Copy)]
struct MarchedRay {
    origin: DVec3,
    dir: DVec3,
    /// Whether a sample where Phi is 0 adds nothing ([`march_intervals`]).
    clear_where_empty: bool,
    samples: MarchSamples,
    shadow_jitter: f64,
    /// Emission–absorption: the colour gathered and the transmittance so far, and at most
    /// the transmittance of the bricks in front (1 for a whole frame).
    colour: [f64; 3],
    transmittance: f64,
    front_transmittance: f64,
    /// Stochastic marching: the optical depth so far and the one it stops at.
    tau: f64,
    target_tau: f64,
}

impl MarchedRay {
    /// The ray of pixel (x, y) as [`march_packet`] starts it, its sample intervals found (and
    /// clipped to `owned`) in `intervals`; `None` when it misses the box.
    #[inline]
    fn start<F: FieldSampler>(
        p: &FrameParams,
        field: &F,
        brick: Option<&BrickShare<'_>>,
        (x, y): (u32, u32),
        primary: &mut F::Ray,
        intervals: &mut Vec<(f64, f64)>,
    ) -> Option<MarchedRay> {
        let (origin, dir) = p.primary_ray(x, y);
        let (t_enter, t_exit) = ray_box(origin, dir, p.box_min, p.box_max)?;
        // Dimension 0 is the primary decision: emission–absorption's jitter, or stochastic
        // marching's free-flight number (its jitter is dimension 1, as the reference's).
        let (jitter, target_tau) = match p.integrator {
            Integrator::Marching => p.free_flight(x, y),
            Integrator::SsReference => (p.random(x, y, 1), f64::INFINITY),
            _ => (p.random(x, y, 0), f64::INFINITY),
        };
        // In a brick, stochastic marching goes on from the depth of the bricks in front; past
        // the free-flight depth already, the ray scattered in front of this brick.
        // Emission–absorption ends where the transmittance in front times its own falls to
        // 1 - threshold; where that in front does, before its first sample (and before its
        // intervals are looked for).
        let tau = brick.map_or(0.0, |b| b.depth_in_front(x, y));
        let front_transmittance = if p.integrator == Integrator::Marching {
            1.0
        } else {
            (-tau).exp()
        };
        let ended_in_front = brick.is_some() && 1.0 - front_transmittance >= p.opacity_threshold;
        if tau.is_nan() || tau > target_tau || ended_in_front {
            return None;
        }
        intervals.clear();
        let clear_where_empty =
            march_intervals(p, field, primary, origin, dir, t_enter, t_exit, intervals);
        if let Some(b) = brick {
            clip_to_owned(p, b.owned, origin, dir, intervals);
        }
        Some(MarchedRay {
            origin,
            dir,
            clear_where_empty,
            samples: MarchSamples::new(t_enter, t_exit, p.dt, jitter),
            shadow_jitter: p.random(x, y, 2),
            colour: [0.0; 3],
            transmittance: 1.0,
            front_transmittance,
            tau,
            target_tau,
        })
    }

    /// The pixel's value: what the ray gathered over the background; or, for a ray marched
    /// through an owned box only, what it gathered there, `[r, g, b, T]` (premultiplied colour
    /// and transmittance, no background).
    fn finish(&self, bg: [f64; 3], brick: Option<&BrickShare<'_>>) -> [f64; 4] {
        if brick.is_some() {
            let c = self.colour;
            return [c[0], c[1], c[2], self.transmittance];
        }
        let c = self.colour;
        let tr = self.transmittance;
        [
            c[0] + tr * bg[0],
            c[1] + tr * bg[1],
            c[2] + tr * bg[2],
            1.0 - tr,
        ]
    }
}

/// The marching integrators on `pixels`' rays, marched in step so the field samples their
/// k-th samples together ([`FieldSampler::sample_packet`]): emission–absorption (with a
/// shadow ray per sample for the single-scattering reference), front-to-back compositing until
/// the opacity threshold; stochastic marching, until the optical depth passes `-ln(1 - xi)`,
/// then one shadow ray from there. A ray leaves the packet when it is done or has no samples
/// left.
fn march_packet<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    brick: Option<&BrickShare<'_>>,
    pixels: &[(u32, u32)],
    scratch: &mut PixelScratch<F>,
    out: &mut [[f64; 4]],
) {
    assert!(pixels.len() <= PACKET && out.len() >= pixels.len());
    let bg = p.background;
    let scatter = p.integrator == Integrator::SsReference;
    let PixelScratch {
        primary,
        intervals,
        packet,
        shadow: shadow_ray,
        shadow_intervals,
    } = scratch;
    let owned = brick.map(|b| b.owned);
    let mut rays: [Option<MarchedRay>; PACKET] = [None; PACKET];
    for (i, &pixel) in pixels.iter().enumerate() {
        out[i] = match brick {
            None => [bg[0], bg[1], bg[2], 0.0],
            Some(_) => [0.0, 0.0, 0.0, 1.0],
        };
        rays[i] = MarchedRay::start(p, field, brick, pixel, &mut primary[i], &mut intervals[i]);
    }
    // What a ray's sample at `at` scatters towards the camera, `albedo` under the light there.
    let mut lit = |ray: &MarchedRay, at: DVec3, albedo: [f64; 3]| {
        radiance(
            p,
            field,
            brick,
            shadow_ray,
            shadow_intervals,
            at,
            albedo,
            ray.shadow_jitter,
        )
    };
    // Each ray's next sample point (kept small: a packet's points are rewritten every step).
    let mut points: [Option<DVec3>; PACKET] = [None; PACKET];
    let mut values = [(0.0, [0.0; 3]); PACKET];
    loop {
        let mut any = false;
        for i in 0..PACKET {
            points[i] = None;
            let Some(ray) = &mut rays[i] else { continue };
            match ray.samples.next(&intervals[i]) {
                Some(t) => {
                    let at = ray.origin + ray.dir * t;
                    // Another box's sample is another rank's (the ray marches on).
                    if owned.is_none_or(|b| b.contains(at)) {
                        points[i] = Some(at);
                    }
                    any = true;
                }
                None => {
                    out[i] = ray.finish(bg, brick);
                    rays[i] = None;
                }
            }
        }
        if !any {
            return;
        }
        if points.iter().all(Option::is_none) {
            // Every ray of the packet is crossing another box's samples.
            continue;
        }
        field.sample_packet(packet, primary, &points, &mut values);
        for i in 0..PACKET {
            let (Some(ray), Some(at)) = (&mut rays[i], points[i]) else {
                continue;
            };
            let (phi, num) = values[i];
            if phi == 0.0 && ray.clear_where_empty {
                continue;
            }
            let (sigma, rgb) = p.shade(phi, num);
            if p.integrator == Integrator::Marching {
                ray.tau += sigma * p.dt;
                if ray.tau > ray.target_tau {
                    let l = lit(ray, at, rgb);
                    // Opaque: alpha 1 over the background, transmittance 0 in a brick.
                    out[i] = [l[0], l[1], l[2], if brick.is_some() { 0.0 } else { 1.0 }];
                    rays[i] = None;
                }
                continue;
            }
            if sigma <= 0.0 {
                continue;
            }
            let alpha = 1.0 - (-sigma * p.dt).exp();
            let emitted = if scatter { lit(ray, at, rgb) } else { rgb };
            for (c, e) in ray.colour.iter_mut().zip(emitted) {
                *c += ray.transmittance * alpha * e;
            }
            ray.transmittance *= 1.0 - alpha;
            if 1.0 - ray.front_transmittance * ray.transmittance >= p.opacity_threshold {
                out[i] = ray.finish(bg, brick);
                rays[i] = None;
            }
        }
    }
}

/// The radiance of pixel (x, y) in this frame: linear RGB and opacity. The marching
/// integrators march it as a packet of one (`march_packet`); delta tracking is
/// [`delta_tracking`].
pub fn render_pixel_with<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    x: u32,
    y: u32,
    scratch: &mut PixelScratch<F>,
) -> [f64; 4] {
    if p.integrator == Integrator::Delta {
        return delta_tracking(p, field, None, x, y, scratch);
    }
    let mut out = [[0.0; 4]];
    march_packet(p, field, None, &[(x, y)], scratch, &mut out);
    out[0]
}

/// Delta tracking of pixel (x, y): over the whole ray, or in a brick over the ray's segment in
/// the brick's box (exactly: a free flight is memoryless, so a brick tracks its own segment,
/// and the first brick along the ray where a collision happens decides, as the whole ray's
/// tracking would in distribution). Returns linear RGB and opacity, or in a brick `[L, 0]`
/// where it collides and `[0, 0, 0, 1]` where not.
fn delta_tracking<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    brick: Option<&BrickShare<'_>>,
    x: u32,
    y: u32,
    scratch: &mut PixelScratch<F>,
) -> [f64; 4] {
    let (origin, dir) = p.primary_ray(x, y);
    let bg = p.background;
    let miss = match brick {
        None => [bg[0], bg[1], bg[2], 0.0],
        Some(_) => [0.0, 0.0, 0.0, 1.0],
    };
    let Some((t_enter, t_exit)) = ray_box(origin, dir, p.box_min, p.box_max) else {
        return miss;
    };
    let PixelScratch {
        primary,
        intervals,
        shadow: shadow_ray,
        shadow_intervals: scratch,
        ..
    } = scratch;
    let (primary, intervals) = (&mut primary[0], &mut intervals[0]);
    intervals.clear();
    // Delta tracking: free flights skip the space outside the intervals (null collisions
    // only), so whether empty space is clear does not matter to it.
    march_intervals(p, field, primary, origin, dir, t_enter, t_exit, intervals);
    if let Some(b) = brick {
        // The segment in the brick's box exactly: its samples are its own.
        clip_to_box(b.owned.clipped_to(p.march_box()), origin, dir, intervals);
    }
    if p.majorant <= 0.0 {
        return miss;
    }
    let Some(&(first, _)) = intervals.first() else {
        return miss;
    };
    let mut dim = 0;
    let mut interval = 0;
    let mut t = first;
    loop {
        let xi = p.random(x, y, dim);
        dim = if dim == 0 { 3 } else { dim + 1 };
        t -= (1.0 - xi).ln() / p.majorant;
        // Skip empty space: a flight through it is a run of null collisions, and what
        // overshoots an interval's end carries on from the next one's start (the
        // exponential distribution is memoryless).
        while t >= intervals[interval].1 {
            let over = t - intervals[interval].1;
            interval += 1;
            if interval == intervals.len() {
                return miss;
            }
            t = intervals[interval].0 + over;
        }
        let at = origin + dir * t;
        let (phi, num) = field.sample(primary, at);
        let (sigma, rgb) = p.shade(phi, num);
        let accept = p.random(x, y, dim);
        dim += 1;
        if accept * p.majorant < sigma {
            let l = radiance(
                p,
                field,
                brick,
                shadow_ray,
                scratch,
                at,
                rgb,
                p.random(x, y, 2),
            );
            return [l[0], l[1], l[2], if brick.is_some() { 0.0 } else { 1.0 }];
        }
        if dim > 100_000 {
            // Bounded work per pixel: a majorant far above the real extinction would
            // otherwise take arbitrarily many null collisions.
            return miss;
        }
    }
}

#[cfg(test)]
mod tests;
