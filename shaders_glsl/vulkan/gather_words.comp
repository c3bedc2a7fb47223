#version 460
// Preparing a step on the device (ash): 4-byte words into the sorted order, out[k] =
// in[order[k]] (the sort's high key words between its two sorts, the radius attribute). Arrays:
// a0 the order, a1 in, a2 out. shaders_wgsl/gather.wgsl's gather_words; twin
// backend/shaders/cpu/gather.rs.
#include "vulkan/prepare.glsl"

layout(local_size_x = 64) in;

void main() {
    uint k = element_index();
    if (k >= push.count) {
        return;
    }
    Words(push.a2).v[k] = Words(push.a1).v[Words(push.a0).v[k]];
}
