// LBVH build, stage 2: a 30-bit Morton key per cluster from its box centre on a 1024^3 grid
// over the series' bounds (LBVH_EMPTY_KEY for an empty box, so empty clusters sort last), the
// identity permutation the sort carries along, and the count of non-empty clusters (the
// tree's leaves). Twin: backend/shaders/cpu/lbvh_keys.rs.

#include "shared/tree_params.wgsl"

@group(0) @binding(2) var<storage, read_write> keys: array<u32>;
@group(0) @binding(3) var<storage, read_write> values: array<u32>;
@group(0) @binding(4) var<storage, read_write> leaf_parents: array<u32>;
// [0] non-empty clusters (cleared by the host before this pass).
@group(0) @binding(5) var<storage, read_write> counters: array<atomic<u32>>;
#include "shared/split_boxes.wgsl"

fn expand_bits(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

@compute @workgroup_size(64)
fn main(id: Invocation) {
    let c = thread_index(id);
    if c >= params.clusters {
        return;
    }
    let b = cluster_box(c);
    var key = LBVH_EMPTY_KEY;
    if b.lo.x <= b.hi.x {
        let centre = (b.lo + b.hi) * 0.5;
        let q = clamp((centre - params.key_lo.xyz) * params.key_scale.xyz, vec3<f32>(0.0), vec3<f32>(f32(MORTON_CELLS - 1u)));
        let cell = vec3<u32>(q);
        key = (expand_bits(cell.x) << 2u) | (expand_bits(cell.y) << 1u) | expand_bits(cell.z);
        atomicAdd(&counters[0], 1u);
    }
    keys[c] = key;
    values[c] = c;
    // The hierarchy pass links the clusters that are leaves; the rest stay out.
    leaf_parents[c] = LBVH_NONE;
}
