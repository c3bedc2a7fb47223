// The voxel-grid baseline's splat, its second pass: each particle of a range (as
// voxel_particles.comp prepared it) adds its kernel phi = w exp(-4.5 d² / r²) for d <= r, and
// theta phi, to every cell centre of the slab within its radius (the twin of rbf.glsl's
// rbf_inside and rbf_add, and of the scatter in Particles::eval_grid_sums). The slab buffer
// holds f32 sums as bit patterns: WGSL has no float atomics, so each add is a
// compare-exchange loop on the word (an add is lost only if another thread changed the word
// in between, and then the exchange fails and is retried with the new value). The host
// clears the slab before the first range and copies it into the grid's texture after the
// last, in later passes, which wgpu orders after this one.
// twin: src/field/grid.rs: the scatter of Particles::eval_grid_sums (tests/voxel_wgpu.rs compares the grids)

#include "shared/invocation.wgsl"

// shaders_glsl/shared/params.glsl's Voxels.
struct Voxels {
    origin: vec4<f32>,
    origin_lo: vec4<f32>,
    cell: vec4<f32>,
    dims: vec4<u32>,
    range: vec4<u32>,
    channels: vec4<u32>,
}

@group(0) @binding(0) var<uniform> voxels: Voxels;
// Per particle: offset from the first cell centre and radius; weight and theta.
@group(0) @binding(8) var<storage, read> splats: array<vec4<f32>>;
// Four f32 sums per cell (Phi, Theta numerator), rows of dims.w cells, layers of dims.y rows.
@group(0) @binding(9) var<storage, read_write> slab: array<atomic<u32>>;

fn add_f32(word: u32, value: f32) {
    var old = atomicLoad(&slab[word]);
    loop {
        let swapped = atomicCompareExchangeWeak(
            &slab[word],
            old,
            bitcast<u32>(bitcast<f32>(old) + value),
        );
        if swapped.exchanged {
            break;
        }
        old = swapped.old_value;
    }
}

@compute @workgroup_size(64)
fn main(id: Invocation) {
    let i = thread_index(id);
    if i >= voxels.range.y {
        return;
    }
    let at = splats[2u * i];
    let kernel = splats[2u * i + 1u];
    let r = at.w;
    // Radius 0 (or NaN) reaches nothing, as rbf_inside says.
    if !(r > 0.0) {
        return;
    }
    let cell = voxels.cell.xyz;
    // The cell centres within the radius along each axis, clipped to the grid and the slab:
    // centre c of axis a lies at c * cell (from the first). One cell beyond each end is
    // included so that rounding in the division cannot drop a centre the test below keeps.
    let first_f = max(floor((at.xyz - r) / cell), vec3<f32>(0.0));
    let last_f = min(ceil((at.xyz + r) / cell), vec3<f32>(voxels.dims.xyz) - 1.0);
    if any(first_f > last_f) {
        return;
    }
    let first = vec3<u32>(first_f);
    let last = vec3<u32>(last_f);
    let z0 = max(first.z, voxels.range.z);
    let z1 = min(last.z, voxels.range.z + voxels.range.w - 1u);
    let r2 = r * r;
    for (var z = z0; z <= z1; z++) {
        for (var y = first.y; y <= last.y; y++) {
            for (var x = first.x; x <= last.x; x++) {
                let d = vec3<f32>(f32(x), f32(y), f32(z)) * cell - at.xyz;
                let d2 = dot(d, d);
                if d2 <= r2 {
                    let phi = kernel.x * exp(-4.5 * d2 / r2);
                    let word = 4u * (((z - voxels.range.z) * voxels.dims.y + y) * voxels.dims.w + x);
                    add_f32(word, phi);
                    if voxels.channels.x > 1u {
                        add_f32(word + 1u, kernel.y * phi);
                    }
                    if voxels.channels.x > 2u {
                        add_f32(word + 2u, kernel.z * phi);
                        add_f32(word + 3u, kernel.w * phi);
                    }
                }
            }
        }
    }
}
