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

// A brick's share of a distributed frame (the brick kernels, `lbvh_owned.comp`; the Rust twin
// is `GpuBrick` in src/backend/shaders/mod.rs, which says how it is made from a BrickShare or
// DepthRays). Positions are local coordinates, as the Frame's; a half-open box's infinite
// faces stay infinite (f32 inf), which the comparisons of owned_contains take as they are.
struct Brick {
    vec4 owned_lo;     // xyz the half-open box's least corner (may be -inf); w unused
    vec4 owned_hi;     // xyz its largest corner (may be +inf); w unused
    vec4 clip_lo;      // xyz the closed box within the march box (shadow rays' exit, delta
                       // tracking's segment); w unused
    vec4 clip_hi;
    vec4 march_lo;     // xyz the clipped box grown by a step: the part of a ray that is marched
                       // (clip_to_owned); w unused
    vec4 march_hi;
    uvec4 rect;        // x0, y0, x1, y1: the pixels (or light map texels) written, row-major
    uvec4 task;        // x OWNED_TASK_*; y 1 when a depth in front is given (first in the
                       // inputs, one per pixel of rect); z where the inputs start (vec4s into
                       // the output array); w unused
    uvec4 prefix;      // x0, y0, x1, y1: the light prefix's texels (empty: local shadows)
    uvec4 prefix_at;   // x the prefix's first float in the inputs; yzw unused
    vec4 light_centre; // the light map (LightMap): xyz its centre; w how far behind it rays start
    vec4 light_u;      // xyz the texel columns' axis; w the map's least u
    vec4 light_v;      // xyz the rows' axis; w the map's least v
    vec4 light_dir;    // xyz towards the light; w unused
    vec4 light_texel;  // x, y a texel's width along u and v; zw unused
    vec4 depth_stop;   // x the depth past which an occluding depth pass's rays stop; yzw unused
};
