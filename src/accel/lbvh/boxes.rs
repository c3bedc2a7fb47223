//! Cluster boxes as the GPU stores them, the tests on them, and a step's boxes (stage 1) by
//! the cluster-box rule at f32.

use crate::accel::clusters::cluster_box;

/// A box as the GPU stores it: `[min.xyz, 0]`, `[max.xyz, 0]`.
pub type GpuBox = [[f32; 4]; 2];

/// The box of a cluster with no member: `min = +inf`, `max = -inf`, which [`box_is_empty`] reports
/// and every union leaves unchanged.
pub const EMPTY_BOX: GpuBox = [
    [f32::INFINITY, f32::INFINITY, f32::INFINITY, 0.0],
    [f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY, 0.0],
];

/// Whether a box holds nothing (the GPU's test: not `min.x <= max.x`).
pub fn box_is_empty(b: &GpuBox) -> bool {
    // Written to match the GPU's `lo.x <= hi.x` exactly, NaN included.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let empty = !(b[0][0] <= b[1][0]);
    empty
}

/// Whether `x` lies in `b` (boundary included), as the traversal tests it.
pub fn box_contains(b: &GpuBox, x: [f32; 3]) -> bool {
    (0..3).all(|i| x[i] >= b[0][i] && x[i] <= b[1][i])
}

pub(super) fn box_union(a: &GpuBox, b: &GpuBox) -> GpuBox {
    let mut out = *a;
    for i in 0..3 {
        out[0][i] = a[0][i].min(b[0][i]);
        out[1][i] = a[1][i].max(b[1][i]);
    }
    out
}

/// `b` contains `inner` (an empty `inner` is contained in anything).
pub(super) fn box_contains_box(b: &GpuBox, inner: &GpuBox) -> bool {
    box_is_empty(inner) || (0..3).all(|i| b[0][i] <= inner[0][i] && b[1][i] >= inner[1][i])
}

/// Cluster `c`'s box (clusters of `k` of `points`, local coordinates in xyz) by the
/// cluster-box rule at f32, particle `i` of radius `radius(points[i], i)`; `None` when the
/// cluster is empty.
pub fn cluster_box_of(
    points: &[[f32; 4]],
    c: usize,
    k: usize,
    radius: impl Fn([f32; 4], usize) -> f32,
) -> Option<[[f32; 3]; 2]> {
    let end = ((c + 1) * k).min(points.len());
    cluster_box((c * k..end).map(|i| {
        let p = points[i];
        ([p[0], p[1], p[2]], radius(p, i))
    }))
}

/// Stage 1: one box per cluster of `k` of `points` ([`cluster_box_of`]), the empty box for an
/// empty cluster, which the tree then leaves out.
pub fn cluster_boxes(
    points: &[[f32; 4]],
    k: usize,
    radius: impl Fn([f32; 4], usize) -> f32,
) -> Vec<GpuBox> {
    (0..points.len().div_ceil(k))
        .map(|c| match cluster_box_of(points, c, k, &radius) {
            Some([lo, hi]) => [[lo[0], lo[1], lo[2], 0.0], [hi[0], hi[1], hi[2], 0.0]],
            None => EMPTY_BOX,
        })
        .collect()
}
