//! A brick's share of a distributed frame, and what the bricks before it tell it: the optical
//! depth in front of it along each primary ray (stochastic marching's free flight) and, through
//! a light map, along the light (shadows). Each brick renders only the samples its half-open
//! box holds; these values carry what the other bricks' samples decide.
//!
//! The light map is an orthographic grid of M² rays along a directional light over the march
//! box. A brick marches each texel's ray through its own box ([`DepthRays::Light`]); an
//! exclusive scan over the bricks in their order from the light gives each brick, per texel,
//! the optical depth of the bricks nearer the light ([`LightPrefix`]). A shadow ray from `x`
//! is then marched to its own brick's exit and adds the prefix at `x`, bilinear across the
//! light's rays: exact along the light, an interpolation across it.

use glam::DVec3;

use crate::values::{Bounds, FrameParams, HalfOpenBox, Integrator, PixelRect};

/// The rays of an orthographic light map: `size`² texels over the projection of a box onto the
/// plane across the light, each a ray towards the light that starts behind the box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightMap {
    /// Unit direction towards the light (the frame's `light_dir`).
    pub toward_light: DVec3,
    /// Unit axes across the light: texel columns along `u`, rows along `v`.
    pub u: DVec3,
    /// See [`LightMap::u`].
    pub v: DVec3,
    /// The box's centre, where the map's axes meet.
    pub centre: DVec3,
    /// The map's least `(u, v)` coordinate relative to `centre`.
    pub origin: [f64; 2],
    /// A texel's width along `u` and `v`.
    pub texel: [f64; 2],
    /// Texels along each side.
    pub size: u32,
    /// How far behind the centre (away from the light) the texel rays start: outside the box.
    pub behind: f64,
}

impl LightMap {
    /// The map of `size`² texels covering `march_box` seen along `toward_light`.
    pub fn new(toward_light: DVec3, march_box: Bounds, size: u32) -> LightMap {
        let toward_light = toward_light.normalize();
        let (u, v) = toward_light.any_orthonormal_pair();
        let centre = march_box.center();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for corner in corners(march_box) {
            let d = corner - centre;
            for (axis, a) in [d.dot(u), d.dot(v)].into_iter().enumerate() {
                lo[axis] = lo[axis].min(a);
                hi[axis] = hi[axis].max(a);
            }
        }
        let size = size.max(1);
        let texel = [0, 1].map(|a| ((hi[a] - lo[a]) / f64::from(size)).max(f64::MIN_POSITIVE));
        LightMap {
            toward_light,
            u,
            v,
            centre,
            origin: lo,
            texel,
            size,
            behind: (march_box.max - march_box.min).length() + 1.0,
        }
    }

    /// All the map's texels.
    pub fn full(&self) -> PixelRect {
        PixelRect::full(self.size, self.size)
    }

    /// Texel `(i, j)`'s ray: its origin, behind the box, and the direction towards the light.
    pub fn texel_ray(&self, i: u32, j: u32) -> (DVec3, DVec3) {
        let a = self.origin[0] + (f64::from(i) + 0.5) * self.texel[0];
        let b = self.origin[1] + (f64::from(j) + 0.5) * self.texel[1];
        let origin = self.centre + self.u * a + self.v * b - self.toward_light * self.behind;
        (origin, self.toward_light)
    }

    /// `x` in texel coordinates: texel `(i, j)`'s ray passes through `(i, j)` exactly.
    pub fn texel_coordinates(&self, x: DVec3) -> [f64; 2] {
        let d = x - self.centre;
        [
            (d.dot(self.u) - self.origin[0]) / self.texel[0] - 0.5,
            (d.dot(self.v) - self.origin[1]) / self.texel[1] - 0.5,
        ]
    }

    /// The texels whose rays can meet `b`, and one more on every side (what a bilinear lookup
    /// at a point of `b` reads), within the map.
    pub fn texels_near(&self, b: Bounds) -> PixelRect {
        if b.is_empty() {
            return PixelRect::default();
        }
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for corner in corners(b) {
            let t = self.texel_coordinates(corner);
            for a in 0..2 {
                lo[a] = lo[a].min(t[a]);
                hi[a] = hi[a].max(t[a]);
            }
        }
        let n = f64::from(self.size);
        let first = |t: f64| (t.floor() - 1.0).clamp(0.0, n) as u32;
        let end = |t: f64| (t.ceil() + 2.0).clamp(0.0, n) as u32;
        PixelRect {
            x0: first(lo[0]),
            y0: first(lo[1]),
            x1: end(hi[0]),
            y1: end(hi[1]),
        }
        .intersection(&self.full())
    }
}

/// The eight corners of a box.
fn corners(b: Bounds) -> impl Iterator<Item = DVec3> {
    (0..8).map(move |c| {
        DVec3::new(
            if c & 1 == 0 { b.min.x } else { b.max.x },
            if c & 2 == 0 { b.min.y } else { b.max.y },
            if c & 4 == 0 { b.min.z } else { b.max.z },
        )
    })
}

