//! The CPU twin of `shaders_glsl/shared/cluster_box.glsl` and of the two kernels that write
//! boxes by it: `shaders_glsl/wgpu/lbvh_bounds.comp` (LBVH stage 1: an empty cluster gets the
//! empty box) and `shaders_glsl/vulkan/boxes.comp` (the BLAS input: an empty cluster gets a
//! degenerate box at its first particle, a slot past the step a NaN box). The rule itself is
//! [`crate::accel::clusters::cluster_box`], at f32.

use super::lbvh::{EMPTY_BOX, GpuBox};
use super::rbf::RadiusRule;
use crate::accel::clusters::cluster_box as rule;

/// Cluster `c`'s box (clusters of `k` of `points`), or `None` when it is empty.
pub fn cluster_box(
    points: &[[f32; 4]],
    c: usize,
    k: usize,
    radius: &RadiusRule<'_>,
) -> Option<[[f32; 3]; 2]> {
    let end = ((c + 1) * k).min(points.len());
    rule((c * k..end).map(|i| {
        let p = points[i];
        ([p[0], p[1], p[2]], radius.radius(p, i))
    }))
}

/// `lbvh_bounds.comp`: one box per cluster, the empty box for an empty cluster.
pub fn lbvh_bounds(points: &[[f32; 4]], k: usize, radius: &RadiusRule<'_>) -> Vec<GpuBox> {
    (0..points.len().div_ceil(k))
        .map(|c| match cluster_box(points, c, k, radius) {
            Some([lo, hi]) => [[lo[0], lo[1], lo[2], 0.0], [hi[0], hi[1], hi[2], 0.0]],
            None => EMPTY_BOX,
        })
        .collect()
}

/// `boxes.comp`: `slots` boxes as `[min.xyz, max.xyz]`: a degenerate box at the first particle
/// for an empty cluster, NaN past the step's clusters.
pub fn blas_boxes(
    points: &[[f32; 4]],
    k: usize,
    radius: &RadiusRule<'_>,
    slots: usize,
) -> Vec<[f32; 6]> {
    (0..slots)
        .map(|c| {
            if c * k >= points.len() {
                return [f32::NAN; 6];
            }
            let [lo, hi] = cluster_box(points, c, k, radius).unwrap_or_else(|| {
                let p = points[c * k];
                [[p[0], p[1], p[2]]; 2]
            });
            [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]]
        })
        .collect()
}
