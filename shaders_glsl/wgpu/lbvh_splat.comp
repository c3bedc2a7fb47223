#version 450
// One frame of Knoll et al.'s RT splatter (the paper's Table 3 baseline) over the LBVH, added
// to the accumulation that lbvh_render.comp fills (sums of linear RGBA; the host divides by
// the frame count). Each pixel's slabs collect their hits by a software traversal of the tree
// (shared/lbvh_splat.glsl) and are composited by shared/splat_pixel.glsl.
// Twin: backend::cpu::splat::splat_pixel. Emission–absorption only: no integrator, no noise.
// twin: src/backend/cpu/splat.rs: the CPU backend splats the same frame (tests/splat_wgpu.rs compares the images)

layout(local_size_x = 8, local_size_y = 8) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform FrameBlock { Frame frame; };
layout(std140, set = 0, binding = 1) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 4) readonly buffer RadiusAttributes { float radius_attributes[]; };
// tiling: x 8x8 tiles per row, y tiles, z blocks B, w tiles per block S (see lbvh_render.comp).
// accumulation_parts: x pixels per part of the accumulation (0xffffffff when one part holds
// the image), y 1 on a frame that starts the accumulation (the pixel is stored, not added: the
// host does not clear the sums first, so a pixel this kernel missed would keep what was there),
// zw unused.
layout(std140, set = 0, binding = 9) uniform TilingBlock {
    uvec4 tiling;
    uvec4 accumulation_parts;
};
// Particles, nodes and boxes, each in up to SPLIT_PARTS parts (bindings 10..21).
#include "wgpu/split.glsl"
#include "wgpu/split_tree.glsl"
// The accumulation in up to SPLIT_PARTS parts, as in lbvh_render.comp: adds c to pixel i's
// sums, or stores it on a first frame.
#split_array accumulation 22 vec4 readwrite accumulation_parts.x add:accumulate set:store_first


#include "shared/maps.glsl"

float radius_attribute(uint i) {
    return radius_attributes[i];
}

float particle_volume(uint i) {
    return radius_attributes[field_params.factors.x + i];
}

#include "shared/rbf.glsl"
#include "shared/shade.glsl"
#include "shared/splat.glsl"
#include "shared/lbvh.glsl"
#include "shared/lbvh_splat.glsl"

void splat_slab(vec3 origin, vec3 dir, float lo, float hi) {
    lbvh_splat_slab(origin, dir, lo, hi);
}

#include "shared/splat_pixel.glsl"

void main() {
    // The same tile order as lbvh_render.comp (consecutive workgroups in different bands of
    // the image, which balances lavapipe's threads).
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
    vec4 c = splat_pixel(pixel);
    if (accumulation_parts.y == 1u) {
        store_first(i, c);
    } else {
        accumulate(i, c);
    }
}
