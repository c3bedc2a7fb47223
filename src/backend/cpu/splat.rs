//! Knoll et al.'s RT splatter on the CPU (the paper's Table 3 baseline): the hits each slab
//! of a primary ray collects through the BVH ([`ReferenceField::splat_ray`], which says what a
//! hit is and how a full buffer loses hits), composited front to back, slab by slab, with the
//! same transfer functions as the RBF renderer: each particle alone at its closest approach is
//! shaded by [`FrameParams::shade`] and absorbs `alpha = 1 - exp(-sigma · length)` of what lies
//! behind it. Emission–absorption only, as in the paper's comparison; deterministic (the slabs
//! start where the ray enters the march box and are one march step long), so one frame is the
//! image.

use glam::DVec3;

use super::integrators::ray_box;
use crate::field::ReferenceField;
use crate::field::splat::{SplatCounts, SplatScratch};
use crate::values::FrameParams;

/// The splatted radiance of pixel (x, y): linear RGB and opacity, with what the slabs' buffers
/// kept and lost.
pub fn splat_pixel(
    p: &FrameParams,
    field: &ReferenceField,
    x: u32,
    y: u32,
    k: usize,
    scratch: &mut SplatScratch,
) -> ([f64; 4], SplatCounts) {
    let (origin, dir): (DVec3, DVec3) = p.primary_ray(x, y);
    let bg = p.background;
    let Some((t_enter, t_exit)) = ray_box(origin, dir, p.box_min, p.box_max) else {
        return ([bg[0], bg[1], bg[2], 0.0], SplatCounts::default());
    };
    let mut colour = [0.0; 3];
    let mut transmittance = 1.0;
    let counts = field.splat_ray(origin, dir, t_enter, t_exit, p.dt, k, scratch, |hits| {
        for hit in hits {
            let (sigma, rgb) = p.shade(hit.phi, hit.num);
            if sigma <= 0.0 {
                continue;
            }
            let alpha = 1.0 - (-sigma * hit.length).exp();
            for c in 0..3 {
                colour[c] += transmittance * alpha * rgb[c];
            }
            transmittance *= 1.0 - alpha;
            if 1.0 - transmittance >= p.opacity_threshold {
                return false;
            }
        }
        true
    });
    (
        [
            colour[0] + transmittance * bg[0],
            colour[1] + transmittance * bg[1],
            colour[2] + transmittance * bg[2],
            1.0 - transmittance,
        ],
        counts,
    )
}
