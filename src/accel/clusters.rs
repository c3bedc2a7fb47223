//! Clusters of K consecutive (Hilbert-sorted) particles and their bounding boxes (paper §3.2.3).

use std::fmt;
use std::str::FromStr;

use glam::DVec3;
use num_traits::Float;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::values::Bounds;

/// The mean overlap from which [`ClusterSize::for_overlap`] picks K = 16.
pub const DENSE_OVERLAP: f64 = 4.0;

/// Particles per cluster: 1, 2, 4, 8 or 16.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "u32", into = "u32")]
pub struct ClusterSize(u32);

impl ClusterSize {
    /// Every allowed cluster size, smallest first.
    pub const ALL: [ClusterSize; 5] = [
        ClusterSize(1),
        ClusterSize(2),
        ClusterSize(4),
        ClusterSize(8),
        ClusterSize(16),
    ];

    /// The cluster size `k`; an error message when `k` is not 1, 2, 4, 8 or 16.
    pub fn new(k: u32) -> Result<ClusterSize, String> {
        if matches!(k, 1 | 2 | 4 | 8 | 16) {
            Ok(ClusterSize(k))
        } else {
            Err(format!("cluster size {k} is not one of 1, 2, 4, 8, 16"))
        }
    }

    /// The cluster size for data where `overlap` particles reach a particle centre on average
    /// (itself included; [`crate::render::auto::mean_overlap`]): 16 where particles overlap
    /// ([`DENSE_OVERLAP`] or more), 4 where they barely do. Measured with `aarbf bench cluster`
    /// on every backend (docs/notes/2026-12-02-cluster-size-from-data.md): where several
    /// particles reach a point, larger clusters only gain (a query visits fewer, fuller boxes;
    /// K = 16 was the fastest or close to it on uniform data, on clustered data and on the dam
    /// break); where a point meets about one particle, the best K depends on how small the
    /// particles are against their spacing, which the overlap does not see, and K = 4 was
    /// close to the fastest on every backend in both cases, where K = 16 was not.
    pub fn for_overlap(overlap: f64) -> ClusterSize {
        if overlap >= DENSE_OVERLAP {
            ClusterSize(16)
        } else {
            ClusterSize(4)
        }
    }

    /// K, the number of particles per cluster.
    pub fn get(self) -> usize {
        self.0 as usize
    }

    /// Clusters needed for `n` particles.
    pub fn clusters_for(self, n: usize) -> usize {
        n.div_ceil(self.get())
    }
}

impl Default for ClusterSize {
    fn default() -> Self {
        ClusterSize(1)
    }
}

impl TryFrom<u32> for ClusterSize {
    type Error = String;
    fn try_from(k: u32) -> Result<Self, String> {
        ClusterSize::new(k)
    }
}

impl From<ClusterSize> for u32 {
    fn from(k: ClusterSize) -> u32 {
        k.0
    }
}

impl FromStr for ClusterSize {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let k = s
            .parse::<u32>()
            .map_err(|_| format!("cluster size '{s}' is not a number"))?;
        ClusterSize::new(k)
    }
}

impl fmt::Display for ClusterSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// The largest f32 not above `x`.
pub fn f32_down(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) > x { f.next_down() } else { f }
}

/// The smallest f32 not below `x`.
pub fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x { f.next_up() } else { f }
}

/// The cluster-box rule (paper §3.2.3), written once for every precision: the union of
/// `[c - r - pad, c + r + pad]` over the members (centre, radius) with `r > 0`, where
/// `pad = max(|c|, r) · 4ε` is four ulp of the coordinates in that precision, so the box holds
/// every point a sphere test in that precision accepts (`shader_constants::BOX_PAD` says why
/// four); `None` when no member has `r > 0` (an empty cluster). At f32 it is the CPU twin of
/// `shaders_glsl/shared/cluster_box.glsl` (same operations in the same order); the f64
/// reference uses it at f64.
pub fn cluster_box<F: Float>(
    members: impl IntoIterator<Item = ([F; 3], F)>,
) -> Option<[[F; 3]; 2]> {
    let pad = F::epsilon() * F::from(4.0).expect("4 fits any float");
    let mut out: Option<[[F; 3]; 2]> = None;
    for (c, r) in members {
        // Radius 0 (or NaN) leaves the member out.
        if r.partial_cmp(&F::zero()) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let a: [F; 3] = std::array::from_fn(|i| c[i] - r - c[i].abs().max(r) * pad);
        let b: [F; 3] = std::array::from_fn(|i| c[i] + r + c[i].abs().max(r) * pad);
        out = Some(match out {
            None => [a, b],
            Some([lo, hi]) => [
                std::array::from_fn(|i| lo[i].min(a[i])),
                std::array::from_fn(|i| hi[i].max(b[i])),
            ],
        });
    }
    out
}

