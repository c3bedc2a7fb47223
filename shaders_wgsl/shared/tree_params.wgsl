// The LBVH build passes' uniform (src/backend/wgpu_lbvh/tree.rs, TreeParams), at binding 0 of
// every pass. Included by lbvh_keys, lbvh_hierarchy and lbvh_fit, with the shared constants.

#include "generated/constants.wgsl"
#include "shared/invocation.wgsl"

struct TreeParams {
    // Key grid: cell = (centre - key_lo) * key_scale on a 1024^3 grid over the series' bounds.
    key_lo: vec4<f32>,
    key_scale: vec4<f32>,
    clusters: u32,
    // 7: bounds and heights (build); 6: bounds only (refit).
    components: u32,
    // Per part of the split boxes and nodes (see box_at, node_exchange): vec4s and words
    // (0xffffffff when one part holds the whole array).
    part_vec4s: u32,
    part_words: u32,
}

@group(0) @binding(0) var<uniform> params: TreeParams;
