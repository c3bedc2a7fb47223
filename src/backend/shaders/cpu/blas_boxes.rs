//! The CPU twin of `shaders_glsl/vulkan/blas_boxes.comp` (the ash backend's BLAS input): one
//! box per slot by the shared rule ([`super::cluster_box`]), a degenerate box at its first
//! particle for an empty cluster, a NaN box for a slot past the step.

use super::cluster_box::cluster_box;
use super::rbf::RadiusRule;

/// `blas_boxes.comp`: `slots` boxes as `[min.xyz, max.xyz]`: a degenerate box at the first particle
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
