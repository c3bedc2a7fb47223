#version 460
// Radix sort pass 2 (ash): the exclusive scan of the whole histogram in one workgroup
// (vulkan/radix_sort.glsl).
#include "vulkan/radix_sort.glsl"

layout(local_size_x = 256) in;

void main() {
    uint lid = gl_LocalInvocationIndex;
    Words histogram = Words(push.a4);
    uint total = SORT_RADIX * push.tiles;
    uint per = (total + SCAN_THREADS - 1u) / SCAN_THREADS;
    uint start = min(lid * per, total);
    uint end = min(start + per, total);
    uint sum = 0u;
    for (uint i = start; i < end; i++) {
        sum += histogram.v[i];
    }
    uint running = exclusive_scan(lid, sum, SCAN_THREADS);
    for (uint i = start; i < end; i++) {
        uint h = histogram.v[i];
        histogram.v[i] = running;
        running += h;
    }
}