/// A brick's lookup of the optical depth nearer the light than itself: the light map's depth
/// summed over the bricks before it in the order from the light, over the texels `rect`.
#[derive(Clone, Debug, PartialEq)]
pub struct LightPrefix {
    /// The map the depths are of.
    pub map: LightMap,
    /// The texels held, row-major in `depth`.
    pub rect: PixelRect,
    /// Per texel of `rect`, the optical depth of the bricks nearer the light.
    pub depth: Vec<f64>,
}

impl LightPrefix {
    /// The optical depth nearer the light than the brick at `x`: bilinear between the four
    /// texels around it (clamped to the rectangle held; 0 where nothing is held).
    pub fn depth_at(&self, x: DVec3) -> f64 {
        if self.rect.is_empty() {
            return 0.0;
        }
        let t = self.map.texel_coordinates(x);
        let axis = |t: f64, first: u32, end: u32| -> (u32, u32, f64) {
            let (first, last) = (f64::from(first), f64::from(end - 1));
            let t = t.clamp(first, last);
            let i0 = t.floor().min(last);
            let i1 = (i0 + 1.0).min(last);
            (i0 as u32, i1 as u32, t - i0)
        };
        let (i0, i1, fu) = axis(t[0], self.rect.x0, self.rect.x1);
        let (j0, j1, fv) = axis(t[1], self.rect.y0, self.rect.y1);
        let at = |i, j| self.depth[self.rect.index(i, j)];
        let below = at(i0, j0) * (1.0 - fu) + at(i1, j0) * fu;
        let above = at(i0, j1) * (1.0 - fu) + at(i1, j1) * fu;
        below * (1.0 - fv) + above * fv
    }
}

/// The rays a brick sums its optical depth along ([`crate::backend::Backend::owned_depth`]).
#[derive(Clone, Copy, Debug)]
pub enum DepthRays<'a> {
    /// The frame's primary rays of these pixels, on stochastic marching's lattice and noise,
    /// each stopped once past its free-flight depth `-ln(1 - xi)` (a larger depth decides
    /// nothing more: the ray has scattered in this brick or before it).
    Primary(PixelRect),
    /// The frame's primary rays of these pixels on emission–absorption's lattice (jitter
    /// dimension 0), each stopped once past `stop_past`: the depth in front of a brick past
    /// which every ray behind it is ended by the opacity threshold, so that a larger depth
    /// decides nothing more. Distributed emission–absorption marches these on a coarse frame
    /// to end the rays of the bricks behind opaque ones.
    Occluding {
        /// The pixels.
        rect: PixelRect,
        /// The depth past which a ray stops.
        stop_past: f64,
    },
    /// The light map's rays of these texels, on the frame's step, marched whole.
    Light(&'a LightMap, PixelRect),
}

impl DepthRays<'_> {
    /// The pixels (texels) whose rays these are.
    pub fn rect(&self) -> PixelRect {
        match *self {
            DepthRays::Primary(rect) | DepthRays::Occluding { rect, .. } => rect,
            DepthRays::Light(_, rect) => rect,
        }
    }
}

/// A brick's share of a distributed frame: the samples its box holds, for the pixels its box
/// can touch, with what the bricks before it decided.
#[derive(Clone, Copy, Debug)]
pub struct BrickShare<'a> {
    /// The samples it owns.
    pub owned: &'a HalfOpenBox,
    /// The pixels it renders, row-major in the result.
    pub rect: PixelRect,
    /// The brick's index: delta tracking draws its numbers per brick (a free flight is
    /// memoryless, so each brick tracks its own segment with independent numbers; brick 0
    /// draws the single rank's).
    pub index: u32,
    /// Per pixel of `rect`, the optical depth of the bricks a primary ray meets before this
    /// one. Stochastic marching: that depth (the exclusive scan of [`DepthRays::Primary`]),
    /// which the ray goes on from. Emission–absorption: at most that depth (from
    /// [`DepthRays::Occluding`] on a coarse frame), so that `exp(-depth)` bounds the
    /// transmittance in front from above: a ray ends where that bound times its own
    /// transmittance falls to `1 - threshold` (never before the single rank's ray would end),
    /// and is not marched at all where the bricks in front reach the threshold.
    pub depth_in_front: Option<&'a [f64]>,
    /// Shadows across bricks: the depth nearer the light. `None`: a shadow ray sees only its
    /// own brick (`--dist-shadows local`).
    pub light: Option<&'a LightPrefix>,
}

