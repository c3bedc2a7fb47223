// The LBVH nodes and cluster boxes, in up to SPLIT_PARTS parts each, read-only: see
// wgpu/split.glsl.

layout(std430, set = 0, binding = 14) readonly buffer LbvhNodes0 { vec4 lbvh_nodes0[]; };
layout(std430, set = 0, binding = 18) readonly buffer LbvhBoxes0 { vec4 lbvh_boxes0[]; };
#if SPLIT_PARTS > 1
layout(std430, set = 0, binding = 15) readonly buffer LbvhNodes1 { vec4 lbvh_nodes1[]; };
layout(std430, set = 0, binding = 16) readonly buffer LbvhNodes2 { vec4 lbvh_nodes2[]; };
layout(std430, set = 0, binding = 17) readonly buffer LbvhNodes3 { vec4 lbvh_nodes3[]; };
layout(std430, set = 0, binding = 19) readonly buffer LbvhBoxes1 { vec4 lbvh_boxes1[]; };
layout(std430, set = 0, binding = 20) readonly buffer LbvhBoxes2 { vec4 lbvh_boxes2[]; };
layout(std430, set = 0, binding = 21) readonly buffer LbvhBoxes3 { vec4 lbvh_boxes3[]; };
#endif

// vec4 number v of the nodes (node j is vec4s 2j and 2j + 1).
vec4 lbvh_node(uint v) {
#if SPLIT_PARTS > 1
    uint len = field_params.counts.w;
    if (v < len) {
        return lbvh_nodes0[v];
    }
    v -= len;
    if (v < len) {
        return lbvh_nodes1[v];
    }
    v -= len;
    if (v < len) {
        return lbvh_nodes2[v];
    }
    return lbvh_nodes3[v - len];
#else
    return lbvh_nodes0[v];
#endif
}

// vec4 number v of the cluster boxes (cluster c's box is vec4s 2c and 2c + 1).
vec4 lbvh_box(uint v) {
#if SPLIT_PARTS > 1
    uint len = field_params.counts.w;
    if (v < len) {
        return lbvh_boxes0[v];
    }
    v -= len;
    if (v < len) {
        return lbvh_boxes1[v];
    }
    v -= len;
    if (v < len) {
        return lbvh_boxes2[v];
    }
    return lbvh_boxes3[v - len];
#else
    return lbvh_boxes0[v];
#endif
}
