#version 450
// Field queries: (Phi, Theta numerator) at each query point (local coordinates), by the
// shared LBVH traversal. Twin: ReferenceField::eval_sums (f64). With double-single positions
// each query is two vec4s, hi then lo.
// twin: src/field/reference.rs: ReferenceField::eval_sums, the f64 field every backend is held to (tests/wgpu_lbvh.rs)

layout(local_size_x = 64) in;

#include "shared/params.glsl"

// x: queries, y: workgroups of 64 queries, z: blocks B, w: workgroups per block S.
layout(std140, set = 0, binding = 0) uniform QueryBlock { uvec4 query_count; };
layout(std140, set = 0, binding = 1) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 4) readonly buffer RadiusAttributes { float radius_attributes[]; };
layout(std430, set = 0, binding = 7) readonly buffer QueryPoints { vec4 query_points[]; };
layout(std430, set = 0, binding = 8) buffer QueryResults { vec4 query_results[]; };
// Particles, nodes and boxes, each in up to SPLIT_PARTS parts (bindings 10..21).
#include "wgpu/split.glsl"
#include "wgpu/split_tree.glsl"

#include "shared/maps.glsl"

float radius_attribute(uint i) {
    return radius_attributes[i];
}

float particle_volume(uint i) {
    return radius_attributes[field_params.factors.x + i];
}

#include "shared/rbf.glsl"
#include "shared/lbvh.glsl"

void main() {
    // Workgroup g takes the queries of group (g mod B) S + g / B, so each of lavapipe's threads
    // (one contiguous range of workgroups each) gets a share of every part of the (Hilbert-
    // sorted) queries rather than one region of space.
    uint g = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
    uint group = (g % query_count.z) * query_count.w + g / query_count.z;
    uint i = group * 64u + gl_LocalInvocationID.x;
    if (group >= query_count.y || i >= query_count.x) {
        return;
    }
    if (POSITION_DS == 1u) {
        query_results[i] = lbvh_field(query_points[2u * i].xyz, query_points[2u * i + 1u].xyz);
    } else {
        query_results[i] = lbvh_field(query_points[i].xyz, vec3(0.0));
    }
}
