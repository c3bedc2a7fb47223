#version 460
// A brick's share of a distributed frame (Backend::render_owned), or its optical depth along
// primary or light map rays (Backend::owned_depth), as brick.task.x says: the shared
// integrators' OWNED_BRICK functions with the LBVH traversal as the field query (the software
// side; owned.rgen is the RT pipeline's), one thread per pixel (texel) of brick.rect, written
// to the brick's output (nothing is accumulated). Its own kernel, so a whole frame
// (render.rgen, lbvh_render.comp) carries none of it.
// twin: src/backend/cpu/owned.rs: the CPU backend renders the same share (tests/gpu_bricks.rs compares them)
#include "vulkan/bindings.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#include "vulkan/lbvh.glsl"

// The integrators' samples are f32 points (their lo part is 0).
vec4 field_query(vec3 x) {
    return lbvh_field(x, vec3(0.0));
}

#include "vulkan/brick_io.glsl"

void main() {
    write_owned(gl_GlobalInvocationID.xy);
}
