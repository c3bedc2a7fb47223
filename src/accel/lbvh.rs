//! A linear BVH (Karras, "Maximizing parallelism in the construction of BVHs, octrees, and k-d
//! trees", HPG 2012) over cluster boxes: the CPU twin of the wgpu backend's GPU build
//! (`shaders_glsl/wgpu/lbvh_bounds.comp`, `shaders_wgsl/lbvh_*.wgsl`, `shaders_wgsl/radix_sort.wgsl`)
//! and of its traversal (`shaders_glsl/shared/lbvh.glsl`). Every stage here does what the GPU
//! stage does, in the same f32 arithmetic, so the tests compare them: integer stages (keys,
//! sort, hierarchy, parents, depth) bit for bit, float stages (boxes) within a stated tolerance,
//! and the bottom-up bounds exactly (min/max of the same f32 values).
//!
//! # Stages
//! 1. **Cluster boxes** (`lbvh_bounds.comp`): cluster `c` holds particles `cK .. cK+K` (Hilbert
//!    order, local coordinates); its box bounds `[p - r, p + r]` over members with `r > 0`
//!    (`r` = `particle_radius` of `shared/rbf.glsl`). No member left: the box is empty
//!    (`min = +inf, max = -inf`) and the cluster stays out of the tree.
//! 2. **Keys** (`lbvh_keys.wgsl`): a 30-bit Morton key of the box centre on a 1024^3 grid over
//!    the series' bounds (x in the highest bit of each triple); [`EMPTY_KEY`] for an empty box,
//!    so empty clusters sort last. The non-empty ones are counted: `n` leaves.
//! 3. **Sort** (`radix_sort.wgsl`): a stable LSD radix sort of (key, cluster) pairs, 4-bit
//!    digits, 8 passes: equal to a stable `sort_by_key`.
//! 4. **Hierarchy** (`lbvh_hierarchy.wgsl`): Karras' internal nodes over the first `n` sorted
//!    keys; duplicate keys are told apart by their sorted index (the key extended by the
//!    index), so the tree is unique and its depth is at most 30 + 32 = 62.
//! 5. **Bottom-up bounds** (`lbvh_fit.wgsl`): each node's box is the union of its children's;
//!    each node's height too. A refit reruns stages 1 and 5 over the same topology.
//!
//! # Node layout (shared with the GPU, 32 bytes a node)
//! `nodes[j]` is 8 words: `[min.x, min.y, min.z, left, max.x, max.y, max.z, right]`, the box as
//! f32 bits and the children as pointers: [`LEAF`]` | c` for cluster `c` (whose box is the
//! cluster box), else an internal node's index. Node 0 is a header whose word 3 holds the root
//! pointer ([`NONE`] for an empty tree, a leaf pointer for a one-leaf tree, else 1); Karras'
//! internal node `i` is node `i + 1`. Beside it: `node_parents[j]` (the root's is [`NONE`])
//! and `leaf_parents[c]` ([`NONE`] for a cluster left out, [`ROOT_LEAF`] for the only leaf).

use glam::DVec3;

use crate::scene::Bounds;
use crate::shaders::GpuField;

/// Cells per axis of the Morton grid (10 bits).
pub const MORTON_CELLS: u32 = 1024;
/// The key of an empty cluster: above every Morton key (those use 30 bits).
pub const EMPTY_KEY: u32 = u32::MAX;
/// A child pointer's leaf flag; the low 31 bits are the cluster index.
pub const LEAF: u32 = 0x8000_0000;
/// No node: a missing root, a root's parent, a cluster left out of the tree.
pub const NONE: u32 = u32::MAX;
/// `leaf_parents` of the only leaf of a one-leaf tree (it is in the tree, with no parent).
pub const ROOT_LEAF: u32 = 0xFFFF_FFFE;
/// The word a bound holds before the bottom-up pass writes it (a NaN no bound can be).
pub const SENTINEL: u32 = u32::MAX;
/// Entries of the traversal stack in `shared/lbvh.glsl`: at least the deepest possible tree's
/// depth (62, see the module documentation), so it cannot overflow.
pub const STACK_SIZE: usize = 64;
/// Words per node.
pub const NODE_WORDS: usize = 8;
/// Bytes per node (nodes), per cluster box, and per parent entry.
pub const NODE_BYTES: usize = 32;
pub const BOX_BYTES: usize = 32;

