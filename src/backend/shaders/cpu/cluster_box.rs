//! The CPU twin of `shaders_glsl/shared/cluster_box.glsl`: cluster `c`'s box by the shared
//! cluster-box rule, which the stages `lbvh_boxes` ([`super::lbvh_boxes`]) and `blas_boxes`
//! ([`super::blas_boxes`]) apply to every cluster. The rule itself is
//! [`crate::accel::clusters::cluster_box`], at f32, over a step's particles by
//! [`crate::accel::lbvh::cluster_box_of`].

use super::rbf::RadiusRule;
use crate::accel::lbvh::cluster_box_of;

/// Cluster `c`'s box (clusters of `k` of `points`), or `None` when it is empty.
pub fn cluster_box(
    points: &[[f32; 4]],
    c: usize,
    k: usize,
    radius: &RadiusRule<'_>,
) -> Option<[[f32; 3]; 2]> {
    cluster_box_of(points, c, k, |p, i| radius.radius(p, i))
}
