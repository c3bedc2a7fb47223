//! A BVH over cluster boxes (obvhs' PLOC builder) for point queries on the CPU.

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
    /// BVH primitive index → cluster index.
    clusters: Vec<u32>,
    /// BVH primitive index → its box (a leaf node may hold several primitives).
    leaf_boxes: Vec<Aabb>,
}

impl ClusterBvh {
    pub fn build(boxes: &ClusterBoxes) -> ClusterBvh {
        let mut clusters = Vec::new();
        let mut leaves = Vec::new();
        for (i, b) in boxes.boxes.iter().enumerate() {
            if !b.is_empty() {
                clusters.push(i as u32);
                leaves.push(Leaf(Aabb::new(b.min.into(), b.max.into())));
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
            clusters,
            leaf_boxes,
        }
    }

    /// Calls `visit` with the index of every cluster whose box may contain `x` (every one that
    /// does, and possibly some within an f32 rounding of it).
    pub fn for_each_cluster_at(&self, x: DVec3, mut visit: impl FnMut(usize)) {
        let Some(bvh) = &self.bvh else { return };
        let query = Aabb::new(
            Vec3A::new(f32_down(x.x), f32_down(x.y), f32_down(x.z)),
            Vec3A::new(f32_up(x.x), f32_up(x.y), f32_up(x.z)),
        );
        bvh.aabb_traverse(query, |bvh, node_index| {
            let node = &bvh.nodes[node_index as usize];
            for i in node.first_index..node.first_index + node.prim_count {
                let prim = bvh.primitive_indices[i as usize] as usize;
                if self.leaf_boxes[prim].intersect_aabb(&query) {
                    visit(self.clusters[prim] as usize);
                }
            }
            true
        });
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
