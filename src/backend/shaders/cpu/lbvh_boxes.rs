//! The CPU twin of `shaders_glsl/wgpu/lbvh_boxes.comp` (LBVH stage 1): one box per cluster by
//! the shared rule ([`super::cluster_box`]), the empty box for an empty cluster, which the tree
//! then leaves out: the library's [`crate::accel::lbvh::cluster_boxes`] under the shaders'
//! radius rule.

use super::lbvh::GpuBox;
use super::rbf::RadiusRule;
use crate::accel::lbvh::cluster_boxes;

/// `lbvh_boxes.comp`: one box per cluster, the empty box for an empty cluster.
pub fn lbvh_boxes(points: &[[f32; 4]], k: usize, radius: &RadiusRule<'_>) -> Vec<GpuBox> {
    cluster_boxes(points, k, |p, i| radius.radius(p, i))
}
