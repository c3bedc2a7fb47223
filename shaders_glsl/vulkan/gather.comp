#version 460
// Preparing a step on the device (ash): an array into the sorted order, out[k] =
// in[order[k]]. Arrays: a0 the order, a1 in, a2 out. Two entry points, as
// shaders_wgsl/gather.wgsl's (build.rs compiles the file once per `#ifdef ENTRY_<name>` block):
// gather_words for 4-byte words (the sort's high key words between its two sorts, the radius
// attribute), gather_vec4s for vec4s (the particles with t, their lo parts). Twin:
// backend/shaders/cpu/gather.rs.
#include "vulkan/prepare.glsl"

layout(local_size_x = 64) in;

#ifdef ENTRY_gather_words
void main() {
    uint k = element_index();
    if (k >= push.count) {
        return;
    }
    Words(push.a2).v[k] = Words(push.a1).v[Words(push.a0).v[k]];
}
#endif

#ifdef ENTRY_gather_vec4s
void main() {
    uint k = element_index();
    if (k >= push.count) {
        return;
    }
    Vec4s(push.a2).v[k] = Vec4s(push.a1).v[Words(push.a0).v[k]];
}
#endif
