#version 460
// Radix sort pass 1 (ash): per-tile digit counts (vulkan/radix_sort.glsl).
#include "vulkan/radix_sort.glsl"

layout(local_size_x = 128) in;

shared uint tile_counts[SORT_RADIX];

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tile = gl_WorkGroupID.x; // one workgroup per tile, a 1D launch
    if (tile >= push.tiles) {
        return;
    }
    if (lid < SORT_RADIX) {
        tile_counts[lid] = 0u;
    }
    barrier();
    uint local_counts[SORT_RADIX];
    for (uint d = 0u; d < SORT_RADIX; d++) {
        local_counts[d] = 0u;
    }
    uint start = tile * SORT_TILE + lid * ITEMS;
    uint end = min(start + ITEMS, push.count);
    Words keys = Words(push.a0);
    for (uint i = start; i < end; i++) {
        local_counts[digit(keys.v[i])] += 1u;
    }
    for (uint d = 0u; d < SORT_RADIX; d++) {
        if (local_counts[d] != 0u) {
            atomicAdd(tile_counts[d], local_counts[d]);
        }
    }
    barrier();
    if (lid < SORT_RADIX) {
        Words(push.a4).v[lid * push.tiles + tile] = tile_counts[lid];
    }
}
