#version 450
// One frame of the shared integrators over the voxel-grid baseline's grid (a 3D texture of
// the sums at cell centres, filled by voxel_particles.comp and voxel_splat.wgsl), added to
// the accumulation lbvh_render.comp fills. Twin: CpuBackend::render_voxels
// (backend::cpu::integrators::render_pixel_with over a VoxelGrid).
// twin: src/backend/voxel.rs: the CPU backend marches the same grid with the same integrators (tests/voxel_wgpu.rs compares the images)

layout(local_size_x = 8, local_size_y = 8) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform FrameBlock { Frame frame; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(set = 0, binding = 5) uniform texture3D voxel_texture;
layout(std140, set = 0, binding = 6) uniform VoxelBlock { Voxels voxels; };
layout(std430, set = 0, binding = 7) readonly buffer StbnMask { uint stbn_words[]; };
// tiling and accumulation_parts as in lbvh_render.comp.
layout(std140, set = 0, binding = 9) uniform TilingBlock {
    uvec4 tiling;
    uvec4 accumulation_parts;
};
#split_array accumulation 22 vec4 readwrite accumulation_parts.x add:accumulate

#include "shared/maps.glsl"
#include "shared/noise.glsl"

vec4 voxel_sums(ivec3 cell) {
    return texelFetch(voxel_texture, cell, 0);
}

#include "shared/voxel_sample.glsl"

vec4 field_query(vec3 x) {
    return voxel_field(x);
}

#include "shared/integrators.glsl"

void main() {
    // The tile order of lbvh_render.comp.
    uint g = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint tile = (g % tiling.z) * tiling.w + g / tiling.z;
    if (tile >= tiling.y) {
        return;
    }
    uvec2 pixel = uvec2(tile % tiling.x, tile / tiling.x) * 8u + gl_LocalInvocationID.xy;
    if (pixel.x >= frame.image.x || pixel.y >= frame.image.y) {
        return;
    }
    uint i = pixel.y * frame.image.x + pixel.x;
    accumulate(i, render_pixel(pixel));
}
