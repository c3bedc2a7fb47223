//! The tree's structural check, for tests and debugging: what every build and refit must
//! leave.

use super::boxes::{GpuBox, box_contains_box, box_is_empty};
use super::{LBVH_LEAF, LBVH_NONE, LBVH_ROOT_LEAF, LBVH_STACK_SIZE, Lbvh, children};

impl Lbvh {
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
