//! The CPU twin of `shaders_glsl/wgpu/lbvh_bounds.comp`: one box per cluster (LBVH stage 1).

use super::lbvh::{EMPTY_BOX, GpuBox};
use super::rbf::RadiusRule;

/// Stage 1: one box per cluster of `k` consecutive particles.
pub fn cluster_boxes(points: &[[f32; 4]], k: usize, rule: &RadiusRule<'_>) -> Vec<GpuBox> {
    points
        .chunks(k)
        .enumerate()
        .map(|(c, members)| {
            let mut b = EMPTY_BOX;
            for (j, p) in members.iter().enumerate() {
                let r = rule.radius(*p, c * k + j);
                if r > 0.0 {
                    for i in 0..3 {
                        b[0][i] = b[0][i].min(p[i] - r);
                        b[1][i] = b[1][i].max(p[i] + r);
                    }
                }
            }
            b
        })
        .collect()
}
