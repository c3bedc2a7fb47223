#version 450
// One frame of the shared integrators over the LBVH field, added to the accumulation (sums of
// linear RGBA; the host divides by the frame count). Twin: backend::cpu::integrators::render_pixel.
// twin: src/backend/cpu/integrators.rs: the CPU backend renders the same frame (tests/wgpu_render.rs compares the images)

layout(local_size_x = 8, local_size_y = 8) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform FrameBlock { Frame frame; };
layout(std140, set = 0, binding = 1) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 4) readonly buffer RadiusAttributes { float radius_attributes[]; };
layout(std430, set = 0, binding = 7) readonly buffer StbnMask { uint stbn_words[]; };
// tiling: x 8x8 tiles per row, y tiles, z blocks B, w tiles per block S (see main).
// accumulation_parts: x pixels per part of the accumulation (0xffffffff when one part holds
// the image; see accumulate), yzw unused.
layout(std140, set = 0, binding = 9) uniform TilingBlock {
    uvec4 tiling;
    uvec4 accumulation_parts;
};
// Particles, nodes and boxes, each in up to SPLIT_PARTS parts (bindings 10..21).
#include "wgpu/split.glsl"
#include "wgpu/split_tree.glsl"
// The accumulation (16 bytes per pixel: 8M pixels, a 4K image, fill lavapipe's 128 MiB
// binding) in up to SPLIT_PARTS parts, as split.glsl splits the particles.
// Adds c to pixel i's sums, in its part.
#split_array accumulation 22 vec4 readwrite accumulation_parts.x add:accumulate


#include "shared/maps.glsl"
#include "shared/noise.glsl"

float radius_attribute(uint i) {
    return radius_attributes[i];
}

float particle_volume(uint i) {
    return radius_attributes[field_params.factors.x + i];
}

#include "shared/rbf.glsl"
#include "shared/lbvh.glsl"

// The integrators' samples are f32 points (their lo part is 0).
vec4 field_query(vec3 x) {
    return lbvh_field(x, vec3(0.0));
}

#include "shared/integrators.glsl"

void main() {
    // Workgroup g renders tile (g mod B) S + g / B: consecutive workgroups fall in different
    // bands of the image. Lavapipe hands each thread one contiguous range of workgroups; without
    // this, one thread would get the top of the image and another the (often much busier)
    // bottom. Any order is the same image; other GPUs schedule dynamically and don't care.
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
