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
// The `#split_array` lines (expanded by src/backend/shaders/include.rs, which writes the part
// selection once for every array and both languages) declare the parts and their accessors.
// The includer declares field_params (params.glsl's Field) first. This file declares the
// particle parts; wgpu/split_tree.glsl the nodes and boxes, read-only (the bounds kernel,
// which writes the boxes, declares its own).

// Particle k: xyz local position, w the normalised attribute.
#split_array particles 10 vec4 readonly field_params.counts.z get:particle
// Particle k's lo part with double-single positions (POSITION_DS; rbf.glsl): xyz, w unused.
#split_array particle_los 26 vec4 readonly field_params.counts.z get:particle_lo
