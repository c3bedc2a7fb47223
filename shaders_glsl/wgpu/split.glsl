// The wgpu kernels' arrays of 16-byte elements that can outgrow one storage-buffer binding
// (128 MiB on lavapipe: 8M particles, 4M clusters). Each kernel is compiled twice, with
// SPLIT_PARTS defined by the host (src/backend/wgpu_lbvh/context.rs):
//   1: each array is one buffer at its first binding and the accessors index it directly.
//      This is the variant every step that fits a binding runs, so the part selection costs
//      it nothing (measured on lavapipe, even a uniform compare in the per-particle loop cost
//      ~20% of the query rate at K >= 4: llvmpipe runs both arms of a branch under a mask),
//      and the kernels bind at most 8 storage buffers, WebGPU's default per-stage limit.
//   4: each array lives in 4 parts (its own wgpu buffers, each at most one binding) at
//      consecutive bindings, read through an accessor that picks the part. The host
//      (src/backend/wgpu_lbvh/util.rs, SplitBuffer) puts the part lengths, in vec4s, in
//      field_params.counts.zw:
//        z: particles per part   (bindings 10..13)
//        w: vec4s per part of the LBVH nodes (bindings 14..17) and of the cluster boxes
//           (18..21); both have 32 bytes per cluster, so their parts have the same length.
//      An array that one part holds has length 0xffffffff (every branch below then takes its
//      first arm) and tiny placeholder buffers for its other parts.
//
// The includer declares field_params (params.glsl's Field) first. This file declares the
// particle parts; wgpu/split_tree.glsl the nodes and boxes, read-only (the bounds kernel,
// which writes the boxes, declares its own).

layout(std430, set = 0, binding = 10) readonly buffer Particles0 { vec4 particles0[]; };
#if SPLIT_PARTS > 1
layout(std430, set = 0, binding = 11) readonly buffer Particles1 { vec4 particles1[]; };
layout(std430, set = 0, binding = 12) readonly buffer Particles2 { vec4 particles2[]; };
layout(std430, set = 0, binding = 13) readonly buffer Particles3 { vec4 particles3[]; };
#endif

// Particle k: xyz local position, w the normalised attribute.
vec4 lbvh_particle(uint k) {
#if SPLIT_PARTS > 1
    uint len = field_params.counts.z;
    if (k < len) {
        return particles0[k];
    }
    k -= len;
    if (k < len) {
        return particles1[k];
    }
    k -= len;
    if (k < len) {
        return particles2[k];
    }
    return particles3[k - len];
#else
    return particles0[k];
#endif
}
