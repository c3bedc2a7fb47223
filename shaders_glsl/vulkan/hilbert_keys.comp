#version 460
// Preparing a step on the device, stage 1 (ash): each particle's 63-bit Hilbert key from the
// f32 local coordinates staged in the step's order, as two words (low 32 bits, high 31), and
// the identity permutation the sort carries along: shaders_wgsl/hilbert_keys.wgsl in GLSL (the
// cell in two correctly rounded operations, then HILBERT_STEP one level a step). Arrays: a0
// the staged particles, a1 the low words, a2 the high words, a3 the permutation. Twin:
// backend/shaders/cpu/hilbert_keys.rs.
#include "vulkan/prepare.glsl"

layout(local_size_x = 64) in;

void main() {
    uint i = element_index();
    if (i >= push.count) {
        return;
    }
    vec3 p = Vec4s(push.a0).v[i].xyz;
    float top = float((1u << HILBERT_BITS) - 1u);
    // precise: no fusing into an FMA, so the cell is the CPU's bit for bit.
    precise vec3 d = p - push.grid_lo.xyz;
    precise vec3 q = d * push.grid_scale.xyz;
    uvec3 cell = uvec3(clamp(q, vec3(0.0), vec3(top)));
    uint state = 0u;
    uint lo = 0u;
    uint hi = 0u;
    for (uint level = HILBERT_BITS; level > 0u; level--) {
        uint b = level - 1u;
        uint octant = (((cell.x >> b) & 1u) << 2u) | (((cell.y >> b) & 1u) << 1u) | ((cell.z >> b) & 1u);
        uint e = HILBERT_STEP[state * 8u + octant];
        hi = (hi << 3u) | (lo >> 29u);
        lo = (lo << 3u) | (e & 7u);
        state = e >> 3u;
    }
    Words(push.a1).v[i] = lo;
    Words(push.a2).v[i] = hi;
    Words(push.a3).v[i] = i;
}
