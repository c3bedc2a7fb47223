//! The CPU backend's share of a distributed frame ([`Backend::render_owned`],
//! [`Backend::owned_depth`]): the pixels of a rectangle marched through one half-open box,
//! rayon over tiles of the rectangle, each tile's pixels in the packets the whole frame uses.
//!
//! [`Backend::render_owned`]: crate::backend::Backend::render_owned
//! [`Backend::owned_depth`]: crate::backend::Backend::owned_depth

use glam::DVec3;
use rayon::prelude::*;

use super::TILE;
use super::integrators::{
    FieldSampler, MarchSamples, PACKET, PACKET_SIZE, PixelScratch, clip_to_owned, march_intervals,
    ray_box, render_owned_pixels_with,
};
use crate::backend::{BrickShare, DepthRays};
use crate::noise::white::white;
use crate::values::shader_constants::LIGHT_MAP_SEED;
use crate::values::{FrameParams, HalfOpenBox, PixelRect};

/// `brick.rect`'s pixels, row-major, each `[r, g, b, T]` of the samples the brick owns.
pub(super) fn render_rect<F: FieldSampler>(
    frame: &FrameParams,
    field: &F,
    brick: &BrickShare<'_>,
) -> Vec<[f64; 4]> {
    let own_frame = brick.own_frame(frame);
    let frame = own_frame.as_ref().unwrap_or(frame);
    in_packets(brick.rect, [0.0; 4], |scratch, pixels, values| {
        render_owned_pixels_with(frame, field, brick, pixels, scratch, values)
    })
}

/// The optical depth of the samples `owned` holds along each of `rays`, row-major over its
/// rectangle.
pub(super) fn depth_rect<F: FieldSampler>(
    frame: &FrameParams,
    field: &F,
    owned: &HalfOpenBox,
    rays: DepthRays<'_>,
) -> Vec<f64> {
    in_packets(rays.rect(), 0.0, |scratch, pixels, values| {
        let mut specs = [DepthRay::default(); PACKET];
        for (spec, &(x, y)) in specs.iter_mut().zip(pixels) {
            *spec = DepthRay::of(frame, rays, x, y);
        }
        depth_packet(frame, field, owned, &specs[..pixels.len()], scratch, values);
    })
}

/// Runs `packet` on every block of [`PACKET_SIZE`] pixels (or light map texels) of `rect`,
/// rayon over tiles, and returns its values row-major.
fn in_packets<F: FieldSampler, T: Copy + Send + Sync>(
    rect: PixelRect,
    zero: T,
    packet: impl Fn(&mut PixelScratch<F>, &[(u32, u32)], &mut [T; PACKET]) + Sync,
) -> Vec<T> {
    let tiles_x = rect.width().div_ceil(TILE);
    let tiles = (tiles_x * rect.height().div_ceil(TILE)) as usize;
    let tile_rect = |index: usize| {
        let (tx, ty) = (index as u32 % tiles_x, index as u32 / tiles_x);
        let (x0, y0) = (rect.x0 + tx * TILE, rect.y0 + ty * TILE);
        PixelRect {
            x0,
            y0,
            x1: (x0 + TILE).min(rect.x1),
            y1: (y0 + TILE).min(rect.y1),
        }
    };
    let rendered: Vec<Vec<T>> = (0..tiles)
        .into_par_iter()
        .map_init(PixelScratch::<F>::default, |scratch, index| {
            let tile = tile_rect(index);
            let mut out = vec![zero; tile.len()];
            let (pw, ph) = PACKET_SIZE;
            let mut values = [zero; PACKET];
            let mut pixels = Vec::with_capacity(values.len());
            for by in (tile.y0..tile.y1).step_by(ph as usize) {
                for bx in (tile.x0..tile.x1).step_by(pw as usize) {
                    pixels.clear();
                    for y in by..(by + ph).min(tile.y1) {
                        for x in bx..(bx + pw).min(tile.x1) {
                            pixels.push((x, y));
                        }
                    }
                    packet(scratch, &pixels, &mut values);
                    for (&(x, y), v) in pixels.iter().zip(values) {
                        out[tile.index(x, y)] = v;
                    }
                }
            }
            out
        })
        .collect();
    let mut pixels = vec![zero; rect.len()];
    for (index, values) in rendered.into_iter().enumerate() {
        for ((x, y), v) in tile_rect(index).pixels().zip(values) {
            pixels[rect.index(x, y)] = v;
        }
    }
    pixels
}

