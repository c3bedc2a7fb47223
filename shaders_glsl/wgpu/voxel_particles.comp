#version 450
// The voxel-grid baseline's splat, its first pass: each particle of a range as the kernel
// sees it, from the shared map and RBF code (rbf.glsl), for voxel_splat.wgsl to add to the
// cells it reaches (naga's GLSL front end has no atomics, so the adding is WGSL's). Per
// particle two vec4s: its offset from the grid's first cell centre (exact for nearby points,
// as rbf_offset's difference; with double-single positions the lo parts are added) and its
// radius; then its weight w(t) and theta. Twin: the scatter of Particles::eval_grid_sums.
// twin: src/field/grid.rs: the scatter of Particles::eval_grid_sums, with voxel_splat (tests/voxel_wgpu.rs compares the grids)

layout(local_size_x = 64) in;

#include "shared/params.glsl"

layout(std140, set = 0, binding = 0) uniform VoxelBlock { Voxels voxels; };
layout(std140, set = 0, binding = 1) uniform FieldBlock { Field field_params; };
layout(std430, set = 0, binding = 3) readonly buffer MapTables { float map_tables[]; };
layout(std430, set = 0, binding = 4) readonly buffer RadiusAttributes { float radius_attributes[]; };
layout(std430, set = 0, binding = 8) buffer Splats { vec4 splats[]; };
// Particles (and their lo parts), each in up to SPLIT_PARTS parts (bindings 10.., 26..).
#include "wgpu/split.glsl"

#include "shared/maps.glsl"

float radius_attribute(uint i) {
    return radius_attributes[i];
}

float particle_volume(uint i) {
    return radius_attributes[field_params.factors.x + i];
}

#include "shared/rbf.glsl"

void main() {
    uint i = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64u
        + gl_LocalInvocationID.x;
    if (i >= voxels.range.y) {
        return;
    }
    uint k = voxels.range.x + i;
    vec4 p = particle(k);
    vec3 offset = p.xyz - voxels.origin.xyz;
    if (POSITION_DS == 1u) {
        offset += particle_lo(k).xyz - voxels.origin_lo.xyz;
    }
    float r = particle_radius(p, k);
    splats[2u * i] = vec4(offset, r);
    splats[2u * i + 1u] = vec4(particle_weight(p, k, r), particle_theta(p));
}