impl BrickShare<'_> {
    /// The frame this brick renders, where it is not `frame` itself: delta tracking draws each
    /// brick's numbers from its own seed (brick 0 the frame's), since bricks track their
    /// segments independently; every other integrator uses the frame's numbers, which make
    /// the single rank's decisions. Every backend renders a share with it.
    pub fn own_frame(&self, frame: &FrameParams) -> Option<FrameParams> {
        (frame.integrator == Integrator::Delta && self.index > 0).then(|| FrameParams {
            seed: frame.seed ^ self.index.wrapping_mul(0x9E37_79B9),
            ..frame.clone()
        })
    }

    /// The depth in front of this brick along pixel `(x, y)`'s primary ray (0 when not given).
    pub fn depth_in_front(&self, x: u32, y: u32) -> f64 {
        self.depth_in_front
            .map_or(0.0, |d| d[self.rect.index(x, y)])
    }

    /// The depth nearer the light than this brick at `x` (0 for local shadows).
    pub fn light_depth_at(&self, x: DVec3) -> f64 {
        self.light.map_or(0.0, |l| l.depth_at(x))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box() -> Bounds {
        Bounds {
            min: DVec3::new(-1.0, -0.5, 0.0),
            max: DVec3::new(2.0, 1.5, 1.0),
        }
    }

    #[test]
    fn texel_rays_cross_the_box_and_pass_through_their_texel_coordinates() {
        let b = unit_box();
        for dir in [
            DVec3::new(0.3, 0.8, -0.5),
            DVec3::Z,
            DVec3::new(-1.0, 0.0, 0.0),
        ] {
            let map = LightMap::new(dir, b, 17);
            let full = map.texels_near(b);
            assert_eq!(full, map.full(), "the box's texels are the whole map");
            for (i, j) in [(0, 0), (8, 3), (16, 16)] {
                let (o, d) = map.texel_ray(i, j);
                assert!((d - dir.normalize()).length() < 1e-15);
                let inside = o.cmpge(b.min).all() && o.cmple(b.max).all();
                assert!(!inside, "rays start outside the box");
                for t in [0.0, 1.0, 7.5] {
                    let c = map.texel_coordinates(o + d * t);
                    assert!(
                        (c[0] - f64::from(i)).abs() < 1e-9 && (c[1] - f64::from(j)).abs() < 1e-9
                    );
                }
            }
            // The centre's ray meets the box.
            let (o, d) = map.texel_ray(8, 8);
            let mid = o + d * map.behind;
            assert!((mid - b.center()).length() < 0.5 * b.diagonal());
        }
    }

    #[test]
    fn bilinear_lookup_is_exact_on_texels_and_linear_between() {
        let map = LightMap::new(DVec3::new(0.2, -0.3, 1.0), unit_box(), 9);
        let rect = PixelRect {
            x0: 2,
            y0: 3,
            x1: 7,
            y1: 6,
        };
        // A plane in texel coordinates: bilinear lookup reproduces it exactly inside.
        let plane = |i: f64, j: f64| 0.5 + 2.0 * i - 0.25 * j;
        let mut depth = vec![0.0; rect.len()];
        for j in rect.y0..rect.y1 {
            for i in rect.x0..rect.x1 {
                depth[rect.index(i, j)] = plane(f64::from(i), f64::from(j));
            }
        }
        let prefix = LightPrefix { map, rect, depth };
        let point_at = |i: f64, j: f64| {
            let (o, _) = map.texel_ray(0, 0);
            o + map.u * (i * map.texel[0]) + map.v * (j * map.texel[1]) + map.toward_light * 3.0
        };
        for (i, j) in [(2.0, 3.0), (4.25, 4.5), (6.0, 5.0), (5.9, 3.1)] {
            let got = prefix.depth_at(point_at(i, j));
            assert!((got - plane(i, j)).abs() < 1e-9, "{got} at ({i}, {j})");
        }
        // Outside, clamped to the nearest held texel.
        assert!((prefix.depth_at(point_at(0.0, 4.0)) - plane(2.0, 4.0)).abs() < 1e-9);
        assert!((prefix.depth_at(point_at(6.0, 9.0)) - plane(6.0, 5.0)).abs() < 1e-9);
    }

    #[test]
    fn a_brick_s_texels_hold_every_texel_whose_ray_meets_it() {
        let b = unit_box();
        let map = LightMap::new(DVec3::new(0.5, 0.4, 0.7), b, 40);
        let brick = Bounds {
            min: DVec3::new(0.0, 0.0, 0.25),
            max: DVec3::new(0.75, 0.5, 0.6),
        };
        let near = map.texels_near(brick);
        assert!(near.len() < map.full().len() / 2, "{near:?}");
        for j in 0..40 {
            for i in 0..40 {
                let (o, d) = map.texel_ray(i, j);
                let inv = d.recip();
                let t1 = (brick.min - o) * inv;
                let t2 = (brick.max - o) * inv;
                let meets = t1.min(t2).max_element() < t1.max(t2).min_element();
                assert!(!meets || near.contains(i, j), "texel ({i}, {j})");
            }
        }
    }
}
