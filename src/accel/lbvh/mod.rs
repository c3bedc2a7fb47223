//! A linear BVH over cluster boxes (Karras, "Maximizing parallelism in the construction of
//! BVHs, octrees, and k-d trees", HPG 2012), built on the CPU in f32 and laid out as the GPU
//! holds it: the tree the ash backend's software traversal walks (`shaders_glsl/shared/lbvh.glsl`),
//! and the build the wgpu backend runs on the device stage by stage. The CPU twins of those
//! shaders (`backend::shaders::cpu::lbvh*`) are these functions: the tests compare them with
//! the GPU's stages, integer stages (keys, sort, hierarchy, parents, depth) bit for bit, float
//! stages (boxes) within a stated tolerance, and the bottom-up bounds exactly (min/max of the
//! same f32 values).
//!
//! # Stages
//! 1. **Cluster boxes** ([`cluster_boxes`]; `lbvh_boxes.comp`): cluster `c` holds particles
//!    `cK .. cK+K` (Hilbert order, local coordinates); its box bounds `[p - r, p + r]` over
//!    members with `r > 0` ([`super::clusters::cluster_box`] at f32). No member left: the box
//!    is empty (`min = +inf, max = -inf`) and the cluster stays out of the tree.
//! 2. **Keys** ([`morton_keys`]; `lbvh_keys.wgsl`): a 30-bit Morton key of the box centre on a
//!    1024^3 grid over the series' bounds (x in the highest bit of each triple);
//!    [`LBVH_EMPTY_KEY`] for an empty box, so empty clusters sort last. The non-empty ones are
//!    counted: `n` leaves.
//! 3. **Sort** ([`sort_pairs`]; `radix_sort.wgsl`): a stable LSD radix sort of (key, cluster)
//!    pairs, 4-bit digits, 8 passes: equal to a stable `sort_by_key`.
//! 4. **Hierarchy** ([`Lbvh::hierarchy`]; `lbvh_hierarchy.wgsl`): Karras' internal nodes over
//!    the first `n` sorted keys; duplicate keys are told apart by their sorted index (the key
//!    extended by the index), so the tree is unique and its depth is at most 30 + 32 = 62.
//! 5. **Bottom-up bounds** ([`Lbvh::fit`]; `lbvh_fit.wgsl`): each node's box is the union of its
//!    children's; each node's height too. A refit ([`Lbvh::refit`]) reruns stages 1 and 5 over
//!    the same topology.
//!
//! # Node layout (shared with the GPU, 32 bytes a node)
//! `nodes[j]` is 8 words: `[min.x, min.y, min.z, left, max.x, max.y, max.z, right]`, the box as
//! f32 bits and the children as pointers: [`LBVH_LEAF`]` | c` for cluster `c` (whose box is the
//! cluster box), else an internal node's index. Node 0 is a header whose word 3 holds the root
//! pointer ([`LBVH_NONE`] for an empty tree, a leaf pointer for a one-leaf tree, else 1); Karras'
//! internal node `i` is node `i + 1`. Beside it: `node_parents[j]` (the root's is [`LBVH_NONE`])
//! and `leaf_parents[c]` ([`LBVH_NONE`] for a cluster left out, [`LBVH_ROOT_LEAF`] for the only leaf).

mod boxes;
mod fit;
mod hierarchy;
mod keys;
mod validate;

pub use crate::values::shader_constants::{
    LBVH_EMPTY_KEY, LBVH_LEAF, LBVH_NONE, LBVH_ROOT_LEAF, LBVH_SENTINEL, LBVH_STACK_SIZE,
    MORTON_CELLS,
};
pub use boxes::{EMPTY_BOX, GpuBox, box_contains, box_is_empty, cluster_box_of, cluster_boxes};
pub use hierarchy::karras_split;
pub use keys::{KeyGrid, expand_bits, morton_key, morton_keys};

/// Words per node.
pub const NODE_WORDS: usize = 8;
/// Bytes per node (nodes), per cluster box, and per parent entry.
pub const NODE_BYTES: usize = 32;
/// Bytes per cluster box ([`GpuBox`]: two rows of four f32).
pub const BOX_BYTES: usize = 32;

/// An LBVH over cluster boxes, laid out as the GPU holds it (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Lbvh {
    /// Node 0 the header, nodes `1..leaves` the internal nodes.
    pub nodes: Vec<[u32; NODE_WORDS]>,
    /// Per node: the index of its parent node ([`LBVH_NONE`] for the root and the header).
    pub node_parents: Vec<u32>,
    /// Per cluster.
    pub leaf_parents: Vec<u32>,
    /// Non-empty clusters: the tree's leaves.
    pub leaves: u32,
    /// Height of the root in edges (0 for zero or one leaf): the most internal nodes on a
    /// path from the root, hence the most entries the traversal stack holds.
    pub depth: u32,
}

/// The children of a node.
pub fn children(node: &[u32; NODE_WORDS]) -> [u32; 2] {
    [node[3], node[7]]
}

