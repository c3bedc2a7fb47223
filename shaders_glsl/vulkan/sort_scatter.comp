#version 460
// Radix sort pass 3 (ash): the stable scatter (vulkan/radix_sort.glsl).
#include "vulkan/radix_sort.glsl"

layout(local_size_x = 128) in;

shared uint offsets[SORT_RADIX * THREADS]; // digit-major

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tile = gl_WorkGroupID.x; // one workgroup per tile, a 1D launch
    if (tile >= push.tiles) {
        return;
    }
    Words keys_in = Words(push.a0);
    Words values_in = Words(push.a1);
    Words keys_out = Words(push.a2);
    Words values_out = Words(push.a3);
    Words histogram = Words(push.a4);
    uint start = tile * SORT_TILE + lid * ITEMS;
    uint end = min(start + ITEMS, push.count);
    uint local_counts[SORT_RADIX];
    for (uint d = 0u; d < SORT_RADIX; d++) {
        local_counts[d] = 0u;
    }
    for (uint i = start; i < end; i++) {
        local_counts[digit(keys_in.v[i])] += 1u;
    }
    for (uint d = 0u; d < SORT_RADIX; d++) {
        offsets[d * THREADS + lid] = local_counts[d];
    }
    barrier();
    uint sum = 0u;
    for (uint k = 0u; k < SORT_RADIX; k++) {
        sum += offsets[lid * SORT_RADIX + k];
    }
    uint running = exclusive_scan(lid, sum, THREADS);
    for (uint k = 0u; k < SORT_RADIX; k++) {
        uint v = offsets[lid * SORT_RADIX + k];
        offsets[lid * SORT_RADIX + k] = running;
        running += v;
    }
    barrier();
    uint dest[SORT_RADIX];
    for (uint d = 0u; d < SORT_RADIX; d++) {
        dest[d] = histogram.v[d * push.tiles + tile] + offsets[d * THREADS + lid] - offsets[d * THREADS];
    }
    for (uint i = start; i < end; i++) {
        uint key = keys_in.v[i];
        uint d = digit(key);
        keys_out.v[dest[d]] = key;
        values_out.v[dest[d]] = values_in.v[i];
        dest[d] += 1u;
    }
}
