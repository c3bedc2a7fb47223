//! The CPU twin of `shaders_glsl/wgpu/lbvh_boxes.comp` (LBVH stage 1): one box per cluster by
//! the shared rule ([`super::cluster_box`]), the empty box for an empty cluster, which the tree
//! then leaves out.

use super::cluster_box::cluster_box;
use super::lbvh::{EMPTY_BOX, GpuBox};
use super::rbf::RadiusRule;

/// `lbvh_boxes.comp`: one box per cluster, the empty box for an empty cluster.
pub fn lbvh_boxes(points: &[[f32; 4]], k: usize, radius: &RadiusRule<'_>) -> Vec<GpuBox> {
    (0..points.len().div_ceil(k))
        .map(|c| match cluster_box(points, c, k, radius) {
            Some([lo, hi]) => [[lo[0], lo[1], lo[2], 0.0], [hi[0], hi[1], hi[2], 0.0]],
            None => EMPTY_BOX,
        })
        .collect()
}
