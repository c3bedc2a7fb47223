#version 460
// One AABB per cluster by the shared cluster-box rule (shared/cluster_box.glsl), written as
// VkAabbPositionsKHR (6 floats) for the BLAS build. Twin: accel::clusters::cluster_box (f32).
//
// - Clusters past the step's particles (the buffer holds the series' maximum) get NaN boxes,
//   Vulkan's inactive primitives. The BLAS build takes only the step's clusters anyway
//   (lavapipe does not treat NaN boxes as inactive; see src/backend/ash_rt/structure.rs), so
//   the NaN tail only keeps a previous step's boxes out of the buffer.
// - A cluster whose particles all have radius 0 gets a degenerate box (min = max = its first
//   particle's centre), never NaN: it stays active, so a later radius change can refit it
//   (an update may not turn an inactive primitive active). The intersection shader reports
//   nothing for radius 0, so the box adds no term.
#include "vulkan/bindings.glsl"

layout(local_size_x = 64) in;
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer BoxArray {
    float v[];
};

void main() {
    uint c = gl_GlobalInvocationID.y * push.width + gl_GlobalInvocationID.x;
    if (c >= push.count) {
        return;
    }
    uint first = c * CLUSTER_SIZE;
    vec3 lo = vec3(uintBitsToFloat(0x7fc00000u));
    vec3 hi = lo;
    if (first < field_params.counts.x && !cluster_box(c, lo, hi)) {
        lo = particle(first).xyz;
        hi = lo;
    }
    BoxArray boxes = BoxArray(push.boxes_address);
    boxes.v[6u * c + 0u] = lo.x;
    boxes.v[6u * c + 1u] = lo.y;
    boxes.v[6u * c + 2u] = lo.z;
    boxes.v[6u * c + 3u] = hi.x;
    boxes.v[6u * c + 4u] = hi.y;
    boxes.v[6u * c + 5u] = hi.z;
}
