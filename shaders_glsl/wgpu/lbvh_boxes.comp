#version 450
// The LBVH build's first stage (the paper's bounds kernel): one box per cluster by the shared
// cluster-box rule (shared/cluster_box.glsl); an empty cluster gets the empty box
// (+inf, -inf) and is left out of the tree. (This stage is GLSL rather than WGSL for that
// reason: one source for the rule and the radius; it needs no atomics.)
// Twin: backend/shaders/cpu/lbvh_boxes.rs.

layout(local_size_x = 64) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 2) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 3) readonly buffer RadiusAttributes { float radius_attributes[]; };
// The particles in up to SPLIT_PARTS parts (bindings 10..13), and the boxes likewise
// (18..21, the bindings split_tree.glsl reads them at): see wgpu/split.glsl.
#include "wgpu/split.glsl"
// Stores vec4 number v of the boxes in its part (split_tree.glsl's lbvh_box reads it back).
#split_array cluster_boxes 18 vec4 readwrite field_params.counts.w set:store_box

#include "shared/maps.glsl"

float radius_attribute(uint i) {
    return radius_attributes[i];
}

float particle_volume(uint i) {
    return radius_attributes[field_params.factors.x + i];
}

#include "shared/rbf.glsl"
#include "shared/cluster_box.glsl"

void main() {
    uint c = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64u + gl_LocalInvocationID.x;
    if (c >= field_params.counts.y) {
        return;
    }
    vec3 lo;
    vec3 hi;
    if (!cluster_box(c, lo, hi)) {
        float inf = uintBitsToFloat(0x7f800000u);
        lo = vec3(inf);
        hi = vec3(-inf);
    }
    store_box(2u * c, vec4(lo, 0.0));
    store_box(2u * c + 1u, vec4(hi, 0.0));
}
