// The ash backend's passes that prepare a step on the device (src/backend/ash_rt/prepare.rs):
// their push constants and the arrays they reach by device address. The same stages as the
// wgpu backend's (shaders_wgsl/hilbert_keys.wgsl, radix_sort.wgsl, gather.wgsl) and the same
// CPU twins (backend/shaders/cpu/{hilbert_keys,radix_sort,gather}.rs); the sort needs
// workgroup atomics, which naga's GLSL front end (and so shaders_glsl/shared/) does not have.

#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require

#include "generated/constants.glsl"
#include "generated/hilbert_step.glsl"

layout(buffer_reference, std430, buffer_reference_align = 16) buffer Vec4s {
    vec4 v[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) buffer Words {
    uint v[];
};

// `PreparePush` in src/backend/ash_rt/prepare.rs. a0..a4 are each pass's arrays, in the
// order its comment gives.
layout(push_constant) uniform PreparePush {
    vec4 grid_lo;     // Hilbert grid: cell = (p - grid_lo) * grid_scale (accel::HilbertQuantizer)
    vec4 grid_scale;
    uint count;       // elements (particles, keys)
    uint shift;       // the sort pass's digit
    uint tiles;       // the sort's tiles of SORT_TILE keys
    uint width;       // row width of a 2D launch over a 1D array
    uvec2 a0;
    uvec2 a1;
    uvec2 a2;
    uvec2 a3;
    uvec2 a4;
} push;

// The thread's element in a 2D launch of 64-thread workgroups.
uint element_index() {
    return gl_GlobalInvocationID.y * push.width + gl_GlobalInvocationID.x;
}

