//! Early termination across bricks for emission–absorption: the work behind opaque bricks.
//!
//! A single rank stops each ray once its opacity reaches the threshold and never samples what
//! lies behind. A brick alone cannot: the bricks in front of it may already be opaque along a
//! pixel, and without knowing it the brick renders samples the composite then hides (on the
//! 1M dam break at P = 4, the work summed over the ranks grew by 44%). Before rendering, each
//! brick therefore marches a coarse frame (a pixel of it for [`COARSENESS`]² of the image's),
//! on emission–absorption's lattice and stopped where its depth alone ends every ray behind
//! ([`DepthRays::Occluding`]); an exclusive scan in view order ([`super::scan`]) gives each
//! brick the depth in front along those coarse rays. [`depth_bound`] makes of it, per pixel of
//! the image, the least depth of the coarse rays around the pixel, times [`DEPTH_MARGIN`]: at
//! most the depth in front along the pixel's own ray, so `exp(-bound)` bounds the
//! transmittance in front from above, and the brick ends a ray where that bound times its own
//! transmittance falls to `1 - threshold` (`BrickShare::depth_in_front`). A ray never ends
//! before the single rank's would, so the image differs from the single rank's by what early
//! termination itself leaves out (at most `1 - threshold` of a pixel), as before.
//!
//! [`DepthRays::Occluding`]: crate::backend::DepthRays::Occluding

use crate::values::{FrameParams, Integrator, PixelRect};

/// Pixels of the image a side per pixel of the coarse frame: the pass marches a sixteenth of
/// the rays, each only until its brick's depth ends the rays behind.
pub const COARSENESS: u32 = 4;

/// The part of the coarse rays' least depth a pixel's bound takes: what covers the difference
/// between the sums of two rays a few pixels apart, each on its own lattice, where the least
/// of the rays around the pixel does not. Every tenth of it costs work: a brick marches until
/// the bound's transmittance times its own falls to `1 - threshold`, so where the bricks in
/// front leave a transmittance T it ends at `T^-margin (1 - threshold)` instead of `(1 -
/// threshold) / T`. On the 1M dam break at 1024² the render work summed over 4 ranks was 1.30
/// of one rank's with 0.5, 1.20 with 0.7, 1.09 with 0.9 and 1.07 with 1 (`docs/distributed.md`).
pub const DEPTH_MARGIN: f64 = 0.9;

/// Whether the bricks of `frame` need the occluding pass: emission–absorption (with or
/// without shadow rays) under an opacity threshold below 1, on more than one brick.
pub fn needed(frame: &FrameParams, bricks: usize) -> bool {
    bricks > 1
        && matches!(frame.integrator, Integrator::Ea | Integrator::SsReference)
        && frame.opacity_threshold < 1.0
}

/// The coarse frame: the same camera, lattice step and shading, [`COARSENESS`] times fewer
/// pixels a side (rounded up). Its pixels' rays lie among the image's: both look along
/// `forward + sx right + sy up` over the same screen.
pub fn coarse_frame(frame: &FrameParams) -> FrameParams {
    FrameParams {
        width: frame.width.div_ceil(COARSENESS),
        height: frame.height.div_ceil(COARSENESS),
        ..frame.clone()
    }
}

/// The depth past which a coarse ray stops: where its bound ([`DEPTH_MARGIN`] of it) alone
/// reaches the opacity threshold (infinite for a threshold of 1).
pub fn stop_depth(frame: &FrameParams) -> f64 {
    -(1.0 - frame.opacity_threshold).ln() / DEPTH_MARGIN
}

/// The coarse pixels whose rays surround column (or row) `x` of an image `fine` pixels
/// across, in a coarse frame `coarse` pixels across: the two whose rays bracket the pixel's,
/// and one more on each side, those of them the coarse frame has (at its edges, the pixel's
/// ray lies beyond the last coarse ray, and the nearest three stand for it).
fn window(x: u32, fine: u32, coarse: u32) -> std::ops::RangeInclusive<u32> {
    // Pixel x's ray has s = 2 (x + 0.5) / fine - 1, coarse pixel i's 2 (i + 0.5) / coarse - 1.
    let at = (f64::from(x) + 0.5) * f64::from(coarse) / f64::from(fine) - 0.5;
    let below = at.floor() as i64;
    let last = i64::from(coarse) - 1;
    // Both ends within 0..=last (below >= -1).
    (below - 1).clamp(0, last) as u32..=(below + 2).clamp(0, last) as u32
}

