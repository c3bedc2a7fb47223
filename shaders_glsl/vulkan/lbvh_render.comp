#version 460
// One frame of the shared integrators with the LBVH traversal as the field query (the
// software side of Fig. 10a on the same device; render.rgen is the hardware side). Added into
// the same accumulation buffer.
// twin: src/backend/cpu/integrators.rs: the CPU backend renders the same frame (tests/ash_rt.rs compares the images)
#include "vulkan/bindings.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#include "vulkan/lbvh.glsl"

// The integrators' samples are f32 points (their lo part is 0).
vec4 field_query(vec3 x) {
    return lbvh_field(x, vec3(0.0));
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
