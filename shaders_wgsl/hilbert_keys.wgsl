// Preparing a step on the device, stage 1: each particle's 63-bit Hilbert key, from the f32
// local coordinates the host staged in the step's order, as two words (low 32 bits, high 31),
// and the identity permutation the sort carries along. The cell is (p - grid_lo) * grid_scale,
// clamped and truncated: a subtraction and a multiplication, both correctly rounded in WGSL,
// so the key is the CPU's bit for bit (accel::HilbertQuantizer::key_of_local). The table walk
// is accel::hilbert's state machine one level a step (the CPU takes two levels a lookup
// through a table derived from this one: the same curve). Twin:
// backend/shaders/cpu/hilbert_keys.rs.

#include "shared/prepare_params.wgsl"

@group(0) @binding(1) var<storage, read_write> keys_lo: array<u32>;
@group(0) @binding(2) var<storage, read_write> keys_hi: array<u32>;
@group(0) @binding(3) var<storage, read_write> values: array<u32>;
#split_array raw_points 10 vec4<f32> read params.part_vec4s get:raw_point

// In private memory: a module-scope constant array indexed at run time would be copied into
// a local variable at every access.
var<private> hilbert_step: array<u32, 192> = HILBERT_STEP;

@compute @workgroup_size(64)
fn main(id: Invocation) {
    let i = thread_index(id);
    if i >= params.count {
        return;
    }
    let p = raw_point(i).xyz;
    let top = f32((1u << HILBERT_BITS) - 1u);
    let q = clamp((p - params.grid_lo.xyz) * params.grid_scale.xyz, vec3<f32>(0.0), vec3<f32>(top));
    let cell = vec3<u32>(q);
    var state = 0u;
    var lo = 0u;
    var hi = 0u;
    for (var level = HILBERT_BITS; level > 0u; level--) {
        let b = level - 1u;
        let octant = (((cell.x >> b) & 1u) << 2u) | (((cell.y >> b) & 1u) << 1u) | ((cell.z >> b) & 1u);
        let e = hilbert_step[state * 8u + octant];
        hi = (hi << 3u) | (lo >> 29u);
        lo = (lo << 3u) | (e & 7u);
        state = e >> 3u;
    }
    keys_lo[i] = lo;
    keys_hi[i] = hi;
    values[i] = i;
}
