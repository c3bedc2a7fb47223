#version 460
// One frame of the shared integrators over the voxel-grid baseline's grid (voxel_splat.comp's
// sums, reached by device address), added into the accumulation the other frame kernels
// fill. Twin: CpuBackend::render_voxels (render_pixel_with over a VoxelGrid).
// twin: src/backend/voxel.rs: the CPU backend marches the same grid with the same integrators (tests/voxel_ash.rs compares the images)
#include "vulkan/bindings.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer VoxelArray {
    vec4 v[];
};

vec4 voxel_sums(ivec3 c) {
    uint i = (uint(c.z) * voxels.dims.y + uint(c.y)) * voxels.dims.w + uint(c.x);
    return VoxelArray(push.voxel_address).v[i];
}

#include "shared/voxel_sample.glsl"

vec4 field_query(vec3 x) {
    return voxel_field(x);
}

#include "shared/integrators.glsl"

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= frame.image.x || pixel.y >= frame.image.y) {
        return;
    }
    vec4 c = render_pixel(pixel);
    uint i = pixel.y * frame.image.x + pixel.x;
    accum[i] = (push.first_frame == 1u) ? c : accum[i] + c;
}
