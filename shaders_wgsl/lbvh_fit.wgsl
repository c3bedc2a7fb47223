// LBVH bottom-up bounds (build and refit): every internal node's box is the union of its
// children's, and (at a build) its height is one more than its taller child's. One thread per
// cluster climbs from its leaf towards the root; at each node the first of the two children's
// threads to arrive stops, the second combines both and climbs on. Twin: Lbvh::fit.
//
// Why this is safe under WGSL's memory model. WGSL atomics are relaxed and it has no
// device-scope fence, so the usual scheme (store the child's box with plain stores, then bump
// a per-node flag; the thread that sees the flag at 1 reads the sibling's box) is a data race:
// seeing the flag promises nothing about the sibling's other stores. Here the flag and the
// data are the same words. Each of a node's bounds words (min.xyz, max.xyz, and its height
// word) starts as SENTINEL, written by an earlier dispatch (the hierarchy pass, or the reset
// entry point at a refit), so it is visible to this one. Each child's thread then does one
// atomicExchange of its own value into the word. Atomic read-modify-writes of one location are
// totally ordered, and each reads the value the previous one wrote (per-location coherence and
// RMW atomicity, which hold for relaxed atomics). Exactly two exchanges hit each word, so
// exactly one of them reads SENTINEL (that thread stops carrying this word's component) and
// the other reads the sibling's
// value, whatever the order, with no reliance on ordering between different locations. The
// second thread stores min/max of the two (the node's final value; nobody else writes the word
// again in this dispatch) and carries it up to the parent. Each of the six bounds words and the
// height is its own rendezvous: a thread never needs a word it did not meet at, so no ordering
// between different locations is assumed anywhere. The traversal and the host read the words
// in later dispatches, which wgpu orders after this one (a barrier between dispatches).

#include "shared/tree_params.wgsl"

@group(0) @binding(3) var<storage, read> node_parents: array<u32>;
@group(0) @binding(4) var<storage, read> leaf_parents: array<u32>;
@group(0) @binding(5) var<storage, read_write> heights: array<atomic<u32>>;
// [0] leaves, [1] depth (the root's height), [2] set when a refit finds a cluster that was
// left out of the tree (empty at the build) holding particles: the tree must be rebuilt.
@group(0) @binding(6) var<storage, read_write> counters: array<atomic<u32>>;
#include "shared/split_boxes.wgsl"

// The nodes (8 words each) in up to SPLIT_PARTS parts likewise. Each word's atomics go to one
// location in one part whatever the split, so the meet-at-the-word argument above holds
// unchanged.
#split_array nodes 14 atomic<u32> read_write params.part_words exchange:node_exchange store:node_store

// The two children of a node meet at each of its words: each exchanges its value `v` into
// word `w`. The first to arrive reads SENTINEL and drops out; the second reads its sibling's
// value, stores the combination (min for a lower bound, max for an upper one) and carries it.
struct Meet {
    second: bool,
    value: f32,
}

fn meet(w: u32, v: f32, is_max: bool) -> Meet {
    let old = node_exchange(w, bitcast<u32>(v));
    if old == LBVH_SENTINEL {
        return Meet(false, v);
    }
    var c = min(v, bitcast<f32>(old));
    if is_max {
        c = max(v, bitcast<f32>(old));
    }
    node_store(w, bitcast<u32>(c));
    return Meet(true, c);
}

@compute @workgroup_size(64)
fn climb(id: Invocation) {
    let c = thread_index(id);
    if c >= params.clusters {
        return;
    }
    let b = cluster_box(c);
    let parent = leaf_parents[c];
    if parent == LBVH_NONE {
        if b.lo.x <= b.hi.x {
            atomicStore(&counters[2], 1u);
        }
        return;
    }
    if parent == LBVH_ROOT_LEAF {
        return;
    }
    // One walk up the tree carrying all seven values; `carried` holds the components this
    // thread still carries (a component drops out at the first node where this thread arrives
    // first). Each component follows the meet-at-the-word rule above on its own, so sharing
    // the walk changes no result; it only reads each node's words together.
    var carried = 0x3fu;
    if params.components > 6u {
        carried = 0x7fu;
    }
    var v = array<f32, 6>(b.lo.x, b.lo.y, b.lo.z, b.hi.x, b.hi.y, b.hi.z);
    var height = 0u;
    var node = parent;
    loop {
        let base = node * 8u;
        for (var i = 0u; i < 6u; i++) {
            if (carried & (1u << i)) != 0u {
                // Words 0..2 hold the lower bounds, 4..6 the upper (3 and 7 the children).
                let m = meet(base + i + i / 3u, v[i], i >= 3u);
                if m.second {
                    v[i] = m.value;
                } else {
                    carried &= ~(1u << i);
                }
            }
        }
        if (carried & 0x40u) != 0u {
            let old = atomicExchange(&heights[node], height);
            if old == LBVH_SENTINEL {
                carried &= ~0x40u;
            } else {
                height = max(height, old) + 1u;
                atomicStore(&heights[node], height);
            }
        }
        if carried == 0u {
            return;
        }
        let up = node_parents[node];
        if up == LBVH_NONE {
            if (carried & 0x40u) != 0u {
                atomicStore(&counters[1], height);
            }
            return;
        }
        node = up;
    }
}

// Refit, first: every internal node's bounds words back to SENTINEL (children kept).
@compute @workgroup_size(64)
fn reset(id: Invocation) {
    let node = thread_index(id) + 1u;
    if node >= atomicLoad(&counters[0]) {
        return;
    }
    // The six bounds words (min.xyz at 0..3, max.xyz at 4..7).
    for (var k = 0u; k < 3u; k++) {
        node_store(node * 8u + k, LBVH_SENTINEL);
        node_store(node * 8u + 4u + k, LBVH_SENTINEL);
    }
}
