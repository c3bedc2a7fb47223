// The LBVH traversal (shared/lbvh.glsl) over the ash backend's arrays: the tree the host
// built (src/backend/shaders/cpu, the wgpu build's twin) at bindings 10 and 11, the particles
// by device address. One buffer per array here; the wgpu backend splits them
// (wgpu/split.glsl). Include after vulkan/bindings.glsl.

layout(std430, set = 0, binding = 10) readonly buffer LbvhNodes { vec4 lbvh_nodes[]; };
layout(std430, set = 0, binding = 11) readonly buffer LbvhBoxes { vec4 lbvh_boxes[]; };

vec4 lbvh_node(uint v) {
    return lbvh_nodes[v];
}
vec4 lbvh_box(uint v) {
    return lbvh_boxes[v];
}

#include "shared/lbvh.glsl"
