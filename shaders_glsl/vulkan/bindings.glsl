// The ash backend's descriptor bindings (set 0) and push constants, shared by its ray-tracing
// stages and compute kernels; src/backend/ash_rt/pipelines.rs (`binding`, `Push`) creates the
// matching layout. Including this file also includes the shared parameter, map, noise and RBF
// code in the order their headers ask for.
//
// Binding 0 (the TLAS) is declared by the ray-generation shaders only, and bindings 7..11 by
// the kernels that use them.
//
// The per-particle and per-box arrays and the image's accumulation are reached by device
// address (push constants), not through descriptors: a binding is capped at
// maxStorageBufferRange (128 MiB on lavapipe: 8M particles, or a 4K image's f32 RGBA sums), an
// address only by the allocation, so a step or image larger than one binding is still one
// buffer and one index space. Ray tracing needs bufferDeviceAddress anyway.

#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require

#include "shared/params.glsl"

layout(std140, set = 0, binding = 1) uniform Params {
    Frame frame;
    Field field_params;
    Voxels voxels;  // the voxel baseline's grid (voxel_splat.comp, voxel_render.comp)
};

layout(std430, set = 0, binding = 4) readonly buffer MapTables { float map_tables[]; };

// Per particle, in Hilbert order: xyz local position, w the normalised attribute t.
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer ParticleArray {
    vec4 v[];
};
// Per pixel: the accumulated f32 RGBA sums (the render kernels' `accum`).
layout(buffer_reference, std430, buffer_reference_align = 16) buffer Vec4Array {
    vec4 v[];
};
// Per particle: the radius attribute h (read only when HAS_RADIUS_ATTRIBUTE is 1).
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer FloatArray {
    float v[];
};

layout(std430, set = 0, binding = 5) readonly buffer StbnMask { uint stbn_words[]; };

layout(push_constant) uniform Push {
    uint count;        // items to process (queries, boxes)
    uint width;        // row width of a 2D launch over a 1D array
    uint first_frame;  // 1: the frame replaces the accumulation
    uint query_lo;     // 1: a query launch whose points carry lo parts (POSITION_DS)
    uvec2 particle_address;     // ParticleArray of the step
    uvec2 radius_address;       // FloatArray of radius attributes, then SPH volumes (0 when neither)
    uvec2 boxes_address;        // the BLAS input boxes, 6 floats each (blas_boxes.comp writes them)
    uvec2 accum_address;        // Vec4Array: the frame's f32 RGBA sums per pixel
    uvec2 particle_lo_address;  // ParticleArray of the lo parts (POSITION_DS; else 0)
    uvec2 voxel_address;        // the voxel baseline's grid: 4 f32 sums per cell (else 0)
    uvec2 owned_address;        // a brick kernel's brick, output and inputs (lbvh_owned.comp; else 0)
} push;

// Query points (query launches): one vec4 each, or with double-single positions two, hi then
// lo; the intersection stage reads the lo part of its launch's point here.
layout(std430, set = 0, binding = 7) readonly buffer QueryPoints { vec4 query_points[]; };

// `particles[i]`, as shared/lbvh.glsl and the RT stages index it.
#define particles (ParticleArray(push.particle_address).v)
// `accum[i]`, pixel i's sums, as the render kernels index them.
#define accum (Vec4Array(push.accum_address).v)

vec4 particle(uint k) {
    return particles[k];
}

vec4 particle_lo(uint k) {
    return ParticleArray(push.particle_lo_address).v[k];
}

float radius_attribute(uint k) {
    return FloatArray(push.radius_address).v[k];
}

float particle_volume(uint k) {
    return FloatArray(push.radius_address).v[field_params.factors.x + k];
}

#include "shared/maps.glsl"
#include "shared/noise.glsl"
#include "shared/rbf.glsl"
#include "shared/cluster_box.glsl"

// The field query's ray payload: a point's sum (Phi, Theta numerator) and its compensation
// (sum_add in rbf.glsl; zero unless COMPENSATED_SUM).
struct FieldPayload {
    vec4 sum;
    vec4 comp;
};
