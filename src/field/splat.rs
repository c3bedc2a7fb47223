//! The hits of Knoll et al.'s RT splatter (the paper's Table 3 baseline, method.md §7), collected
//! through the reference field's BVH: the ray is cut into slabs of a fixed length; in each slab
//! the particles whose sphere the ray crosses with their point of closest approach inside the
//! slab are gathered into a buffer of at most `k` entries, in traversal order; a candidate met
//! when the buffer is full is *accepted* as the RT pipeline's any-hit does (the ray's `t_max`
//! shrinks to it, culling every farther candidate of the slab), so overflow loses particles by
//! design. The renderer (`backend::cpu::splat`) sorts each slab's buffer by distance and
//! composites it front to back.
//!
//! What a hit carries is the particle alone at its closest approach: its term
//! `phi_i = w_i exp(-4.5 b² / r²)` at distance `b` from the centre, its Theta numerator, and the
//! length over which its Gaussian acts along the ray,
//! `∫ exp(-4.5 s² / r²) ds` over the chord, `= (r / 3) √(2π) erf(3h / (√2 r))` with half-chord
//! `h = √(r² - b²)`. For an optical map linear in Phi, `sigma(phi_i) · length` is exactly the
//! particle's optical depth along the ray, so the splatter's transmittance is exact and its
//! error is ordering (particles composited one after another instead of mixed where they
//! overlap), colour (each particle's own, not the Phi-weighted mean) and overflow.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::DVec3;

use super::{ReferenceField, Theta};

/// One particle a splatting ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplatHit {
    /// Distance along the ray to the point of closest approach to the centre.
    pub t: f64,
    /// The particle's term at its closest approach.
    pub phi: f64,
    /// Its Theta numerator there (theta_i · phi).
    pub num: [f64; 3],
    /// The length over which its Gaussian acts along the ray (the chord's integral of the
    /// profile, relative to its value at closest approach).
    pub length: f64,
}

/// Counts of what the slabs' buffers kept and lost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SplatCounts {
    /// Hits composited (or left behind the opacity threshold's stop).
    pub kept: u64,
    /// Hits lost to full buffers.
    pub lost: u64,
}

impl std::ops::Add for SplatCounts {
    type Output = SplatCounts;

    fn add(self, o: SplatCounts) -> SplatCounts {
        SplatCounts {
            kept: self.kept + o.kept,
            lost: self.lost + o.lost,
        }
    }
}

impl SplatCounts {
    /// The fraction of the hits met that full buffers lost.
    pub fn lost_fraction(&self) -> f64 {
        let met = self.kept + self.lost;
        if met == 0 {
            0.0
        } else {
            self.lost as f64 / met as f64
        }
    }
}

/// What collecting a ray's hits keeps between rays (made once per thread).
#[derive(Default)]
pub struct SplatScratch {
    boxes: Vec<(f64, f64, u32)>,
    /// Candidates not yet composited: (slab, traversal order, index into `candidates`).
    pending: BinaryHeap<Reverse<(u64, u64, usize)>>,
    candidates: Vec<SplatHit>,
    slab: Vec<SplatHit>,
}

/// `erf(x)` (libm's, accurate to an ulp or so).
fn erf(x: f64) -> f64 {
    libm::erf(x)
}

/// `∫ exp(-4.5 s² / r²) ds` over the chord of a sphere of radius `r` at distance `b` from its
/// centre.
pub fn chord_length(r: f64, b2: f64) -> f64 {
    let h = (r * r - b2).max(0.0).sqrt();
    r / 3.0 * (2.0 * std::f64::consts::PI).sqrt() * erf(3.0 * h / (std::f64::consts::SQRT_2 * r))
}

