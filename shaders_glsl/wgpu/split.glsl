// The wgpu kernels' arrays of 16-byte elements that can outgrow one storage-buffer binding
// (128 MiB on lavapipe: 8M particles, 4M clusters): each lives in SPLIT_PARTS = 4 parts (its
// own wgpu buffers, each at most one binding) at consecutive bindings, and is read through an
// accessor that picks the part. The host (src/backend/wgpu_lbvh/util.rs, SplitBuffer) puts
// the part lengths, in vec4s, in field_params.counts.zw:
//     z: particles per part   (bindings 10..13)
//     w: vec4s per part of the LBVH nodes (bindings 14..17) and of the cluster boxes (18..21);
//        both have 32 bytes per cluster, so their parts have the same length.
// When one part holds a whole array its length is 0xffffffff (every branch below then takes
// its first arm) and the unused parts are tiny placeholder buffers. When no array a kernel
// reads is split, the host also sets SPLIT_ARRAYS to 0, and the part selection compiles away:
// measured on lavapipe, the runtime compare alone (uniform as it is) cost ~20% of the query
// rate at K >= 4, where it sits in the per-particle loop, since llvmpipe runs both arms of a
// branch under a mask.
layout(constant_id = 7) const uint SPLIT_ARRAYS = 1u;
//
// The includer declares field_params (params.glsl's Field) first. This file declares the
// particle parts; wgpu/split_tree.glsl the nodes and boxes, read-only (the bounds kernel,
// which writes the boxes, declares its own).

layout(std430, set = 0, binding = 10) readonly buffer Particles0 { vec4 particles0[]; };
layout(std430, set = 0, binding = 11) readonly buffer Particles1 { vec4 particles1[]; };
layout(std430, set = 0, binding = 12) readonly buffer Particles2 { vec4 particles2[]; };
layout(std430, set = 0, binding = 13) readonly buffer Particles3 { vec4 particles3[]; };

// Particle k: xyz local position, w the normalised attribute.
vec4 lbvh_particle(uint k) {
    uint len = field_params.counts.z;
    if (SPLIT_ARRAYS == 0u || k < len) {
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
}

