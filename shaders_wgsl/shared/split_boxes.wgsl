// The cluster boxes in up to SPLIT_PARTS parts (src/backend/wgpu_lbvh/util.rs, SplitBuffer;
// shaders_glsl/wgpu/split.glsl explains the two variants). In the 4-part variant an unsplit
// array has part_vec4s 0xffffffff and every thread takes the first branch of box_at. Include
// after tree_params.wgsl.
@group(0) @binding(18) var<storage, read> boxes0: array<vec4<f32>>;
#if SPLIT_PARTS > 1
@group(0) @binding(19) var<storage, read> boxes1: array<vec4<f32>>;
@group(0) @binding(20) var<storage, read> boxes2: array<vec4<f32>>;
@group(0) @binding(21) var<storage, read> boxes3: array<vec4<f32>>;
#endif

// vec4 number v of the boxes (cluster c's box is 2c and 2c + 1).
fn box_at(v: u32) -> vec4<f32> {
#if SPLIT_PARTS > 1
    let len = params.part_vec4s;
    var i = v;
    if i < len {
        return boxes0[i];
    }
    i -= len;
    if i < len {
        return boxes1[i];
    }
    i -= len;
    if i < len {
        return boxes2[i];
    }
    return boxes3[i - len];
#else
    return boxes0[v];
#endif
}
