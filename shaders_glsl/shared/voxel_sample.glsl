// The voxel-grid baseline's field: trilinear interpolation of the grid's sums between cell
// centres, clamped to the outer cells' centres at the grid's faces. The GLSL twin of
// VoxelGrid::sample (src/backend/voxel.rs), statement for statement (f32 here, f64 there).
//
// The includer defines, before this file, `Voxels voxels` (params.glsl) and `vec4
// voxel_sums(ivec3 cell)`, the sums (Phi, Theta numerator) at a cell centre.

vec4 voxel_field(vec3 x) {
    vec3 g = (x - voxels.origin.xyz) / voxels.cell.xyz;
    ivec3 base = ivec3(0);
    vec3 frac = vec3(0.0);
    for (int a = 0; a < 3; a++) {
        float max_c = float(voxels.dims[a] - 1u);
        float c = clamp(g[a], 0.0, max_c);
        float b = min(floor(c), max(max_c - 1.0, 0.0));
        base[a] = int(b);
        frac[a] = c - b;
    }
    vec4 sums = vec4(0.0);
    for (int corner = 0; corner < 8; corner++) {
        float w = 1.0;
        ivec3 i = base;
        for (int a = 0; a < 3; a++) {
            bool hi = ((corner >> a) & 1) == 1;
            if (hi) {
                if (voxels.dims[a] == 1u) {
                    w = 0.0;
                }
                i[a] = min(base[a] + 1, int(voxels.dims[a]) - 1);
                w *= frac[a];
            } else {
                w *= 1.0 - frac[a];
            }
        }
        if (w > 0.0) {
            sums += w * voxel_sums(i);
        }
    }
    return sums;
}
