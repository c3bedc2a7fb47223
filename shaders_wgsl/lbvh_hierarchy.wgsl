// LBVH build, stage 4: Karras' internal nodes (HPG 2012, "Maximizing parallelism in the
// construction of BVHs, octrees, and k-d trees"), one thread per internal node, over the n
// sorted keys of non-empty clusters. Duplicate keys are told apart by their sorted index (the
// key extended by the index), so every node's range and split are unique. Each thread writes
// its node's children, sets its bounds words (and its height word) to SENTINEL for the
// bottom-up pass, and links its children's parents. Node layout: src/backend/shaders/cpu/lbvh.rs (node 0 a
// header holding the root pointer; Karras' node i is node i + 1). Twin: Lbvh::hierarchy.

#include "shared/tree_params.wgsl"

@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read> clusters: array<u32>;
@group(0) @binding(4) var<storage, read_write> node_parents: array<u32>;
@group(0) @binding(5) var<storage, read_write> leaf_parents: array<u32>;
@group(0) @binding(6) var<storage, read_write> heights: array<u32>;
// [0] leaves (from the keys pass).
@group(0) @binding(7) var<storage, read> counters: array<u32>;
// The nodes (8 words each) in up to SPLIT_PARTS parts (src/backend/wgpu_lbvh/util.rs,
// SplitBuffer; shaders_glsl/wgpu/split.glsl explains the two variants). In the 4-part variant
// an unsplit array has part_words 0xffffffff and every thread takes the first branch of
// node_store.
#split_array nodes 14 u32 read_write params.part_words set:node_store

fn delta(i: i32, j: i32, n: i32) -> i32 {
    if j < 0 || j >= n {
        return -1;
    }
    let a = keys[i];
    let b = keys[j];
    if a == b {
        return 32 + i32(countLeadingZeros(u32(i) ^ u32(j)));
    }
    return i32(countLeadingZeros(a ^ b));
}

@compute @workgroup_size(64)
fn main(id: Invocation) {
    let index = thread_index(id);
    let n = i32(counters[0]);
    if index == 0u {
        var root = LBVH_NONE;
        if n == 1 {
            root = LBVH_LEAF | clusters[0];
            leaf_parents[clusters[0]] = LBVH_ROOT_LEAF;
        } else if n > 1 {
            root = 1u;
            node_parents[1] = LBVH_NONE;
        }
        for (var w = 0u; w < 8u; w++) {
            node_store(w, 0u);
        }
        node_store(3u, root);
        node_store(7u, LBVH_NONE);
        node_parents[0] = LBVH_NONE;
    }
    let i = i32(index);
    if i >= n - 1 {
        return;
    }
    // Direction of the node's range, and its other end j.
    var d = -1;
    if delta(i, i + 1, n) - delta(i, i - 1, n) >= 0 {
        d = 1;
    }
    let dmin = delta(i, i - d, n);
    var lmax = 2;
    while delta(i, i + lmax * d, n) > dmin {
        lmax *= 2;
    }
    var l = 0;
    for (var t = lmax / 2; t >= 1; t /= 2) {
        if delta(i, i + (l + t) * d, n) > dmin {
            l += t;
        }
    }
    let j = i + l * d;
    // The split: the last position sharing more than dnode bits with i.
    let dnode = delta(i, j, n);
    var s = 0;
    var divisor = 2;
    loop {
        let t = (l + divisor - 1) / divisor;
        if delta(i, i + (s + t) * d, n) > dnode {
            s += t;
        }
        if t <= 1 {
            break;
        }
        divisor *= 2;
    }
    let gamma = i + s * d + min(d, 0);
    let node = index + 1u;

    var left = u32(gamma) + 1u;
    if min(i, j) == gamma {
        left = LBVH_LEAF | clusters[gamma];
        leaf_parents[clusters[gamma]] = node;
    } else {
        node_parents[left] = node;
    }
    var right = u32(gamma) + 2u;
    if max(i, j) == gamma + 1 {
        right = LBVH_LEAF | clusters[gamma + 1];
        leaf_parents[clusters[gamma + 1]] = node;
    } else {
        node_parents[right] = node;
    }
    // The bounds words (min.xyz at 0..3, max.xyz at 4..7) wait for the bottom-up pass.
    for (var k = 0u; k < 3u; k++) {
        node_store(node * 8u + k, LBVH_SENTINEL);
        node_store(node * 8u + 4u + k, LBVH_SENTINEL);
    }
    node_store(node * 8u + 3u, left);
    node_store(node * 8u + 7u, right);
    heights[node] = LBVH_SENTINEL;
}