/// A box as the GPU stores it: `[min.xyz, 0]`, `[max.xyz, 0]`.
pub type GpuBox = [[f32; 4]; 2];

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

fn box_union(a: &GpuBox, b: &GpuBox) -> GpuBox {
    let mut out = *a;
    for i in 0..3 {
        out[0][i] = a[0][i].min(b[0][i]);
        out[1][i] = a[1][i].max(b[1][i]);
    }
    out
}

/// `b` contains `inner` (an empty `inner` is contained in anything).
fn box_contains_box(b: &GpuBox, inner: &GpuBox) -> bool {
    box_is_empty(inner) || (0..3).all(|i| b[0][i] <= inner[0][i] && b[1][i] >= inner[1][i])
}

/// `maps.glsl`'s `map_lookup` in f32: clamp t to [0, 1] (NaN to 0) and interpolate.
pub fn table_lookup_f32(table: &[f32], t: f32) -> f32 {
    let size = table.len() as u32;
    let c = if t >= 0.0 { t.min(1.0) } else { 0.0 };
    let x = c * (size - 1) as f32;
    let i = (x.floor() as u32).min(size - 2);
    let f = x - i as f32;
    let (a, b) = (table[i as usize], table[i as usize + 1]);
    a + (b - a) * f
}

/// How particle radii are computed: `rbf.glsl`'s `particle_radius` in f32.
#[derive(Clone, Copy, Debug)]
pub struct RadiusRule<'a> {
    pub field: GpuField,
    /// The radius-map table when the map varies (`RADIUS_MAP_VARIES`), else the constant
    /// `field.radius[1]` applies.
    pub radius_table: Option<&'a [f32]>,
    /// Per-particle radius factors (`HAS_RADIUS_ATTRIBUTE`).
    pub radius_attribute: Option<&'a [f32]>,
}

impl RadiusRule<'_> {
    pub fn radius(&self, p: [f32; 4], index: usize) -> f32 {
        let m = match self.radius_table {
            Some(t) => table_lookup_f32(t, p[3]),
            None => self.field.radius[1],
        };
        let mut r = self.field.radius[0] * m;
        if let Some(h) = self.radius_attribute {
            r *= h[index];
        }
        r
    }
}

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

/// The Morton grid over the series' bounds, in local coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyGrid {
    /// The grid's lower corner (local coordinates).
    pub lo: [f32; 3],
    /// Cells per unit length on each axis (0 on an axis of zero extent).
    pub scale: [f32; 3],
}

impl KeyGrid {
    /// The grid over `series_bounds`, with local coordinates relative to `origin`.
    pub fn new(series_bounds: Bounds, origin: DVec3) -> KeyGrid {
        let extent = series_bounds.extent();
        let lo = if series_bounds.is_empty() {
            DVec3::ZERO
        } else {
            series_bounds.min.as_dvec3() - origin
        };
        let scale = |e: f64| {
            if e > 0.0 {
                (f64::from(MORTON_CELLS) / e) as f32
            } else {
                0.0
            }
        };
        KeyGrid {
            lo: [lo.x as f32, lo.y as f32, lo.z as f32],
            scale: [scale(extent.x), scale(extent.y), scale(extent.z)],
        }
    }
}

/// Spreads the low 10 bits of `v` to every third bit.
pub fn expand_bits(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00FF;
    x = (x | (x << 8)) & 0x0300_F00F;
    x = (x | (x << 4)) & 0x030C_30C3;
    x = (x | (x << 2)) & 0x0924_9249;
    x
}

/// Stage 2: a cluster's key.
pub fn morton_key(b: &GpuBox, grid: &KeyGrid) -> u32 {
    if box_is_empty(b) {
        return EMPTY_KEY;
    }
    let max = (MORTON_CELLS - 1) as f32;
    let q: [u32; 3] = std::array::from_fn(|i| {
        let centre = (b[0][i] + b[1][i]) * 0.5;
        ((centre - grid.lo[i]) * grid.scale[i]).clamp(0.0, max) as u32
    });
    (expand_bits(q[0]) << 2) | (expand_bits(q[1]) << 1) | expand_bits(q[2])
}

