// Knoll et al.'s RT splatter (the paper's Table 3 baseline): the buffer of one slab's hits and
// what a hit is. GLSL twin of src/field/splat.rs, whose documentation says what the splatter
// does; splat_pixel.glsl composites, per pixel.
//
// A slab [lo, hi) of a ray gathers, in its traversal's order, the particles whose sphere the ray
// crosses with their closest approach t in the slab, at most splat_k of them; a hit met when
// the buffer is full is accepted as the RT any-hit does: the slab's end moves to it, so it and
// every farther hit of the slab are lost. The RT pipeline fills the buffer in its any-hit
// shader (vulkan/splat.rahit); a software traversal offers each hit to splat_offer.
//
// The includer includes rbf.glsl before this file (particle_radius, particle_weight,
// particle_theta, and particle_lo for double-single positions). SPLAT_K_MAX comes with
// params.glsl (generated/constants.glsl).

float splat_t[SPLAT_K_MAX];
uint splat_id[SPLAT_K_MAX];
// Hits in the buffer, its size this frame, and the slab's current end.
uint splat_n;
uint splat_k;
float splat_end;

// Offers particle id, closest approach t, to the slab's buffer.
void splat_offer(float t, uint id) {
    if (t >= splat_end) {
        return;
    }
    if (splat_n < splat_k) {
        splat_t[splat_n] = t;
        splat_id[splat_n] = id;
        splat_n++;
    } else {
        splat_end = t;
    }
}

// From the ray's origin to particle k's centre (p its position; with double-single positions
// its lo part added, so the offset keeps f32's relative precision however far the data lies).
vec3 splat_offset(vec3 origin, vec4 p, uint k) {
    vec3 oc = p.xyz - origin;
    if (POSITION_DS == 1u) {
        oc += particle_lo(k).xyz;
    }
    return oc;
}

// erf(x) by Abramowitz and Stegun 7.1.26 (absolute error below 1.5e-7; f64 twin: libm's erf).
float splat_erf(float x) {
    float a = abs(x);
    float t = 1.0 / (1.0 + 0.3275911 * a);
    float poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741
        + t * (-1.453152027 + t * 1.061405429))));
    float y = 1.0 - poly * exp(-a * a);
    return (x < 0.0) ? -y : y;
}

// ∫ exp(-4.5 s² / r²) ds over the chord of a sphere of radius r at squared distance b2 from its
// centre: the length over which a particle's Gaussian acts along the ray (field::splat's
// chord_length).
float splat_chord(float r, float b2) {
    float h = sqrt(max(r * r - b2, 0.0));
    return r / 3.0 * 2.5066282746 * splat_erf(3.0 * h / (1.4142135624 * r));
}
