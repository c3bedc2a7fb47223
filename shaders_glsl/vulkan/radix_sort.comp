#version 460
// The ash backend's stable LSD radix sort of (key, value) pairs: shaders_wgsl/radix_sort.wgsl
// in GLSL, the same tiles, digits, histogram layout and scans (its comment explains them),
// and the same three passes as entry points: count, scan and scatter (build.rs compiles the
// file once per `#ifdef ENTRY_<name>` block, with that name defined). Arrays: a0 the keys in,
// a1 the values in, a2 the keys out, a3 the values out, a4 the histogram. Twin:
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

#ifdef ENTRY_count
// Pass 1: per-tile digit counts.

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
#endif

#ifdef ENTRY_scan
// Pass 2: the exclusive scan of the whole histogram in one workgroup.

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
#endif

#ifdef ENTRY_scatter
// Pass 3: the stable scatter.

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
#endif
