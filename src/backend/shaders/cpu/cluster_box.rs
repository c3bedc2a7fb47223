//! The CPU twin of `shaders_glsl/shared/cluster_box.glsl`: cluster `c`'s box by the shared
//! cluster-box rule, which the stages `lbvh_boxes` ([`super::lbvh_boxes`]) and `blas_boxes`
//! ([`super::blas_boxes`]) apply to every cluster. The rule itself is
//! [`crate::accel::clusters::cluster_box`], at f32.

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
