//! The CPU backend's share of a distributed frame ([`Backend::render_owned`]): the pixels of a
//! rectangle marched through one half-open box, rayon over tiles of the rectangle, each tile's
//! pixels in the packets the whole frame uses.
//!
//! [`Backend::render_owned`]: crate::backend::Backend::render_owned

use rayon::prelude::*;

use super::TILE;
use super::integrators::{FieldSampler, PACKET_SIZE, PixelScratch, render_owned_pixels_with};
use crate::backend::BackendError;
use crate::values::{FrameParams, HalfOpenBox, Integrator, PixelRect};

/// Why a frame's integrator cannot be split between boxes, if it cannot.
pub(super) fn check_integrator(frame: &FrameParams) -> Result<(), BackendError> {
    match frame.integrator {
        Integrator::Ea => Ok(()),
        other => Err(BackendError::NotDistributed {
            backend: "cpu",
            what: format!(
                "the {} integrator: single scattering across bricks (a free flight and a shadow \
                 ray that cross ranks) is not distributed yet; distributed renders are \
                 emission-absorption (--integrator ea)",
                match other {
                    Integrator::Delta => "delta",
                    Integrator::Marching => "marching",
                    Integrator::SsReference => "ss-reference",
                    Integrator::Ea => "ea",
                }
            ),
        }),
    }
}

/// `rect`'s pixels, row-major, each `[r, g, b, T]` of the samples `owned` holds.
pub(super) fn render_rect<F: FieldSampler>(
    frame: &FrameParams,
    field: &F,
    owned: &HalfOpenBox,
    rect: PixelRect,
) -> Vec<[f64; 4]> {
    let rect = rect.intersection(&PixelRect::full(frame.width, frame.height));
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
    let rendered: Vec<Vec<[f64; 4]>> = (0..tiles)
        .into_par_iter()
        .map_init(PixelScratch::<F>::default, |scratch, index| {
            let tile = tile_rect(index);
            let mut out = vec![[0.0; 4]; tile.len()];
            let (pw, ph) = PACKET_SIZE;
            let mut values = [[0.0; 4]; super::integrators::PACKET];
            let mut pixels = Vec::with_capacity(values.len());
            for by in (tile.y0..tile.y1).step_by(ph as usize) {
                for bx in (tile.x0..tile.x1).step_by(pw as usize) {
                    pixels.clear();
                    for y in by..(by + ph).min(tile.y1) {
                        for x in bx..(bx + pw).min(tile.x1) {
                            pixels.push((x, y));
                        }
                    }
                    render_owned_pixels_with(frame, field, owned, &pixels, scratch, &mut values);
                    for (&(x, y), v) in pixels.iter().zip(values) {
                        out[tile.index(x, y)] = v;
                    }
                }
            }
            out
        })
        .collect();
    let mut pixels = vec![[0.0; 4]; rect.len()];
    for (index, values) in rendered.into_iter().enumerate() {
        let tile = tile_rect(index);
        let mut values = values.into_iter();
        for y in tile.y0..tile.y1 {
            for x in tile.x0..tile.x1 {
                pixels[rect.index(x, y)] = values.next().expect("one value per pixel");
            }
        }
    }
    pixels
}
