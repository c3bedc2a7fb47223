#version 460
// A brick's share of a distributed frame (Backend::render_owned), or its optical depth along
// primary or light map rays (Backend::owned_depth), as brick.task.x says: the shared
// integrators' OWNED_BRICK functions with the LBVH traversal as the field query, one thread
// per pixel (texel) of brick.rect, written to the brick's output (nothing is accumulated).
// Its own kernel, so a whole frame (render.rgen, lbvh_render.comp) carries none of it.
// twin: src/backend/cpu/owned.rs: the CPU backend renders the same share (tests/gpu_bricks.rs compares them)
#include "vulkan/bindings.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#include "vulkan/lbvh.glsl"

// The brick, then its output (one vec4 per pixel of brick.rect, row-major), then its inputs
// (floats packed four to a vec4 from brick.task.z), by device address (push.owned_address).
layout(buffer_reference, std430, buffer_reference_align = 16) buffer BrickIo {
    Brick brick;
    vec4 io[];
};
#define brick_io (BrickIo(push.owned_address).io)
#define brick (BrickIo(push.owned_address).brick)

float brick_input(uint j) {
    return brick_io[brick.task.z + j / 4u][j % 4u];
}

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
