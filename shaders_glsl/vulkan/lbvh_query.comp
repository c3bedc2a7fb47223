#version 460
// The software side of the paper's Fig. 10a on the same Vulkan device: field queries by the
// shared LBVH stack traversal (shared/lbvh.glsl, the wgpu backend's) instead of the RT
// pipeline, over the same particles, maps and RBF code. The tree is built on the CPU
// (backend::shaders::cpu, the wgpu build's twin) and uploaded.
// twin: src/field/reference.rs: ReferenceField::eval_sums, the f64 field every backend is held to (tests/ash_rt.rs)
#include "vulkan/bindings.glsl"

layout(local_size_x = 64) in;
layout(std430, set = 0, binding = 8) writeonly buffer QueryResults { vec4 query_results[]; };
#include "vulkan/lbvh.glsl"

void main() {
    uint i = gl_GlobalInvocationID.y * push.width + gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    if (POSITION_DS == 1u) {
        query_results[i] = lbvh_field(query_points[2u * i].xyz, query_points[2u * i + 1u].xyz);
    } else {
        query_results[i] = lbvh_field(query_points[i].xyz, vec3(0.0));
    }
}
