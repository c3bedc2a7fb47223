//! Karras' internal nodes (stage 4; `lbvh_hierarchy.wgsl` on the GPU).

use super::{
    LBVH_EMPTY_KEY, LBVH_LEAF, LBVH_NONE, LBVH_ROOT_LEAF, LBVH_SENTINEL, Lbvh, NODE_WORDS,
};

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

impl Lbvh {
    /// Stage 4: the hierarchy over sorted keys and their clusters (`n_clusters` in all, the
    /// empty ones sorted last), bounds words left at [`LBVH_SENTINEL`].
    pub fn hierarchy(sorted_keys: &[u32], sorted_clusters: &[u32]) -> Lbvh {
        let n_clusters = sorted_keys.len();
        let n = sorted_keys
            .iter()
            .take_while(|&&k| k != LBVH_EMPTY_KEY)
            .count();
        let internal = n.saturating_sub(1);
        let mut nodes = vec![[LBVH_SENTINEL; NODE_WORDS]; internal + 1];
        let mut node_parents = vec![LBVH_NONE; internal + 1];
        let mut leaf_parents = vec![LBVH_NONE; n_clusters];
        let root = match n {
            0 => LBVH_NONE,
            1 => {
                leaf_parents[sorted_clusters[0] as usize] = LBVH_ROOT_LEAF;
                LBVH_LEAF | sorted_clusters[0]
            }
            _ => 1,
        };
        nodes[0] = [0, 0, 0, root, 0, 0, 0, LBVH_NONE];
        for i in 0..internal {
            let (gamma, left_leaf, right_leaf) = karras_split(sorted_keys, n, i);
            let node = i as u32 + 1;
            let mut link = |position: usize, leaf: bool| {
                if leaf {
                    let c = sorted_clusters[position];
                    leaf_parents[c as usize] = node;
                    LBVH_LEAF | c
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
}