pub fn morton_keys(boxes: &[GpuBox], grid: &KeyGrid) -> Vec<u32> {
    boxes.iter().map(|b| morton_key(b, grid)).collect()
}

/// Stage 3: (key, value) pairs sorted stably by key, values the input indices.
pub fn sort_pairs(keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut values: Vec<u32> = (0..keys.len() as u32).collect();
    values.sort_by_key(|&i| keys[i as usize]);
    (values.iter().map(|&i| keys[i as usize]).collect(), values)
}

/// Karras' δ: the common prefix length of the extended keys of sorted positions i and j
/// (-1 outside `0..n`).
fn delta(keys: &[u32], n: i64, i: i64, j: i64) -> i32 {
    if j < 0 || j >= n {
        return -1;
    }
    let (a, b) = (keys[i as usize], keys[j as usize]);
    if a == b {
        32 + ((i as u32) ^ (j as u32)).leading_zeros() as i32
    } else {
        (a ^ b).leading_zeros() as i32
    }
}

/// The two children of Karras' internal node `i` (over `n` sorted keys), as sorted positions:
/// `(gamma, left_is_leaf, right_is_leaf)`; the children are `gamma` and `gamma + 1`.
pub fn karras_split(keys: &[u32], n: usize, i: usize) -> (usize, bool, bool) {
    let (n, i) = (n as i64, i as i64);
    let d: i64 = if delta(keys, n, i, i + 1) - delta(keys, n, i, i - 1) >= 0 {
        1
    } else {
        -1
    };
    let dmin = delta(keys, n, i, i - d);
    let mut lmax: i64 = 2;
    while delta(keys, n, i, i + lmax * d) > dmin {
        lmax *= 2;
    }
    let mut l = 0;
    let mut t = lmax / 2;
    while t >= 1 {
        if delta(keys, n, i, i + (l + t) * d) > dmin {
            l += t;
        }
        t /= 2;
    }
    let j = i + l * d;
    let dnode = delta(keys, n, i, j);
    let mut s = 0;
    let mut divisor = 2;
    loop {
        let t = (l + divisor - 1) / divisor;
        if delta(keys, n, i, i + (s + t) * d) > dnode {
            s += t;
        }
        if t <= 1 {
            break;
        }
        divisor *= 2;
    }
    let gamma = i + s * d + d.min(0);
    (gamma as usize, i.min(j) == gamma, i.max(j) == gamma + 1)
}

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
    /// Stage 4: the hierarchy over sorted keys and their clusters (`n_clusters` in all, the
    /// empty ones sorted last), bounds words left at [`SENTINEL`].
    pub fn hierarchy(sorted_keys: &[u32], sorted_clusters: &[u32]) -> Lbvh {
        let n_clusters = sorted_keys.len();
        let n = sorted_keys.iter().take_while(|&&k| k != EMPTY_KEY).count();
        let internal = n.saturating_sub(1);
        let mut nodes = vec![[SENTINEL; NODE_WORDS]; internal + 1];
        let mut node_parents = vec![NONE; internal + 1];
        let mut leaf_parents = vec![NONE; n_clusters];
        let root = match n {
            0 => NONE,
            1 => {
                leaf_parents[sorted_clusters[0] as usize] = ROOT_LEAF;
                LEAF | sorted_clusters[0]
            }
            _ => 1,
        };
        nodes[0] = [0, 0, 0, root, 0, 0, 0, NONE];
        for i in 0..internal {
            let (gamma, left_leaf, right_leaf) = karras_split(sorted_keys, n, i);
            let node = i as u32 + 1;
            let mut link = |position: usize, leaf: bool| {
                if leaf {
                    let c = sorted_clusters[position];
                    leaf_parents[c as usize] = node;
                    LEAF | c
                } else {
                    node_parents[position + 1] = node;
                    position as u32 + 1
                }
            };
            let left = link(gamma, left_leaf);
            let right = link(gamma + 1, right_leaf);
            nodes[node as usize][3] = left;
            nodes[node as usize][7] = right;
        }
        Lbvh {
            nodes,
            node_parents,
            leaf_parents,
            leaves: n as u32,
            depth: 0,
        }
    }

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

    fn set_node_box(&mut self, j: usize, b: &GpuBox) {
        let node = &mut self.nodes[j];
        for (i, (lo, hi)) in b[0][..3].iter().zip(&b[1][..3]).enumerate() {
            node[i] = lo.to_bits();
            node[4 + i] = hi.to_bits();
        }
    }

    /// Stage 5: every internal node's box and height, bottom up, from the cluster boxes.
    pub fn fit(&mut self, boxes: &[GpuBox]) {
        self.depth = 0;
        let root = self.root();
        if root == NONE || root & LEAF != 0 {
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
                    if c & LEAF == 0 {
                        stack.push((c, false));
                    }
                }
                continue;
            }
            let mut b = EMPTY_BOX;
            let mut h = 0;
            for (k, c) in ch.into_iter().enumerate() {
                let (cb, ch_height) = if c & LEAF != 0 {
                    (boxes[(c & !LEAF) as usize], 0)
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
            .any(|(b, &p)| p == NONE && !box_is_empty(b))
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
        if root == NONE {
            return 0;
        }
        let mut stack = [0u32; STACK_SIZE];
        let mut sp = 0;
        let mut most = 0;
        let mut ptr = root;
        loop {
            if ptr & LEAF != 0 {
                let c = ptr & !LEAF;
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
        if root == NONE {
            if self.leaves != 0 {
                return Err("no root but leaves".into());
            }
        } else if root & LEAF != 0 {
            let c = (root & !LEAF) as usize;
            if self.leaf_parents.get(c) != Some(&ROOT_LEAF) {
                return Err(format!("the only leaf {c} lacks the ROOT_LEAF mark"));
            }
            leaf_seen[c] += 1;
        } else {
            if root != 1 || self.node_parents[1] != NONE {
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
                    if c & LEAF != 0 {
                        let cl = (c & !LEAF) as usize;
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
            let in_tree = self.leaf_parents[c] != NONE;
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
        if depth as usize > STACK_SIZE {
            return Err(format!("depth {depth} exceeds the stack ({STACK_SIZE})"));
        }
        Ok(())
    }
}

/// Bytes the tree keeps for `clusters` clusters: nodes, cluster boxes and parent links.
pub fn structure_bytes(clusters: usize) -> usize {
    clusters * (NODE_BYTES + BOX_BYTES + 4 + 4)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_boxes(n: usize, seed: u64, empty_every: usize) -> Vec<GpuBox> {
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

    fn grid() -> KeyGrid {
        KeyGrid {
            lo: [-1.0; 3],
            scale: [512.0; 3],
        }
    }

    #[test]
    fn morton_keys_interleave_x_highest() {
        assert_eq!(expand_bits(0x3ff), 0x0924_9249);
        let b = |x: f32, y: f32, z: f32| [[x, y, z, 0.0], [x, y, z, 0.0]];
        let g = KeyGrid {
            lo: [0.0; 3],
            scale: [1.0; 3],
        };
        assert_eq!(morton_key(&b(1.0, 0.0, 0.0), &g), 0b100);
        assert_eq!(morton_key(&b(0.0, 1.0, 0.0), &g), 0b010);
        assert_eq!(morton_key(&b(0.0, 0.0, 1.0), &g), 0b001);
        assert_eq!(morton_key(&b(5000.0, -3.0, 2.0), &g) >> 2 & 1, 1);
        assert_eq!(morton_key(&EMPTY_BOX, &g), EMPTY_KEY);
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

    #[test]
    fn table_lookup_matches_the_f64_tables() {
        let table: Vec<f32> = (0..256).map(|i| (i as f32 / 255.0).powi(2)).collect();
        for t in [-1.0f32, 0.0, 0.3, 0.5, 0.999, 1.0, 2.0, f32::NAN] {
            let a = table_lookup_f32(&table, t);
            let b = crate::render::tables::lookup(&table, f64::from(t));
            assert!((f64::from(a) - b).abs() < 1e-6, "{t}: {a} {b}");
        }
    }
}
