#version 450
// A brick's share of a distributed frame over the LBVH field (Backend::render_owned), or its
// optical depth along primary or light map rays (Backend::owned_depth), as brick.task.x says:
// the shared integrators' OWNED_BRICK functions, one thread per pixel (texel) of brick.rect,
// written to the brick's output (nothing is accumulated). Its own kernel, so a whole frame
// (lbvh_render.comp) carries none of it.
// twin: src/backend/cpu/owned.rs: the CPU backend renders the same share (tests/gpu_bricks.rs compares them)

layout(local_size_x = 8, local_size_y = 8) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform FrameBlock { Frame frame; };
layout(std140, set = 0, binding = 1) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 4) readonly buffer RadiusAttributes { float radius_attributes[]; };
layout(std430, set = 0, binding = 7) readonly buffer StbnMask { uint stbn_words[]; };
// Particles, nodes and boxes, each in up to SPLIT_PARTS parts (bindings 10..21, 26..29).
#include "wgpu/split.glsl"
#include "wgpu/split_tree.glsl"
// The brick, then its output (one vec4 per pixel of brick.rect, row-major), then its inputs
// (floats packed four to a vec4 from brick.task.z): one binding, so the kernel binds 8
// storage buffers, WebGPU's default per-stage limit.
layout(std430, set = 0, binding = 30) buffer BrickIo {
    Brick brick;
    vec4 brick_io[];
};

float brick_input(uint j) {
    return brick_io[brick.task.z + j / 4u][j % 4u];
}

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

#define OWNED_BRICK 1
#include "shared/integrators.glsl"

void main() {
    uvec4 r = brick.rect;
    uvec2 pixel = uvec2(r.xy) + gl_GlobalInvocationID.xy;
    if (pixel.x >= r.z || pixel.y >= r.w) {
        return;
    }
    uint i = (pixel.y - r.y) * (r.z - r.x) + (pixel.x - r.x);
    if (brick.task.x == OWNED_TASK_RENDER) {
        brick_io[i] = render_owned_pixel(pixel);
    } else {
        brick_io[i] = vec4(owned_depth_ray(pixel), 0.0, 0.0, 0.0);
    }
}
