// The splatter's ray payload (splat.rgen traces a ray per slab with it; splat.rahit fills it):
// the slab's buffer of hits (distance along the ray, particle index), how many it holds, and
// how many it may hold (k, the frame's shading.w).
struct SplatPayload {
    float t[SPLAT_K_MAX];
    uint id[SPLAT_K_MAX];
    uint n;
    uint k;
};
