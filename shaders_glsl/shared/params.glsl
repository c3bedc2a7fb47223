// The constants every GPU kernel reads: the GLSL twin of values::FrameParams and
// of the field settings, laid out as src/backend/shaders/mod.rs's `GpuFrame` / `GpuField` (std140 and
// std430 agree on this all-vec4 layout). Positions are in local coordinates: the data's
// coordinates minus the series' bounding-box centre, so f32 keeps its digits far from the
// origin.

struct Frame {
    vec4 eye;        // xyz camera position
    vec4 forward;    // xyz view direction at the image centre (unit except on a half lattice)
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
    uvec4 factors;   // x = where an SPH kernel's volumes start in the radius-attribute
                     // buffer (floats; after the radius attribute's section); yzw unused
};

// The shared constants, with the specialisation constants (wgpu: pipeline overrides; Vulkan:
// VkSpecializationInfo): one shader source, a variant per used feature, and no runtime branch
// over an unused one. Generated from src/values/shader_constants.rs.
#include "generated/constants.glsl"

// The voxel-grid baseline's grid (src/backend/voxel.rs; the Rust twin is `GpuVoxels` in
// src/backend/shaders/mod.rs, and shaders_wgsl/voxel_splat.wgsl declares the same struct).
struct Voxels {
    vec4 origin;     // xyz the first cell's centre, local coordinates (the hi part with
                     // double-single positions); w unused
    vec4 origin_lo;  // xyz the lo part of origin (double-single positions; else 0); w unused
    vec4 cell;       // xyz the cell size; w unused
    uvec4 dims;      // xyz cells per axis; w cells per row of the splat's slab buffer (dims.x
                     // rounded up for the row alignment of buffer-to-texture copies)
    uvec4 range;     // the splat's pass: x first particle, y particles, z the slab's first
                     // layer (z), w its layers
    uvec4 channels;  // x the sums each cell receives: 1 (Phi), 2 (and a scalar Theta
                     // numerator) or 4 (and an RGB one); yzw unused
};
