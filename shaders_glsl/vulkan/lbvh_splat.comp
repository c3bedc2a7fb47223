#version 460
// One frame of Knoll et al.'s splatter with the LBVH traversal of each slab (the software side
// of the same device's comparison, as lbvh_render.comp is for the RBF renderer; splat.rgen is
// the RT side). Added into the same accumulation buffer. CPU twin:
// backend::cpu::splat::splat_pixel.
// twin: src/backend/cpu/splat.rs: the CPU backend splats the same frame (tests/splat_ash.rs compares the images)
#include "vulkan/bindings.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#include "vulkan/lbvh.glsl"
#include "shared/shade.glsl"
#include "shared/splat.glsl"
#include "shared/lbvh_splat.glsl"

void splat_slab(vec3 origin, vec3 dir, float lo, float hi) {
    lbvh_splat_slab(origin, dir, lo, hi);
}

#include "shared/splat_pixel.glsl"

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= frame.image.x || pixel.y >= frame.image.y) {
        return;
    }
    vec4 c = splat_pixel(pixel);
    uint i = pixel.y * frame.image.x + pixel.x;
    accum[i] = (push.first_frame == 1u) ? c : accum[i] + c;
}
