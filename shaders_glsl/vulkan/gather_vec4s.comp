#version 460
// Preparing a step on the device (ash): vec4s into the sorted order, out[k] = in[order[k]]
// (the particles with t, their lo parts). Arrays: a0 the order, a1 in, a2 out.
// shaders_wgsl/gather.wgsl's gather_vec4s; twin backend/shaders/cpu/gather.rs.
#include "vulkan/prepare.glsl"

layout(local_size_x = 64) in;

void main() {
    uint k = element_index();
    if (k >= push.count) {
        return;
    }
    Vec4s(push.a2).v[k] = Vec4s(push.a1).v[Words(push.a0).v[k]];
}
