//! The LBVH as the GPU holds it, and the CPU twin of `shaders_glsl/shared/lbvh.glsl` (the
//! point-query traversal). The module documentation of [`super`] describes the build.

use super::lbvh_keys::{KeyGrid, morton_keys};
use super::radix_sort::sort_pairs;
pub use crate::values::shader_constants::{
    LBVH_EMPTY_KEY, LBVH_LEAF, LBVH_NONE, LBVH_ROOT_LEAF, LBVH_SENTINEL, LBVH_STACK_SIZE,
    MORTON_CELLS,
};

/// Words per node.
pub const NODE_WORDS: usize = 8;
/// Bytes per node (nodes), per cluster box, and per parent entry.
pub const NODE_BYTES: usize = 32;
pub const BOX_BYTES: usize = 32;

// The box as the GPU stores it, and the tests on it, live with the cluster-box rule that makes
// the boxes (a module lbvh_keys uses too, without a loop through this one).
pub use super::cluster_box::{EMPTY_BOX, GpuBox, box_contains, box_is_empty};
pub(super) use super::cluster_box::{box_contains_box, box_union};

/// An LBVH over cluster boxes, laid out as the GPU holds it (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct Lbvh {
    /// Node 0 the header, nodes `1..leaves` the internal nodes.
    pub nodes: Vec<[u32; NODE_WORDS]>,
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

impl Lbvh {
    /// Stages 2–5 over cluster boxes.
    pub fn build(boxes: &[GpuBox], grid: &KeyGrid) -> Lbvh {
        let (keys, clusters) = sort_pairs(&morton_keys(boxes, grid));
        let mut tree = Lbvh::hierarchy(&keys, &clusters);
        tree.fit(boxes);
        tree
    }

    pub fn root(&self) -> u32 {
        self.nodes[0][3]
    }

    /// The box of node `j` (an internal node).
    pub fn node_box(&self, j: usize) -> GpuBox {
        let w = &self.nodes[j];
        let f = |i: usize| f32::from_bits(w[i]);
        [[f(0), f(1), f(2), 0.0], [f(4), f(5), f(6), 0.0]]
    }

    pub(super) fn set_node_box(&mut self, j: usize, b: &GpuBox) {
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

    /// Checks the tree against the cluster boxes it was built or refitted over: every node's
    /// box contains its children's, every non-empty cluster is a leaf reached exactly once
    /// (clusters left out are empty, or `built` is false after a refit), every internal node is
    /// reached once, parent and child links agree, and the depth is the root's height.
    pub fn validate(&self, boxes: &[GpuBox], built: bool) -> Result<(), String> {
        let n_internal = self.nodes.len() - 1;
        if self.leaf_parents.len() != boxes.len() {
            return Err(format!(
                "{} leaf parents for {} clusters",
                self.leaf_parents.len(),
                boxes.len()
            ));
        }
        if self.leaves as usize != n_internal + 1 && !(self.leaves == 0 && n_internal == 0) {
            return Err(format!(
                "{} leaves but {n_internal} internal nodes",
                self.leaves
            ));
        }
        let mut leaf_seen = vec![0u32; boxes.len()];
        let mut node_seen = vec![0u32; self.nodes.len()];
        let root = self.root();
        let mut depth = 0u32;
        if root == LBVH_NONE {
            if self.leaves != 0 {
                return Err("no root but leaves".into());
            }
        } else if root & LBVH_LEAF != 0 {
            let c = (root & !LBVH_LEAF) as usize;
            if self.leaf_parents.get(c) != Some(&LBVH_ROOT_LEAF) {
                return Err(format!("the only leaf {c} lacks the LBVH_ROOT_LEAF mark"));
            }
            leaf_seen[c] += 1;
        } else {
            if root != 1 || self.node_parents[1] != LBVH_NONE {
                return Err(format!("root {root}, its parent {}", self.node_parents[1]));
            }
            let mut stack = vec![(root, 0u32)];
            while let Some((j, level)) = stack.pop() {
                let j = j as usize;
                if j == 0 || j > n_internal {
                    return Err(format!("node pointer {j} out of range"));
                }
                node_seen[j] += 1;
                depth = depth.max(level + 1);
                let b = self.node_box(j);
                if (0..3).any(|i| b[0][i].is_nan() || b[1][i].is_nan()) {
                    return Err(format!("node {j} has an unwritten (NaN) bound: {b:?}"));
                }
                for c in children(&self.nodes[j]) {
                    if c & LBVH_LEAF != 0 {
                        let cl = (c & !LBVH_LEAF) as usize;
                        if cl >= boxes.len() {
                            return Err(format!("node {j}: leaf {cl} out of range"));
                        }
                        leaf_seen[cl] += 1;
                        if self.leaf_parents[cl] != j as u32 {
                            return Err(format!(
                                "leaf {cl}: parent {} but child of {j}",
                                self.leaf_parents[cl]
                            ));
                        }
                        if !box_contains_box(&b, &boxes[cl]) {
                            return Err(format!(
                                "node {j} {b:?} does not contain leaf {cl} {:?}",
                                boxes[cl]
                            ));
                        }
                    } else {
                        if self.node_parents.get(c as usize) != Some(&(j as u32)) {
                            return Err(format!("node {c}: parent is not {j}"));
                        }
                        let cb = self.node_box(c as usize);
                        if !box_contains_box(&b, &cb) {
                            return Err(format!("node {j} {b:?} does not contain node {c} {cb:?}"));
                        }
                        stack.push((c, level + 1));
                    }
                }
            }
        }
        if let Some(j) = (1..=n_internal).find(|&j| node_seen[j] != 1) {
            return Err(format!("internal node {j} reached {} times", node_seen[j]));
        }
        for (c, b) in boxes.iter().enumerate() {
            let in_tree = self.leaf_parents[c] != LBVH_NONE;
            if leaf_seen[c] != u32::from(in_tree) {
                return Err(format!(
                    "cluster {c} reached {} times (in tree: {in_tree})",
                    leaf_seen[c]
                ));
            }
            if built && in_tree == box_is_empty(b) {
                return Err(format!("cluster {c}: in tree {in_tree}, box {b:?}"));
            }
        }
        if depth != self.depth {
            return Err(format!("depth {} reported, {depth} found", self.depth));
        }
        if depth > LBVH_STACK_SIZE {
            return Err(format!(
                "depth {depth} exceeds the stack ({LBVH_STACK_SIZE})"
            ));
        }
        Ok(())
    }
}

/// Bytes the tree keeps for `clusters` clusters: nodes, cluster boxes and parent links.
pub fn structure_bytes(clusters: usize) -> usize {
    clusters * (NODE_BYTES + BOX_BYTES + 4 + 4)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    pub(crate) fn random_boxes(n: usize, seed: u64, empty_every: usize) -> Vec<GpuBox> {
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

    pub(crate) fn grid() -> KeyGrid {
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
