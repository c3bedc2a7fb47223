// The constants every GPU kernel reads: the GLSL twin of values::FrameParams and
// of the field settings, laid out as src/backend/shaders/mod.rs's `GpuFrame` / `GpuField` (std140 and
// std430 agree on this all-vec4 layout). Positions are in local coordinates: the data's
// coordinates minus the series' bounding-box centre, so f32 keeps its digits far from the
// origin.

struct Frame {
    vec4 eye;        // xyz camera position
    vec4 forward;    // xyz unit view direction
    vec4 right;      // xyz, scaled by tan(fovy / 2) * aspect
    vec4 up;         // xyz, scaled by tan(fovy / 2)
    vec4 box_min;    // xyz march box; w = dt (march step)
    vec4 box_max;    // xyz march box; w = opacity threshold
    vec4 light;      // xyz unit vector towards the light; w = intensity
    vec4 background; // rgb; w = ambient light
    vec4 shading;    // x = Phi_ref, y = density scale, z = majorant, w = the splatter's hits
                     // per slab (splat kernels only; splat.glsl)
    uvec4 image;     // width, height, frame number, seed
};

struct Field {
    vec4 radius;     // x = global radius R, y = the radius map's value if constant,
                     // z = the density map's value if constant, w unused
    uvec4 counts;    // x = particles, y = clusters, zw: the wgpu backend's part lengths
                     // (wgpu/split.glsl; unused by the Vulkan kernels)
};

// The shared constants, with the specialisation constants (wgpu: pipeline overrides; Vulkan:
// VkSpecializationInfo): one shader source, a variant per used feature, and no runtime branch
// over an unused one. Generated from src/values/shader_constants.rs.
#include "generated/constants.glsl"