/// One box per cluster of K consecutive particles by [`cluster_box`], in f64 (a cluster with no
/// member left is empty, `Bounds::is_empty`).
#[derive(Clone, Debug, PartialEq)]
pub struct ClusterBoxes {
    /// Particles per cluster (K): box `c` bounds particles `cK .. cK+K` in cluster order.
    pub size: ClusterSize,
    /// One box per cluster, in cluster order (`Bounds::EMPTY` where no member has a positive
    /// radius).
    pub boxes: Vec<Bounds>,
}

impl ClusterBoxes {
    /// Boxes for particles `centers` (already in cluster order) with `radii`.
    pub fn build(centers: &[DVec3], radii: &[f64], size: ClusterSize) -> ClusterBoxes {
        assert_eq!(centers.len(), radii.len());
        let k = size.get();
        let boxes = centers
            .par_chunks(k)
            .zip(radii.par_chunks(k))
            .map(
                |(c, r)| match cluster_box(c.iter().zip(r).map(|(c, &r)| (c.to_array(), r))) {
                    None => Bounds::EMPTY,
                    Some([lo, hi]) => Bounds {
                        min: DVec3::from_array(lo),
                        max: DVec3::from_array(hi),
                    },
                },
            )
            .collect();
        ClusterBoxes { size, boxes }
    }

    /// The number of clusters (boxes, empty ones included).
    pub fn len(&self) -> usize {
        self.boxes.len()
    }

    /// Whether there are no clusters at all (no particles).
    pub fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// Boxes that bound at least one particle.
    pub fn non_empty(&self) -> usize {
        self.boxes.iter().filter(|b| !b.is_empty()).count()
    }

    /// The particle indices (in cluster order) of cluster `c`, for `n` particles in all.
    pub fn members(&self, c: usize, n: usize) -> std::ops::Range<usize> {
        let k = self.size.get();
        c * k..((c + 1) * k).min(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cluster_size_grows_with_the_overlap() {
        let k = |n: f64| ClusterSize::for_overlap(n).get();
        assert_eq!(k(1.0), 4);
        assert_eq!(k(DENSE_OVERLAP - 1e-9), 4);
        assert_eq!(k(DENSE_OVERLAP), 16);
        assert_eq!(k(1e4), 16);
        assert_eq!(k(f64::NAN), 4);
    }

    #[test]
    fn outward_rounding_contains_the_f64_value() {
        for x in [0.1f64, -0.1, 1e6 + 0.3, -3.0, 1e-30, 0.0] {
            assert!(
                f64::from(f32_down(x)) <= x && f64::from(f32_up(x)) >= x,
                "{x}"
            );
        }
        assert_eq!(f32_down(0.5), 0.5);
        assert_eq!(f32_up(0.5), 0.5);
    }

    #[test]
    fn boxes_bound_members_skip_zero_radii_and_mark_empty_clusters() {
        let c = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z, DVec3::ONE];
        let r = [0.5, 0.0, 0.0, 0.0, 0.25];
        let b = ClusterBoxes::build(&c, &r, ClusterSize::new(2).unwrap());
        assert_eq!(b.len(), 3);
        let pad = 0.5 * 4.0 * f64::EPSILON;
        assert_eq!(b.boxes[0].min, DVec3::splat(-0.5 - pad));
        assert_eq!(
            b.boxes[0].max,
            DVec3::splat(0.5 + pad),
            "the zero-radius member adds nothing"
        );
        assert!(b.boxes[1].is_empty());
        assert!(b.boxes[2].min.cmple(DVec3::splat(0.75)).all());
        assert_eq!(b.non_empty(), 2);
        assert_eq!(b.members(2, 5), 4..5);
        assert!(ClusterSize::new(3).is_err());
    }
}