/// One ray of a depth pass: where it starts, its lattice's jitter, and the depth past which
/// it stops.
#[derive(Clone, Copy, Debug, Default)]
struct DepthRay {
    origin: DVec3,
    dir: DVec3,
    jitter: f64,
    stop_past: f64,
}

impl DepthRay {
    /// Pixel or texel `(x, y)` of `rays`: a primary ray on stochastic marching's lattice
    /// (jitter dimension 1) stopped past its free-flight depth (dimension 0), as
    /// `MarchedRay::start` starts it; an occluding ray on emission–absorption's (dimension 0)
    /// stopped past its given depth; a light map ray marched whole.
    fn of(frame: &FrameParams, rays: DepthRays<'_>, x: u32, y: u32) -> DepthRay {
        match rays {
            DepthRays::Primary(_) => {
                let (origin, dir) = frame.primary_ray(x, y);
                let (jitter, stop_past) = frame.free_flight(x, y);
                DepthRay {
                    origin,
                    dir,
                    jitter,
                    stop_past,
                }
            }
            DepthRays::Occluding { stop_past, .. } => {
                let (origin, dir) = frame.primary_ray(x, y);
                DepthRay {
                    origin,
                    dir,
                    jitter: frame.random(x, y, 0),
                    stop_past,
                }
            }
            DepthRays::Light(map, _) => {
                let (origin, dir) = map.texel_ray(x, y);
                DepthRay {
                    origin,
                    dir,
                    jitter: f64::from(white(x, y, 0, 0, LIGHT_MAP_SEED)),
                    stop_past: f64::INFINITY,
                }
            }
        }
    }
}

/// The depth of each of `rays` through the samples `owned` holds, marched as a packet (their
/// k-th samples together, as `march_packet` marches a frame's).
fn depth_packet<F: FieldSampler>(
    p: &FrameParams,
    field: &F,
    owned: &HalfOpenBox,
    rays: &[DepthRay],
    scratch: &mut PixelScratch<F>,
    out: &mut [f64; PACKET],
) {
    let PixelScratch {
        primary,
        intervals,
        packet,
        ..
    } = scratch;
    let mut marching: [Option<(MarchSamples, bool)>; PACKET] = [None; PACKET];
    for (i, ray) in rays.iter().enumerate() {
        out[i] = 0.0;
        let Some((t_enter, t_exit)) = ray_box(ray.origin, ray.dir, p.box_min, p.box_max) else {
            continue;
        };
        let (origin, dir) = (ray.origin, ray.dir);
        intervals[i].clear();
        let clear = march_intervals(
            p,
            field,
            &mut primary[i],
            origin,
            dir,
            t_enter,
            t_exit,
            &mut intervals[i],
        );
        clip_to_owned(p, owned, origin, dir, &mut intervals[i]);
        marching[i] = Some((MarchSamples::new(t_enter, t_exit, p.dt, ray.jitter), clear));
    }
    let mut points: [Option<DVec3>; PACKET] = [None; PACKET];
    let mut values = [(0.0, [0.0; 3]); PACKET];
    loop {
        let mut any = false;
        for i in 0..PACKET {
            points[i] = None;
            let Some((samples, _)) = &mut marching[i] else {
                continue;
            };
            match samples.next(&intervals[i]) {
                Some(t) => {
                    let at = rays[i].origin + rays[i].dir * t;
                    if owned.contains(at) {
                        points[i] = Some(at);
                    }
                    any = true;
                }
                None => marching[i] = None,
            }
        }
        if !any {
            return;
        }
        if points.iter().all(Option::is_none) {
            continue;
        }
        field.sample_packet(packet, primary, &points, &mut values);
        for i in 0..PACKET {
            let (Some((_, clear)), Some(_)) = (marching[i], points[i]) else {
                continue;
            };
            let (phi, num) = values[i];
            if phi == 0.0 && clear {
                continue;
            }
            out[i] += p.shade(phi, num).0 * p.dt;
            if out[i] > rays[i].stop_past {
                marching[i] = None;
            }
        }
    }
}
