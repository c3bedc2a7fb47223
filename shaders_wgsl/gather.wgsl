// Preparing a step on the device: arrays put into the sorted order, element k of the output
// being element order[k] of the input. gather_words moves 4-byte elements in one binding (the
// sort's high key words between its two sorts, the radius attribute), gather_vec4s the split
// particle arrays (positions with t, their lo parts). Twin: backend/shaders/cpu/gather.rs.

#include "shared/prepare_params.wgsl"

@group(0) @binding(1) var<storage, read> order: array<u32>;
@group(0) @binding(2) var<storage, read> words_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> words_out: array<u32>;
#split_array vec4s_in 10 vec4<f32> read params.part_vec4s get:vec4_in
#split_array vec4s_out 14 vec4<f32> read_write params.part_vec4s set:vec4_out

@compute @workgroup_size(64)
fn gather_words(id: Invocation) {
    let k = thread_index(id);
    if k >= params.count {
        return;
    }
    words_out[k] = words_in[order[k]];
}

@compute @workgroup_size(64)
fn gather_vec4s(id: Invocation) {
    let k = thread_index(id);
    if k >= params.count {
        return;
    }
    vec4_out(k, vec4_in(order[k]));
}
