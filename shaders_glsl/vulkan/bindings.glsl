// The ash backend's descriptor bindings (set 0) and push constants, shared by its ray-tracing
// stages and compute kernels; src/backend/ash_rt/pipelines.rs (`binding`, `Push`) creates the
// matching layout. Including this file also includes the shared parameter, map, noise and RBF
// code in the order their headers ask for.
//
// Binding 0 (the TLAS) is declared by the ray-generation shaders only, and bindings 6..11 by
// the kernels that use them.

#include "shared/params.glsl"

layout(std140, set = 0, binding = 1) uniform Params {
    Frame frame;
    Field field_params;
};

// Per particle, in Hilbert order: xyz local position, w the normalised attribute t. (Named
// as shared/lbvh.glsl expects it.)
layout(std430, set = 0, binding = 2) readonly buffer Particles { vec4 particles[]; };
// Per particle: the radius attribute h (read only when HAS_RADIUS_ATTRIBUTE is 1).
layout(std430, set = 0, binding = 3) readonly buffer RadiusAttribute { float radius_attr[]; };
layout(std430, set = 0, binding = 4) readonly buffer MapTables { float map_tables[]; };

const uint STBN_WIDTH = 128u;
const uint STBN_HEIGHT = 128u;
const uint STBN_DEPTH = 64u;
layout(std430, set = 0, binding = 5) readonly buffer StbnMask { uint stbn_words[]; };

layout(push_constant) uniform Push {
    uint count;        // items to process (queries, boxes)
    uint width;        // row width of a 2D launch over a 1D array
    uint first_frame;  // 1: the frame replaces the accumulation
    uint unused;
} push;

float radius_attribute(uint particle) {
    return radius_attr[particle];
}

#include "shared/maps.glsl"
#include "shared/noise.glsl"
#include "shared/rbf.glsl"
