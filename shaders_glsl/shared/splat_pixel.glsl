// The splatter per pixel: the GLSL twin of backend::cpu::splat::splat_pixel (and of the slab
// loop of field::splat's splat_ray). The ray is cut into slabs one march step long from where
// it enters the march box; each slab's hits (splat.glsl) are sorted by distance and composited
// front to back, each particle alone at its closest approach: shaded by shade(), absorbing
// alpha = 1 - exp(-sigma · chord) of what lies behind it, until the opacity threshold.
//
// The includer includes shade.glsl and splat.glsl, and defines before this file
//     void splat_slab(vec3 origin, vec3 dir, float lo, float hi);
// which fills splat_t, splat_id and splat_n with the hits of slab [lo, hi) (splat_n is 0,
// splat_end hi and splat_k set when it is called). Empty slabs cost a traversal each, as in
// Knoll et al.'s; the CPU twin skips them (the image is the same).

vec4 splat_pixel(uvec2 pixel) {
    vec3 origin, dir;
    vec2 span = primary_span(pixel, origin, dir);
    vec3 bg = frame.background.rgb;
    if (!(span.x < span.y)) {
        return vec4(bg, 0.0);
    }
    float dt = frame.box_min.w;
    splat_k = clamp(uint(frame.shading.w), 1u, SPLAT_K_MAX);
    vec3 colour = vec3(0.0);
    float transmittance = 1.0;
    for (float j = 0.0;; j += 1.0) {
        float lo = span.x + j * dt;
        if (lo >= span.y) {
            break;
        }
        float hi = min(lo + dt, span.y);
        splat_n = 0u;
        splat_end = hi;
        splat_slab(origin, dir, lo, hi);
        // Insertion sort by distance (at most SPLAT_K_MAX hits).
        for (uint a = 1u; a < splat_n; a++) {
            float t = splat_t[a];
            uint id = splat_id[a];
            uint b = a;
            while (b > 0u && splat_t[b - 1u] > t) {
                splat_t[b] = splat_t[b - 1u];
                splat_id[b] = splat_id[b - 1u];
                b--;
            }
            splat_t[b] = t;
            splat_id[b] = id;
        }
        for (uint a = 0u; a < splat_n; a++) {
            uint k = splat_id[a];
            vec4 p = particle(k);
            float r = particle_radius(p, k);
            vec3 oc = splat_offset(origin, p, k);
            float t = dot(oc, dir);
            vec3 perp = oc - dir * t;
            float b2 = dot(perp, perp);
            float phi = particle_weight(p, k, r) * rbf_profile(b2, r);
            vec4 s = shade(vec4(phi, particle_theta(p) * phi));
            if (s.w <= 0.0) {
                continue;
            }
            float alpha = 1.0 - exp(-s.w * splat_chord(r, b2));
            colour += transmittance * alpha * s.rgb;
            transmittance *= 1.0 - alpha;
            if (1.0 - transmittance >= frame.box_max.w) {
                return vec4(colour + transmittance * bg, 1.0 - transmittance);
            }
        }
    }
    return vec4(colour + transmittance * bg, 1.0 - transmittance);
}
