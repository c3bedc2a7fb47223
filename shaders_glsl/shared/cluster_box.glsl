// The cluster-box rule (paper §3.2.3; method.md §3), the one GPU definition: cluster c holds
// the CLUSTER_SIZE consecutive (Hilbert-sorted) particles c K .. min(c K + K, n); its box is
// the union of [p - r - pad, p + r + pad] over the members with r > 0 (r = rbf.glsl's
// particle_radius, the very rule the queries test spheres with). pad = max(|p|, r) BOX_PAD, four
// ulp of the coordinates, so the f32 box holds every point the f32 sphere test accepts (a
// point at distance r computed with rounding may lie just outside [p - r, p + r]), and with
// double-single positions every rounded point whose exact position is inside. A cluster
// with no member of r > 0 is empty: cluster_box returns false and lo, hi are unset; each
// structure decides what an empty box is (the LBVH leaves it out, the RT BLAS keeps a
// degenerate box so a refit can grow it).
//
// The CPU twin is accel::clusters::cluster_box at f32 (the f64 reference uses it at f64).
// The includer defines `vec4 particle(uint k)` and includes rbf.glsl first.

bool cluster_box(uint c, out vec3 lo, out vec3 hi) {
    uint first = c * CLUSTER_SIZE;
    uint end = min(first + CLUSTER_SIZE, field_params.counts.x);
    bool any = false;
    lo = vec3(0.0);
    hi = vec3(0.0);
    for (uint k = first; k < end; k++) {
        vec4 p = particle(k);
        float r = particle_radius(p, k);
        if (r > 0.0) {
            vec3 pad = max(abs(p.xyz), vec3(r)) * BOX_PAD;
            vec3 a = p.xyz - vec3(r) - pad;
            vec3 b = p.xyz + vec3(r) + pad;
            lo = any ? min(lo, a) : a;
            hi = any ? max(hi, b) : b;
            any = true;
        }
    }
    return any;
}