/// Per pixel of `rect` (row-major) of `frame`, a bound from below of the depth in front
/// along its ray: [`DEPTH_MARGIN`] times the least, over the coarse pixels around it
/// ([`window`]), of `coarse_depth` (the scanned depth in front over `coarse_rect` of `coarse`,
/// row-major; 0 at a coarse pixel outside it, where no brick in front was met).
pub fn depth_bound(
    frame: &FrameParams,
    rect: PixelRect,
    coarse: &FrameParams,
    coarse_rect: PixelRect,
    coarse_depth: &[f64],
) -> Vec<f64> {
    assert_eq!(
        coarse_depth.len(),
        coarse_rect.len(),
        "one depth a coarse pixel"
    );
    let at = |i: u32, j: u32| -> f64 {
        if coarse_rect.contains(i, j) {
            coarse_depth[coarse_rect.index(i, j)]
        } else {
            0.0
        }
    };
    // The windows of `rect`'s columns and rows, each distinct one once (they follow the
    // pixels in order), and for each pixel which of them it takes.
    let distinct = |range: std::ops::Range<u32>, fine: u32, coarse: u32| {
        let mut windows: Vec<std::ops::RangeInclusive<u32>> = Vec::new();
        let mut of = Vec::with_capacity(range.len());
        for x in range {
            let w = window(x, fine, coarse);
            if windows.last() != Some(&w) {
                windows.push(w);
            }
            of.push(windows.len() - 1);
        }
        (windows, of)
    };
    let (columns, column_of) = distinct(rect.x0..rect.x1, frame.width, coarse.width);
    let (rows, row_of) = distinct(rect.y0..rect.y1, frame.height, coarse.height);
    let Some(first_row) = rows.first().map(|r| *r.start()) else {
        return Vec::new();
    };
    // The least over each column window, on every coarse row the row windows span; then over
    // each row window: the bound of every pixel taking that pair of windows.
    let across: Vec<Vec<f64>> = (first_row..=*rows.last().expect("not empty").end())
        .map(|j| {
            let row: Vec<f64> = columns
                .iter()
                .map(|c| c.clone().map(|i| at(i, j)).fold(f64::INFINITY, f64::min))
                .collect();
            row
        })
        .collect();
    let least: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| {
            (0..columns.len())
                .map(|k| {
                    r.clone()
                        .map(|j| across[(j - first_row) as usize][k])
                        .fold(f64::INFINITY, f64::min)
                })
                .collect()
        })
        .collect();
    let mut bound = Vec::with_capacity(rect.len());
    for &r in &row_of {
        bound.extend(column_of.iter().map(|&k| DEPTH_MARGIN * least[r][k]));
    }
    bound
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// A frame of `width` x `height` (only its size matters here).
    fn frame(width: u32, height: u32) -> FrameParams {
        let march = crate::values::Bounds {
            min: glam::DVec3::ZERO,
            max: glam::DVec3::ONE,
        };
        super::super::tests::frame(
            glam::DVec3::splat(3.0),
            glam::DVec3::ZERO,
            march,
            width,
            height,
        )
    }

    /// Each pixel's bound is at most the margin times the depth of the two coarse rays on each
    /// side of its own (the four around it), for image sizes that are and are not multiples
    /// of the coarseness, rectangles anywhere; 0 where one of those rays lies outside the
    /// coarse rectangle; and equal to the margin times a depth that is the same everywhere.
    #[test]
    fn a_pixel_s_bound_is_at_most_the_coarse_rays_around_it() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(0x0cc1);
        for (w, h) in [(64, 48), (1023, 257), (5, 3), (1, 1), (130, 4)] {
            let fine = frame(w, h);
            let coarse = coarse_frame(&fine);
            assert_eq!(
                (coarse.width, coarse.height),
                (w.div_ceil(COARSENESS), h.div_ceil(COARSENESS))
            );
            for _ in 0..4 {
                let x0 = rng.random_range(0..coarse.width);
                let y0 = rng.random_range(0..coarse.height);
                let coarse_rect = PixelRect {
                    x0,
                    y0,
                    x1: rng.random_range(x0 + 1..=coarse.width),
                    y1: rng.random_range(y0 + 1..=coarse.height),
                };
                let depth: Vec<f64> = (0..coarse_rect.len())
                    .map(|_| rng.random_range(0.0..20.0))
                    .collect();
                let fx0 = rng.random_range(0..w);
                let fy0 = rng.random_range(0..h);
                let rect = PixelRect {
                    x0: fx0,
                    y0: fy0,
                    x1: rng.random_range(fx0 + 1..=w),
                    y1: rng.random_range(fy0 + 1..=h),
                };
                let bound = depth_bound(&fine, rect, &coarse, coarse_rect, &depth);
                assert_eq!(bound.len(), rect.len());
                let coarse_at = |i: i64, j: i64| {
                    let inside = i >= i64::from(coarse_rect.x0)
                        && i < i64::from(coarse_rect.x1)
                        && j >= i64::from(coarse_rect.y0)
                        && j < i64::from(coarse_rect.y1);
                    inside.then(|| depth[coarse_rect.index(i as u32, j as u32)])
                };
                for (x, y) in rect.pixels() {
                    let b = bound[rect.index(x, y)];
                    // The coarse coordinates of the pixel's ray, and the four rays around it.
                    let cx = (f64::from(x) + 0.5) * f64::from(coarse.width) / f64::from(w) - 0.5;
                    let cy = (f64::from(y) + 0.5) * f64::from(coarse.height) / f64::from(h) - 0.5;
                    let last = (i64::from(coarse.width) - 1, i64::from(coarse.height) - 1);
                    let around = |c: f64, last: i64| {
                        [c.floor() as i64, c.floor() as i64 + 1].map(|k| k.clamp(0, last))
                    };
                    for i in around(cx, last.0) {
                        for j in around(cy, last.1) {
                            match coarse_at(i, j) {
                                Some(d) => assert!(b <= DEPTH_MARGIN * d, "{x},{y}: {b} > {d}"),
                                None => assert_eq!(b, 0.0, "{x},{y}: ray ({i},{j}) met none"),
                            }
                        }
                    }
                }
            }
            // The same depth everywhere: every bound is the margin of it.
            let all = PixelRect::full(coarse.width, coarse.height);
            let bound = depth_bound(
                &fine,
                PixelRect::full(w, h),
                &coarse,
                all,
                &vec![8.0; all.len()],
            );
            assert!(bound.iter().all(|&b| b == DEPTH_MARGIN * 8.0), "{w}x{h}");
        }
    }

    /// An opaque disc in front: pixels well inside it get its depth's margin, pixels a few
    /// coarse pixels outside get 0, and no pixel outside the disc gets any.
    #[test]
    fn the_bound_follows_an_occluder_s_outline_conservatively() {
        let fine = frame(96, 64);
        let coarse = coarse_frame(&fine);
        let all = PixelRect::full(coarse.width, coarse.height);
        let centre = [12.0, 8.0];
        let inside = |x: f64, y: f64| (x - centre[0]).hypot(y - centre[1]) < 7.0;
        let depth: Vec<f64> = all
            .pixels()
            .map(|(i, j)| {
                if inside(f64::from(i) + 0.5, f64::from(j) + 0.5) {
                    30.0
                } else {
                    0.0
                }
            })
            .collect();
        let rect = PixelRect::full(96, 64);
        let bound = depth_bound(&fine, rect, &coarse, all, &depth);
        let (mut covered, mut clear) = (0, 0);
        for (x, y) in rect.pixels() {
            let b = bound[rect.index(x, y)];
            // The pixel's place in coarse pixel units.
            let (u, v) = (
                (f64::from(x) + 0.5) / f64::from(COARSENESS),
                (f64::from(y) + 0.5) / f64::from(COARSENESS),
            );
            let r = (u - centre[0]).hypot(v - centre[1]);
            if r >= 7.0 {
                assert_eq!(b, 0.0, "{x},{y} outside the disc");
            }
            if r < 3.0 {
                assert_eq!(b, DEPTH_MARGIN * 30.0, "{x},{y} well inside");
                covered += 1;
            }
            if b == 0.0 {
                clear += 1;
            }
        }
        assert!(covered > 300 && clear > 2500, "{covered} {clear}");
    }

    #[test]
    fn the_pass_serves_emission_absorption_under_a_threshold_on_several_bricks() {
        let mut f = frame(8, 8);
        f.integrator = Integrator::Ea;
        f.opacity_threshold = 0.99;
        assert!(needed(&f, 2) && !needed(&f, 1));
        assert!((stop_depth(&f) - 100f64.ln() / DEPTH_MARGIN).abs() < 1e-12);
        f.integrator = Integrator::SsReference;
        assert!(needed(&f, 4));
        for i in [Integrator::Marching, Integrator::Delta] {
            f.integrator = i;
            assert!(!needed(&f, 4));
        }
        f.integrator = Integrator::Ea;
        f.opacity_threshold = 1.0;
        assert!(!needed(&f, 4));
        assert_eq!(stop_depth(&f), f64::INFINITY);
    }
}
