// The ash backend's stable LSD radix sort of (key, value) pairs: shaders_wgsl/radix_sort.wgsl
// in GLSL, the same tiles, digits, histogram layout and scans (its comment explains them);
// sort_count.comp, sort_scan.comp and sort_scatter.comp are its three passes. Arrays: a0 the
// keys in, a1 the values in, a2 the keys out, a3 the values out, a4 the histogram. Twin:
// backend/shaders/cpu/radix_sort.rs.
#include "vulkan/prepare.glsl"

const uint THREADS = 128u;
const uint ITEMS = SORT_TILE / THREADS;
const uint SCAN_THREADS = 256u;

shared uint sums[SCAN_THREADS];

// The sum of `value` over threads 0 .. lid - 1 of the first `threads` (Hillis-Steele);
// every thread of the workgroup calls it with the same `threads`.
uint exclusive_scan(uint lid, uint value, uint threads) {
    sums[lid] = value;
    barrier();
    for (uint step = 1u; step < threads; step <<= 1u) {
        uint v = sums[lid];
        if (lid >= step) {
            v += sums[lid - step];
        }
        barrier();
        sums[lid] = v;
        barrier();
    }
    return lid > 0u ? sums[lid - 1u] : 0u;
}

uint digit(uint key) {
    return (key >> push.shift) & (SORT_RADIX - 1u);
}
