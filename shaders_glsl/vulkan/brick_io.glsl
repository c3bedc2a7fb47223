// A brick kernel's one buffer on the ash backend (lbvh_owned.comp, owned.rgen), by device
// address (push.owned_address): the brick (params.glsl's Brick), then its output (one vec4 per
// pixel of brick.rect, row-major), then its inputs (floats packed four to a vec4 from
// brick.task.z); and the launch's work for one invocation. Include after vulkan/bindings.glsl
// and the includer's field_query; it includes the shared integrators' OWNED_BRICK variant.

layout(buffer_reference, std430, buffer_reference_align = 16) buffer BrickIo {
    Brick brick;
    vec4 io[];
};
#define brick_io (BrickIo(push.owned_address).io)
#define brick (BrickIo(push.owned_address).brick)

float brick_input(uint j) {
    return brick_io[brick.task.z + j / 4u][j % 4u];
}

#define OWNED_BRICK 1
#include "shared/integrators.glsl"

// The launch's invocation `id` (from the rectangle's first pixel): its pixel's share, or its
// ray's optical depth, written to the output.
void write_owned(uvec2 id) {
    uvec4 r = brick.rect;
    uvec2 pixel = uvec2(r.xy) + id;
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
