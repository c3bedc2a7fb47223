//! A BVH over cluster boxes (obvhs' PLOC builder) for rays on the CPU (the splatter walks the
//! boxes along a ray in order). obvhs works in f32: the boxes are held relative to a local
//! origin (their centre), rounded outward, so the tree keeps its resolution far from the
//! data's origin and never misses a box a ray crosses; the f64 tests of the particles
//! themselves decide.

use glam::{DVec3, Vec3A};
use obvhs::{Boundable, BvhBuildParams, aabb::Aabb, bvh2::Bvh2};

use super::clusters::{ClusterBoxes, f32_down, f32_up};

struct Leaf(Aabb);

impl Boundable for Leaf {
    fn aabb(&self) -> Aabb {
        self.0
    }
}

/// A BVH whose leaves are the non-empty boxes of a [`ClusterBoxes`].
pub struct ClusterBvh {
    bvh: Option<Bvh2>,
    /// Leaf boxes are relative to this point.
    origin: DVec3,
    /// BVH primitive index → cluster index.
    clusters: Vec<u32>,
    /// BVH primitive index → its box (a leaf node may hold several primitives).
    leaf_boxes: Vec<Aabb>,
}

impl ClusterBvh {
    /// Builds the tree over the non-empty boxes of `boxes` (none at all: an empty tree that no ray
    /// crosses).
    pub fn build(boxes: &ClusterBoxes) -> ClusterBvh {
        let origin = boxes
            .boxes
            .iter()
            .fold(crate::values::Bounds::EMPTY, |u, b| u.union(*b))
            .center();
        let mut clusters = Vec::new();
        let mut leaves = Vec::new();
        for (i, b) in boxes.boxes.iter().enumerate() {
            if !b.is_empty() {
                clusters.push(i as u32);
                leaves.push(Leaf(Aabb::new(down(b.min - origin), up(b.max - origin))));
            }
        }
        let bvh = (!leaves.is_empty()).then(|| {
            obvhs::bvh2::builder::build_bvh2(
                &leaves,
                BvhBuildParams::fast_build(),
                &mut std::time::Duration::default(),
            )
        });
        let leaf_boxes = leaves.into_iter().map(|l| l.0).collect();
        ClusterBvh {
            bvh,
            origin,
            clusters,
            leaf_boxes,
        }
    }

    /// Appends `(t_in, t_out, cluster)` for every cluster box the ray `origin + t dir` crosses
    /// within `[t0, t1]`, in f64 and local coordinates (the boxes' outward-rounded f32 bounds
    /// are exact in f64, so nothing is missed to rounding). The tree is walked near child
    /// first, so the boxes come out nearly in order of `t_in` (a sort of them is then cheap).
    pub fn ray_boxes(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        out: &mut Vec<(f64, f64, u32)>,
    ) {
        let Some(bvh) = &self.bvh else { return };
        let origin = origin - self.origin;
        let inv = dir.recip();
        let interval = |b: &Aabb| -> Option<(f64, f64)> {
            let lo = (b.min.as_dvec3() - origin) * inv;
            let hi = (b.max.as_dvec3() - origin) * inv;
            // NaN (0 * inf on a face) must not shrink the interval: min/max ignore NaN.
            let t_in = lo.min(hi).max_element().max(t0);
            let t_out = lo.max(hi).min_element().min(t1);
            (t_in <= t_out).then_some((t_in, t_out))
        };
        let hit = |b: &Aabb| interval(b).map(|(t_in, _)| t_in);
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        if hit(bvh.nodes[0].aabb()).is_some() {
            stack.push(0);
        }
        while let Some(index) = stack.pop() {
            let node = &bvh.nodes[index as usize];
            if node.is_leaf() {
                for i in node.first_index..node.first_index + node.prim_count {
                    let prim = bvh.primitive_indices[i as usize] as usize;
                    if let Some((a, b)) = interval(&self.leaf_boxes[prim]) {
                        out.push((a, b, self.clusters[prim]));
                    }
                }
                continue;
            }
            let (l, r) = (node.first_index, node.first_index + 1);
            match (
                hit(bvh.nodes[l as usize].aabb()),
                hit(bvh.nodes[r as usize].aabb()),
            ) {
                // The nearer child goes on top of the stack.
                (Some(a), Some(b)) if a <= b => stack.extend([r, l]),
                (Some(_), Some(_)) => stack.extend([l, r]),
                (Some(_), None) => stack.push(l),
                (None, Some(_)) => stack.push(r),
                (None, None) => {}
            }
        }
    }

    /// Bytes of the tree's nodes and index arrays.
    pub fn bytes(&self) -> usize {
        self.bvh.as_ref().map_or(0, |b| {
            b.nodes.len() * std::mem::size_of::<obvhs::bvh2::node::Bvh2Node>()
                + b.primitive_indices.len() * 4
        }) + self.clusters.len() * 4
            + self.leaf_boxes.len() * std::mem::size_of::<Aabb>()
    }
}

/// The f32 point at or below `v` on every axis.
fn down(v: DVec3) -> Vec3A {
    Vec3A::new(f32_down(v.x), f32_down(v.y), f32_down(v.z))
}

/// The f32 point at or above `v` on every axis.
fn up(v: DVec3) -> Vec3A {
    Vec3A::new(f32_up(v.x), f32_up(v.y), f32_up(v.z))
}
