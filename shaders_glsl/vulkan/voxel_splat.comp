#version 460
// The voxel-grid baseline's splat on the ash backend: each particle adds its kernel (the
// shared rbf_inside and rbf_add) to every cell centre of the grid within its radius. The grid
// is one buffer reached by device address (push.voxel_address: four f32 sums per cell, x
// fastest), so no binding limit splits it into slabs as on wgpu. Vulkan GLSL has atomics but
// no float atomic add without an extension lavapipe may lack, so each add is a
// compare-exchange loop on the word's bits (an add is lost only if another thread changed the
// word in between, and then the exchange fails and is retried with the new value). The host
// clears the grid first. Twin: the scatter of Particles::eval_grid_sums.
// twin: src/field/grid.rs: the scatter of Particles::eval_grid_sums (tests/voxel_ash.rs compares the grids)
#include "vulkan/bindings.glsl"

layout(local_size_x = 64) in;
layout(buffer_reference, std430, buffer_reference_align = 4) buffer WordArray {
    uint v[];
};

void add_f32(uint word, float value) {
    WordArray grid = WordArray(push.voxel_address);
    // Any first guess will do: the exchange only succeeds against the word's current bits.
    uint old = grid.v[word];
    for (;;) {
        uint seen = atomicCompSwap(grid.v[word], old, floatBitsToUint(uintBitsToFloat(old) + value));
        if (seen == old) {
            break;
        }
        old = seen;
    }
}

void main() {
    uint k = gl_GlobalInvocationID.y * push.width + gl_GlobalInvocationID.x;
    if (k >= push.count) {
        return;
    }
    vec4 p = particle(k);
    float r = particle_radius(p, k);
    // Radius 0 (or NaN) reaches nothing, as rbf_inside says.
    if (!(r > 0.0)) {
        return;
    }
    // The particle's offset from the first cell centre (with double-single positions the lo
    // parts added, as rbf_offset does).
    vec3 at = p.xyz - voxels.origin.xyz;
    if (POSITION_DS == 1u) {
        at += particle_lo(k).xyz - voxels.origin_lo.xyz;
    }
    vec3 cell = voxels.cell.xyz;
    // The cell centres within the radius along each axis (centre c at c * cell from the first),
    // one beyond each end so that rounding in the division cannot drop one the test keeps.
    vec3 first_f = max(floor((at - r) / cell), vec3(0.0));
    vec3 last_f = min(ceil((at + r) / cell), vec3(voxels.dims.xyz) - 1.0);
    if (any(greaterThan(first_f, last_f))) {
        return;
    }
    uvec3 first = uvec3(first_f);
    uvec3 last = uvec3(last_f);
    for (uint z = first.z; z <= last.z; z++) {
        for (uint y = first.y; y <= last.y; y++) {
            for (uint x = first.x; x <= last.x; x++) {
                vec3 d = vec3(x, y, z) * cell - at;
                float d2 = dot(d, d);
                if (rbf_inside(d2, r)) {
                    vec4 sums = vec4(0.0);
                    rbf_add(sums, d2, r, p, k);
                    uint word = 4u * ((z * voxels.dims.y + y) * voxels.dims.w + x);
                    add_f32(word, sums.x);
                    if (voxels.channels.x > 1u) {
                        add_f32(word + 1u, sums.y);
                    }
                    if (voxels.channels.x > 2u) {
                        add_f32(word + 2u, sums.z);
                        add_f32(word + 3u, sums.w);
                    }
                }
            }
        }
    }
}