/// Stage 3: (key, value) pairs sorted stably by key, values the input indices.
pub fn sort_pairs(keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut values: Vec<u32> = (0..keys.len() as u32).collect();
    values.sort_by_key(|&i| keys[i as usize]);
    (values.iter().map(|&i| keys[i as usize]).collect(), values)
}

/// Bytes the tree keeps for `clusters` clusters: nodes, cluster boxes and parent links.
pub fn structure_bytes(clusters: usize) -> usize {
    clusters * (NODE_BYTES + BOX_BYTES + 4 + 4)
}

impl Lbvh {
    /// Stages 2–5 over cluster boxes.
    pub fn build(boxes: &[GpuBox], grid: &KeyGrid) -> Lbvh {
        let (keys, clusters) = sort_pairs(&morton_keys(boxes, grid));
        let mut tree = Lbvh::hierarchy(&keys, &clusters);
        tree.fit(boxes);
        tree
    }

    /// The root pointer (word 3 of the header): [`LBVH_NONE`] for an empty tree, a leaf pointer for
    /// a one-leaf tree, else 1.
    pub fn root(&self) -> u32 {
        self.nodes[0][3]
    }

    /// The box of node `j` (an internal node).
    pub fn node_box(&self, j: usize) -> GpuBox {
        let w = &self.nodes[j];
        let f = |i: usize| f32::from_bits(w[i]);
        [[f(0), f(1), f(2), 0.0], [f(4), f(5), f(6), 0.0]]
    }

    fn set_node_box(&mut self, j: usize, b: &GpuBox) {
        let node = &mut self.nodes[j];
        for (i, (lo, hi)) in b[0][..3].iter().zip(&b[1][..3]).enumerate() {
            node[i] = lo.to_bits();
            node[4 + i] = hi.to_bits();
        }
    }

    /// Calls `visit(c)` for every cluster whose box contains `x`, walking the tree exactly as
    /// `lbvh_field` in `shared/lbvh.glsl` does (which, for clusters of one particle, skips the
    /// leaf's box test and lets the particle's sphere test decide). Returns the most stack
    /// entries used.
    pub fn for_each_cluster_at(
        &self,
        boxes: &[GpuBox],
        x: [f32; 3],
        mut visit: impl FnMut(u32),
    ) -> usize {
        let root = self.root();
        if root == LBVH_NONE {
            return 0;
        }
        let mut stack = [0u32; LBVH_STACK_SIZE as usize];
        let mut sp = 0;
        let mut most = 0;
        let mut ptr = root;
        loop {
            if ptr & LBVH_LEAF != 0 {
                let c = ptr & !LBVH_LEAF;
                if box_contains(&boxes[c as usize], x) {
                    visit(c);
                }
            } else if box_contains(&self.node_box(ptr as usize), x) {
                let node = &self.nodes[ptr as usize];
                stack[sp] = node[7];
                sp += 1;
                most = most.max(sp);
                ptr = node[3];
                continue;
            }
            if sp == 0 {
                break;
            }
            sp -= 1;
            ptr = stack[sp];
        }
        most
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    pub(super) fn random_boxes(n: usize, seed: u64, empty_every: usize) -> Vec<GpuBox> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                if empty_every > 0 && i % empty_every == 3 {
                    return EMPTY_BOX;
                }
                let c: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                let r = rng.random_range(0.0..0.05f32);
                [
                    [c[0] - r, c[1] - r, c[2] - r, 0.0],
                    [c[0] + r, c[1] + r, c[2] + r, 0.0],
                ]
            })
            .collect()
    }

    pub(super) fn grid() -> KeyGrid {
        KeyGrid {
            lo: [-1.0; 3],
            scale: [512.0; 3],
        }
    }

    #[test]
    fn trees_are_valid_for_awkward_sizes_and_duplicate_keys() {
        for n in [0usize, 1, 2, 3, 255, 256, 257, 5000] {
            for empty_every in [0, 7] {
                let boxes = random_boxes(n, n as u64, empty_every);
                let tree = Lbvh::build(&boxes, &grid());
                tree.validate(&boxes, true)
                    .unwrap_or_else(|e| panic!("n {n}: {e}"));
            }
        }
        // All keys equal: the index tie-break gives a balanced tree of depth ceil(log2 n).
        let same = vec![[[0.0, 0.0, 0.0, 0.0], [0.1, 0.1, 0.1, 0.0]]; 1000];
        let tree = Lbvh::build(&same, &grid());
        tree.validate(&same, true).unwrap();
        assert_eq!(tree.depth, 10);
    }

    #[test]
    fn traversal_finds_exactly_the_boxes_containing_a_point() {
        let boxes = random_boxes(3000, 9, 11);
        let tree = Lbvh::build(&boxes, &grid());
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        for _ in 0..500 {
            let x: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
            let mut found = Vec::new();
            let most = tree.for_each_cluster_at(&boxes, x, |c| found.push(c));
            assert!(most <= tree.depth as usize);
            found.sort();
            let expected: Vec<u32> = (0..boxes.len() as u32)
                .filter(|&c| box_contains(&boxes[c as usize], x))
                .collect();
            assert_eq!(found, expected);
        }
    }
}
