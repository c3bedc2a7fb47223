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
    vec4 shading;    // x = Phi_ref, y = density scale, z = majorant, w unused
    uvec4 image;     // width, height, frame number, seed
};

struct Field {
    vec4 radius;     // x = global radius R, y = the radius map's value if constant,
                     // z = the density map's value if constant, w unused
    uvec4 counts;    // x = particles, y = clusters, zw: the wgpu backend's part lengths
                     // (wgpu/split.glsl; unused by the Vulkan kernels)
};

// Specialisation constants (wgpu: pipeline overrides; Vulkan: VkSpecializationInfo): one
// shader source, a variant per used feature, and no runtime branch over an unused one.
layout(constant_id = 0) const uint INTEGRATOR = 0u;        // 0 EA, 1 delta, 2 marching, 3 SS reference
layout(constant_id = 1) const uint COLOUR_MODE = 0u;       // 0 post, 1 pre, 2 density
layout(constant_id = 2) const uint NOISE_KIND = 0u;        // 0 STBN, 1 white
layout(constant_id = 3) const uint CLUSTER_SIZE = 1u;      // particles per box: 1, 2, 4, 8, 16
layout(constant_id = 4) const uint RADIUS_MAP_VARIES = 0u; // 1: look the radius map up per particle
layout(constant_id = 5) const uint DENSITY_MAP_VARIES = 0u;// 1: look the density map up per particle
layout(constant_id = 6) const uint HAS_RADIUS_ATTRIBUTE = 0u; // 1: per-particle radius buffer

const uint INTEGRATOR_EA = 0u;
const uint INTEGRATOR_DELTA = 1u;
const uint INTEGRATOR_MARCHING = 2u;
const uint INTEGRATOR_SS_REFERENCE = 3u;
const uint COLOUR_POST = 0u;
const uint COLOUR_PRE = 1u;
const uint COLOUR_DENSITY = 2u;
