// The LBVH traversal of one splatter slab: the software path's splat_slab (splat_pixel.glsl),
// with lbvh.glsl's tree. Every node whose box the ray crosses within [lo, splat_end] is
// entered (left child first, the right one on the stack, as lbvh_field does); every particle
// of a reached cluster whose sphere the ray crosses with its closest approach at or after lo
// is offered to the slab's buffer (splat_offer, which drops those at or beyond splat_end: a
// hit accepted into a full buffer shortens the segment, and with it the traversal).
//
// The includer includes lbvh.glsl (its accessors and LBVH_* constants) and splat.glsl first.

// Whether the ray origin + t dir (inv = 1 / dir) crosses the box lo..hi for some t in [t0, t1].
bool lbvh_segment_crosses(vec4 lo, vec4 hi, vec3 origin, vec3 inv, float t0, float t1) {
    vec3 a = (lo.xyz - origin) * inv;
    vec3 b = (hi.xyz - origin) * inv;
    vec3 near = min(a, b);
    vec3 far = max(a, b);
    float t_in = max(max(max(near.x, near.y), near.z), t0);
    float t_out = min(min(min(far.x, far.y), far.z), t1);
    return t_in <= t_out;
}

// Offers every particle of cluster c the slab's ray meets.
void lbvh_splat_cluster(uint c, vec3 origin, vec3 dir, float lo) {
    uint first = c * CLUSTER_SIZE;
    uint end = min(first + CLUSTER_SIZE, field_params.counts.x);
    for (uint k = first; k < end; k++) {
        vec4 p = particle(k);
        float r = particle_radius(p, k);
        if (r <= 0.0) {
            continue;
        }
        vec3 oc = splat_offset(origin, p, k);
        float t = dot(oc, dir);
        vec3 perp = oc - dir * t;
        if (dot(perp, perp) <= r * r && t >= lo) {
            splat_offer(t, k);
        }
    }
}

void lbvh_splat_slab(vec3 origin, vec3 dir, float lo, float hi) {
    uint ptr = floatBitsToUint(lbvh_node(0u).w);
    if (ptr == LBVH_NONE) {
        return;
    }
    vec3 inv = 1.0 / dir;
    uint stack[LBVH_STACK_SIZE];
    uint sp = 0u;
    for (;;) {
        if ((ptr & LBVH_LEAF) != 0u) {
            uint c = ptr & ~LBVH_LEAF;
            // A single particle's own test costs no more than its box's.
            if (CLUSTER_SIZE == 1u || lbvh_segment_crosses(lbvh_box(2u * c),
                    lbvh_box(2u * c + 1u), origin, inv, lo, splat_end)) {
                lbvh_splat_cluster(c, origin, dir, lo);
            }
        } else {
            vec4 a = lbvh_node(2u * ptr);
            vec4 b = lbvh_node(2u * ptr + 1u);
            if (lbvh_segment_crosses(a, b, origin, inv, lo, splat_end)) {
                stack[sp] = floatBitsToUint(b.w);
                sp++;
                ptr = floatBitsToUint(a.w);
                continue;
            }
        }
        if (sp == 0u) {
            break;
        }
        sp--;
        ptr = stack[sp];
    }
}