impl ReferenceField {
    /// Collects the splatter's hits along `origin + t dir` (`dir` a unit vector, data
    /// coordinates) over `[t0, t1]`, slabs `[t0 + j slab, t0 + (j + 1) slab)`, at most `k` per
    /// slab; calls `composite` with each slab's buffer sorted by distance, nearest slab first,
    /// until it returns false. Slabs without hits are skipped.
    #[allow(clippy::too_many_arguments)]
    pub fn splat_ray(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        slab: f64,
        k: usize,
        scratch: &mut SplatScratch,
        mut composite: impl FnMut(&[SplatHit]) -> bool,
    ) -> SplatCounts {
        let mut counts = SplatCounts::default();
        if slab.is_nan() || slab <= 0.0 || k == 0 || t0.is_nan() || t1.is_nan() || t0 >= t1 {
            return counts;
        }
        let local = origin - self.particles.origin;
        let SplatScratch {
            boxes,
            pending,
            candidates,
            slab: buffer,
        } = scratch;
        boxes.clear();
        pending.clear();
        candidates.clear();
        // The boxes in order of entry: the near-first traversal's order, which is the order an
        // RT traversal of one slab meets them in (closely; the loss rule below is the same).
        self.bvh().ray_boxes(local, dir, t0, t1, boxes);
        boxes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let slab_of = |t: f64| ((t - t0) / slab).floor() as u64;
        let n = self.particles.len();
        let mut next_box = 0;
        let mut order = 0u64;
        loop {
            // The next slab with a hit: the nearest pending one, or the slab where the next
            // box begins (its particles' closest approaches lie at or after its entry).
            let from_boxes = boxes.get(next_box).map(|b| slab_of(b.0));
            let from_pending = pending.peek().map(|Reverse((s, ..))| *s);
            let current = match (from_pending, from_boxes) {
                (Some(a), Some(b)) => a.min(b),
                (Some(a), None) | (None, Some(a)) => a,
                (None, None) => break,
            };
            let lo = t0 + current as f64 * slab;
            let hi = (lo + slab).min(t1);
            // Every box entered before the slab ends may hold one of its hits.
            while let Some(&(t_in, _, cluster)) = boxes.get(next_box) {
                if t_in >= hi {
                    break;
                }
                next_box += 1;
                for i in self.boxes().members(cluster as usize, n) {
                    let r = self.particles.radii[i];
                    if r <= 0.0 {
                        continue;
                    }
                    let oc = self.particles.centers[i] - local;
                    let t = oc.dot(dir);
                    let b2 = (oc - dir * t).length_squared();
                    if b2 > r * r || t < t0 || t >= t1 {
                        continue;
                    }
                    let phi = self.particles.weights[i] * (-4.5 * b2 / (r * r)).exp();
                    let num = match &self.particles.theta {
                        Theta::None => [0.0; 3],
                        Theta::Scalar(s) => [s[i] * phi, 0.0, 0.0],
                        Theta::Rgb(c) => c[i].map(|c| c * phi),
                    };
                    pending.push(Reverse((slab_of(t), order, candidates.len())));
                    order += 1;
                    candidates.push(SplatHit {
                        t,
                        phi,
                        num,
                        length: chord_length(r, b2),
                    });
                }
            }
            // The slab's buffer, filled in traversal order; once full, a candidate nearer than
            // the ray's current end is accepted (lost, and the end moves to it), a farther one
            // culled (lost too).
            buffer.clear();
            let mut t_max = hi;
            while let Some(&Reverse((s, _, c))) = pending.peek() {
                if s != current {
                    break;
                }
                pending.pop();
                let hit = candidates[c];
                if buffer.len() < k && hit.t < t_max {
                    buffer.push(hit);
                } else {
                    counts.lost += 1;
                    t_max = t_max.min(hit.t);
                }
            }
            counts.kept += buffer.len() as u64;
            buffer.sort_by(|a, b| a.t.total_cmp(&b.t));
            if !buffer.is_empty() && !composite(buffer) {
                break;
            }
        }
        counts
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::ClusterSize;
    use crate::field::FieldSettings;
    use crate::values::{Attribute, Bounds, Step};

    /// [`ReferenceField::splat_ray`] along +x from `(x0, 0, 0)` over t in `[0, t1]`, slabs 1
    /// long, at most `k` hits a slab.
    fn along_x(
        field: &ReferenceField,
        x0: f64,
        t1: f64,
        k: usize,
        scratch: &mut SplatScratch,
        composite: impl FnMut(&[SplatHit]) -> bool,
    ) -> SplatCounts {
        let origin = DVec3::new(x0, 0.0, 0.0);
        field.splat_ray(origin, DVec3::X, 0.0, t1, 1.0, k, scratch, composite)
    }

    fn field_of(centers: Vec<DVec3>, radius: f64, k: u32) -> ReferenceField {
        let n = centers.len();
        let step = Step {
            name: "splat test".into(),
            positions: centers,
            attributes: vec![Attribute {
                name: "a".into(),
                values: (0..n).map(|i| i as f64).collect(),
            }],
        };
        let settings = FieldSettings::new(Some("a"), radius);
        let bounds = Bounds::of_points(&step.positions);
        ReferenceField::of_step(&step, &settings, ClusterSize::new(k).unwrap(), bounds, None)
            .unwrap()
    }

    #[test]
    fn the_chord_length_is_the_profiles_integral() {
        for (r, b) in [(1.0f64, 0.0f64), (0.37, 0.2), (2e-6, 1.9e-6), (5.0, 4.999)] {
            let h = ((r * r) - b * b).sqrt();
            let n = 20_000;
            let ds = 2.0 * h / n as f64;
            let simpson: f64 = (0..n)
                .map(|j| {
                    let s = -h + (j as f64 + 0.5) * ds;
                    (-4.5 * s * s / (r * r)).exp() * ds
                })
                .sum();
            let got = chord_length(r, b * b);
            assert!(
                (got - simpson).abs() <= 1e-6 * simpson.max(1e-300),
                "r {r} b {b}: {got} vs {simpson}"
            );
        }
        assert_eq!(chord_length(1.0, 1.0), 0.0);
    }

    #[test]
    fn hits_come_slab_by_slab_nearest_first_with_their_closest_approach() {
        // Particles on the x axis, off it by 0.1 in y, radius 0.5: the ray along x meets each.
        let xs = [0.35, 3.2, 1.1, 1.3, 0.2, 2.05];
        let centers: Vec<DVec3> = xs.iter().map(|&x| DVec3::new(x, 0.1, 0.0)).collect();
        let field = field_of(centers, 0.5, 2);
        let mut scratch = SplatScratch::default();
        let mut slabs = Vec::new();
        let mut phis = Vec::new();
        let counts = along_x(&field, -1.0, 10.0, 8, &mut scratch, |hits| {
            slabs.push(hits.iter().map(|h| h.t).collect::<Vec<_>>());
            phis.extend(hits.iter().map(|h| (h.phi, h.length)));
            true
        });
        let close = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
        };
        let want = [vec![1.2, 1.35], vec![2.1, 2.3], vec![3.05], vec![4.2]];
        assert_eq!(slabs.len(), want.len(), "{slabs:?}");
        for (got, want) in slabs.iter().zip(&want) {
            assert!(close(got, want), "{slabs:?}");
        }
        assert_eq!(counts, SplatCounts { kept: 6, lost: 0 });
        let expected_phi = (-4.5f64 * 0.01 / 0.25).exp();
        assert_eq!(phis.len(), 6);
        for (phi, length) in phis {
            assert!((phi - expected_phi).abs() < 1e-12);
            assert!((length - chord_length(0.5, 0.01)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_full_buffer_loses_hits_and_compositing_can_stop_early() {
        // Ten particles in one slab, a buffer of 3: three kept, seven lost.
        let centers: Vec<DVec3> = (0..10)
            .map(|i| DVec3::new(0.5 + 0.01 * i as f64, 0.0, 0.0))
            .collect();
        let field = field_of(centers.clone(), 0.3, 1);
        let mut scratch = SplatScratch::default();
        let mut seen = 0;
        let counts = along_x(&field, 0.0, 2.0, 3, &mut scratch, |hits| {
            seen += hits.len();
            assert!(hits.windows(2).all(|w| w[0].t <= w[1].t));
            true
        });
        assert_eq!((seen, counts), (3, SplatCounts { kept: 3, lost: 7 }));
        assert!((counts.lost_fraction() - 0.7).abs() < 1e-12);
        // A buffer as large as the slab's hits keeps them all.
        let counts = along_x(&field, 0.0, 2.0, 10, &mut scratch, |_| true);
        assert_eq!(counts, SplatCounts { kept: 10, lost: 0 });
        // Particles in two slabs; compositing stops after the first.
        let mut two = centers;
        two.push(DVec3::new(1.6, 0.0, 0.0));
        let field = field_of(two, 0.3, 4);
        let mut calls = 0;
        along_x(&field, 0.0, 2.0, 16, &mut scratch, |_| {
            calls += 1;
            false
        });
        assert_eq!(calls, 1);
    }
}
