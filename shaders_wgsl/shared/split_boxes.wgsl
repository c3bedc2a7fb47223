// The cluster boxes in up to SPLIT_PARTS parts (src/backend/wgpu_lbvh/util.rs, SplitBuffer;
// shaders_glsl/wgpu/split.glsl explains the two variants). In the 4-part variant an unsplit
// array has part_vec4s 0xffffffff and every thread takes the first branch of box_at. Include
// after tree_params.wgsl.
#split_array boxes 18 vec4<f32> read params.part_vec4s get:box_at

struct ClusterBox {
    lo: vec3<f32>,
    hi: vec3<f32>,
}

// Cluster c's box (empty when not lo.x <= hi.x).
fn cluster_box(c: u32) -> ClusterBox {
    return ClusterBox(box_at(2u * c).xyz, box_at(2u * c + 1u).xyz);
}
