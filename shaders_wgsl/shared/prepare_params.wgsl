// The uniform of the passes that prepare a step on the device (src/backend/wgpu_lbvh/prepare.rs,
// PrepareParams), at binding 0 of each: the Hilbert grid, the particle count and the part
// length of the split particle arrays.

#include "generated/constants.wgsl"
#include "shared/invocation.wgsl"

struct PrepareParams {
    // Hilbert grid in local coordinates (accel::HilbertQuantizer): cell = (p - grid_lo) * grid_scale.
    grid_lo: vec4<f32>,
    grid_scale: vec4<f32>,
    count: u32,
    // vec4s per part of the split particle arrays (0xffffffff when one part holds them).
    part_vec4s: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> params: PrepareParams;
