// A stable LSD radix sort of (key, value) u32 pairs: 4-bit digits, one pass per digit, each
// pass three dispatches (count, scan, scatter). Portable: workgroup memory and barriers only,
// no subgroup operations, so it runs on lavapipe and every wgpu backend. Twin: a stable
// sort_by_key (backend/shaders/cpu/radix_sort.rs).
//
// A tile of SORT_TILE = THREADS * ITEMS keys belongs to one workgroup; thread t owns the ITEMS
// consecutive keys tile * SORT_TILE + t * ITEMS ... and walks them in order, so ranking within a
// tile is stable by construction (the keys of thread t precede those of thread t + 1).
// histogram[d * tiles + tile] counts digit d in a tile; its exclusive scan (digit-major) is
// where the tile's first key of digit d goes.

struct SortParams {
    count: u32,
    shift: u32,
    tiles: u32,
    pad: u32,
}

#include "generated/constants.wgsl"
#include "shared/invocation.wgsl"

// A tile of SORT_TILE = THREADS * ITEMS keys; SORT_RADIX digit values per 4-bit digit.
const THREADS: u32 = 128u;
const ITEMS: u32 = SORT_TILE / THREADS;
const SCAN_THREADS: u32 = 256u;

@group(0) @binding(0) var<uniform> params: SortParams;
@group(0) @binding(1) var<storage, read> keys_in: array<u32>;
@group(0) @binding(2) var<storage, read> values_in: array<u32>;
@group(0) @binding(3) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(4) var<storage, read_write> values_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> histogram: array<u32>;

var<workgroup> tile_counts: array<atomic<u32>, SORT_RADIX>;
var<workgroup> offsets: array<u32, SORT_RADIX * THREADS>; // digit-major
var<workgroup> sums: array<u32, SCAN_THREADS>;

// The sum of `value` over threads 0 .. lid - 1 of the first `threads` (a Hillis–Steele scan
// in `sums`); every thread of the workgroup calls it, with the same `threads`.
fn exclusive_scan(lid: u32, value: u32, threads: u32) -> u32 {
    sums[lid] = value;
    workgroupBarrier();
    for (var step = 1u; step < threads; step <<= 1u) {
        var v = sums[lid];
        if lid >= step {
            v += sums[lid - step];
        }
        workgroupBarrier();
        sums[lid] = v;
        workgroupBarrier();
    }
    var running = 0u;
    if lid > 0u {
        running = sums[lid - 1u];
    }
    return running;
}

fn digit(key: u32) -> u32 {
    return (key >> params.shift) & (SORT_RADIX - 1u);
}

// How often each digit occurs in thread lid's keys of the tile.
fn digit_counts(tile: u32, lid: u32) -> array<u32, SORT_RADIX> {
    var local: array<u32, SORT_RADIX>;
    let start = tile * SORT_TILE + lid * ITEMS;
    let end = min(start + ITEMS, params.count);
    for (var i = start; i < end; i++) {
        let d = digit(keys_in[i]);
        local[d] += 1u;
    }
    return local;
}

// Pass 1: per-tile digit counts.
@compute @workgroup_size(128)
fn count(id: Invocation) {
    let lid = id.lid;
    let tile = workgroup_index(id);
    if tile >= params.tiles {
        return;
    }
    if lid < SORT_RADIX {
        atomicStore(&tile_counts[lid], 0u);
    }
    workgroupBarrier();
    var local = digit_counts(tile, lid);
    for (var d = 0u; d < SORT_RADIX; d++) {
        if local[d] != 0u {
            atomicAdd(&tile_counts[d], local[d]);
        }
    }
    workgroupBarrier();
    if lid < SORT_RADIX {
        histogram[lid * params.tiles + tile] = atomicLoad(&tile_counts[lid]);
    }
}

// Pass 2: exclusive scan of the whole histogram, one workgroup: each thread scans a
// contiguous segment serially, the segments' totals are scanned in workgroup memory.
@compute @workgroup_size(256)
fn scan(@builtin(local_invocation_index) lid: u32) {
    let total = SORT_RADIX * params.tiles;
    let per = (total + SCAN_THREADS - 1u) / SCAN_THREADS;
    let start = min(lid * per, total);
    let end = min(start + per, total);
    var sum = 0u;
    for (var i = start; i < end; i++) {
        sum += histogram[i];
    }
    // The exclusive prefix of the 256 totals.
    var running = exclusive_scan(lid, sum, SCAN_THREADS);
    for (var i = start; i < end; i++) {
        let h = histogram[i];
        histogram[i] = running;
        running += h;
    }
}

// Pass 3: stable scatter.
@compute @workgroup_size(128)
fn scatter(id: Invocation) {
    let lid = id.lid;
    let tile = workgroup_index(id);
    if tile >= params.tiles {
        return;
    }
    var local = digit_counts(tile, lid);
    for (var d = 0u; d < SORT_RADIX; d++) {
        offsets[d * THREADS + lid] = local[d];
    }
    workgroupBarrier();
    // Exclusive scan of offsets (digit-major): thread t scans entries 16t .. 16t + 15.
    var sum = 0u;
    for (var k = 0u; k < SORT_RADIX; k++) {
        sum += offsets[lid * SORT_RADIX + k];
    }
    var running = exclusive_scan(lid, sum, THREADS);
    for (var k = 0u; k < SORT_RADIX; k++) {
        let v = offsets[lid * SORT_RADIX + k];
        offsets[lid * SORT_RADIX + k] = running;
        running += v;
    }
    workgroupBarrier();
    // offsets[d * THREADS + t]: keys of the tile before thread t's first key of digit d, in
    // digit-major order; offsets[d * THREADS] counts the tile's keys of smaller digits.
    var dest: array<u32, SORT_RADIX>;
    for (var d = 0u; d < SORT_RADIX; d++) {
        dest[d] = histogram[d * params.tiles + tile] + offsets[d * THREADS + lid] - offsets[d * THREADS];
    }
    let start = tile * SORT_TILE + lid * ITEMS;
    for (var i = start; i < min(start + ITEMS, params.count); i++) {
        let key = keys_in[i];
        let d = digit(key);
        keys_out[dest[d]] = key;
        values_out[dest[d]] = values_in[i];
        dest[d] += 1u;
    }
}
