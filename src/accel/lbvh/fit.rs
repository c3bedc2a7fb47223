//! Bottom-up bounds and heights (stage 5; `lbvh_fit.wgsl` on the GPU), for builds and refits.

use super::boxes::{EMPTY_BOX, GpuBox, box_is_empty, box_union};
use super::{LBVH_LEAF, LBVH_NONE, Lbvh, children};

impl Lbvh {
    /// Stage 5: every internal node's box and height, bottom up, from the cluster boxes.
    pub fn fit(&mut self, boxes: &[GpuBox]) {
        self.depth = 0;
        let root = self.root();
        if root == LBVH_NONE || root & LBVH_LEAF != 0 {
            return;
        }
        // Post-order over internal nodes with an explicit stack: (node, children done).
        let mut heights = vec![0u32; self.nodes.len()];
        let mut stack = vec![(root, false)];
        while let Some((j, done)) = stack.pop() {
            let ch = children(&self.nodes[j as usize]);
            if !done {
                stack.push((j, true));
                for c in ch {
                    if c & LBVH_LEAF == 0 {
                        stack.push((c, false));
                    }
                }
                continue;
            }
            let mut b = EMPTY_BOX;
            let mut h = 0;
            for (k, c) in ch.into_iter().enumerate() {
                let (cb, ch_height) = if c & LBVH_LEAF != 0 {
                    (boxes[(c & !LBVH_LEAF) as usize], 0)
                } else {
                    (self.node_box(c as usize), heights[c as usize])
                };
                b = if k == 0 { cb } else { box_union(&b, &cb) };
                h = h.max(ch_height);
            }
            heights[j as usize] = h + 1;
            self.set_node_box(j as usize, &b);
        }
        self.depth = heights[root as usize];
    }

    /// A refit over new cluster boxes, topology kept. False when a cluster that was left out
    /// of the tree (empty at the build) holds particles now: the tree must be rebuilt.
    pub fn refit(&mut self, boxes: &[GpuBox]) -> bool {
        let depth = self.depth;
        self.fit(boxes);
        self.depth = depth;
        !boxes
            .iter()
            .zip(&self.leaf_parents)
            .any(|(b, &p)| p == LBVH_NONE && !box_is_empty(b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::lbvh::morton_keys;
    use crate::accel::lbvh::tests::{grid, random_boxes};

    #[test]
    fn refit_over_unchanged_centres_equals_a_fresh_build() {
        let boxes = random_boxes(2000, 4, 0);
        let mut tree = Lbvh::build(&boxes, &grid());
        // Grow every box about its centre: the keys and so the topology stay.
        let grown: Vec<GpuBox> = boxes
            .iter()
            .map(|b| {
                let mut g = *b;
                g[0][..3].iter_mut().for_each(|v| *v -= 0.25);
                g[1][..3].iter_mut().for_each(|v| *v += 0.25);
                g
            })
            .collect();
        assert!(tree.refit(&grown));
        tree.validate(&grown, true).unwrap();
        let fresh = Lbvh::build(&grown, &grid());
        let centre_keys_equal = morton_keys(&boxes, &grid()) == morton_keys(&grown, &grid());
        if centre_keys_equal {
            assert_eq!(tree, fresh);
        }
        // A cluster that was empty gains a particle: refit reports that a rebuild is needed.
        let mut boxes = random_boxes(100, 5, 4);
        let mut tree = Lbvh::build(&boxes, &grid());
        boxes[3] = boxes[0];
        assert!(!tree.refit(&boxes));
    }
}
