// The attribute-aware RBF (method.md §2): the GLSL twin of field::Particles::accumulate.
//
// A particle is a vec4: xyz its local position, w its normalised attribute t. Its radius is
// R * m(t) * h (h from the radius attribute when the scene has one), its weight w(t), its
// theta t (post-classification) or C(t) (pre-classification). A field value is a vec4:
// x = Phi, yzw = the Theta numerator Σ theta_i phi_i.
//
// Positions: with POSITION_DS = 0 a particle's position is p.xyz and a query point x, f32 in
// local coordinates. With POSITION_DS = 1 (a scene whose radii f32 cannot resolve, see
// src/backend/gpu_data.rs) each is a double-single pair: p.xyz + particle_lo(k) and x + x_lo,
// the hi parts f32-rounded, the lo parts the remainders. The distance is then
// (x - p) + (x_lo - p_lo): the hi difference is exact for nearby points (Sterbenz), so d keeps
// f32's relative precision however small the radius is against the coordinates.
//
// The includer defines, before this file, `Field field_params` (params.glsl), `vec4
// particle_lo(uint k)` (read only when POSITION_DS is 1), when HAS_RADIUS_ATTRIBUTE is 1
// `float radius_attribute(uint particle)`, and for an SPH kernel (KERNEL > 0) `float
// particle_volume(uint particle)`, the particle's m/rho.
//
// The kernel (values::Kernel, the one definition in f64): the paper's Gaussian, or an SPH
// kernel normalised in 3D, `V sigma / h^3 f(q)`, q = d / h and h = r / support.

float particle_radius(vec4 p, uint index) {
    float m = (RADIUS_MAP_VARIES == 1u) ? map_lookup(TABLE_RADIUS, p.w) : field_params.radius.y;
    float r = field_params.radius.x * m;
    if (HAS_RADIUS_ATTRIBUTE == 1u) {
        r *= radius_attribute(index);
    }
    return r;
}

// The weight of particle k (p) of radius r: the density map's, times an SPH kernel's volume
// and normalisation V sigma support^3 / r^3.
float particle_weight(vec4 p, uint k, float r) {
    float w = (DENSITY_MAP_VARIES == 1u) ? map_lookup(TABLE_DENSITY, p.w) : field_params.radius.z;
    if (KERNEL != KERNEL_GAUSSIAN_RBF) {
        w *= particle_volume(k) * kernel_radius_norm() / (r * r * r);
    }
    return w;
}

vec3 particle_theta(vec4 p) {
    if (COLOUR_MODE == COLOUR_PRE) {
        return colour_lookup(p.w);
    } else if (COLOUR_MODE == COLOUR_POST) {
        return vec3(p.w, 0.0, 0.0);
    }
    return vec3(0.0);
}

// Whether a point at squared distance d2 lies within radius r (radius 0: never).
bool rbf_inside(float d2, float r) {
    return r > 0.0 && d2 <= r * r;
}

// The exponent 4.5 d²/r² of a term. Where every particle has one radius (no radius map that
// varies, no radius attribute) it is k d², k = 4.5 / (R m)² rounded once from f64 on the host:
// one rounding where the division of f32 values has several, and no division (the error model
// that counts them: src/backend/precision.rs).
float rbf_exponent(float d2, float r) {
    if (RADIUS_MAP_VARIES == 0u && HAS_RADIUS_ATTRIBUTE == 0u) {
        return field_params.radius.w * d2;
    }
    return 4.5 * d2 / (r * r);
}

// The kernel's profile at squared distance d2 within radius r (values::Kernel::profile): the
// Gaussian exp(-4.5 d²/r²), or an SPH kernel's f(q), its splines' (x)+ as max(x, 0).
float rbf_profile(float d2, float r) {
    if (KERNEL == KERNEL_GAUSSIAN_RBF) {
        return exp(-rbf_exponent(d2, r));
    }
    float q = kernel_support() * sqrt(d2 / (r * r));
    if (KERNEL == KERNEL_SPH_CUBIC) {
        float a = max(2.0 - q, 0.0);
        float b = max(1.0 - q, 0.0);
        return 0.25 * (a * a * a) - b * b * b;
    }
    if (KERNEL == KERNEL_SPH_QUINTIC) {
        float a = max(3.0 - q, 0.0);
        float b = max(2.0 - q, 0.0);
        float c = max(1.0 - q, 0.0);
        float a2 = a * a;
        float b2 = b * b;
        float c2 = c * c;
        return a2 * a2 * a - 6.0 * (b2 * b2 * b) + 15.0 * (c2 * c2 * c);
    }
    float a = max(1.0 - 0.5 * q, 0.0);
    float a2 = a * a;
    if (KERNEL == KERNEL_SPH_WENDLAND_C2) {
        return a2 * a2 * (1.0 + 2.0 * q);
    }
    return a2 * a2 * a2 * (1.0 + 3.0 * q + (35.0 / 12.0) * q * q);
}

// Adds the contribution of particle k (p), at squared distance d2 (inside radius r), to acc.
void rbf_add(inout vec4 acc, float d2, float r, vec4 p, uint k) {
    float phi = particle_weight(p, k, r) * rbf_profile(d2, r);
    acc.x += phi;
    acc.yzw += particle_theta(p) * phi;
}

// Adds v (a cluster's terms) to a point's sum acc: plainly, or with COMPENSATED_SUM = 1
// compensated (Kahan), comp keeping what each addition rounded away (negated) and taking it
// back at the next. A plain f32 sum of n positive terms errs by up to (n - 1) 2^-24 of it; the
// compensated one by about 2^-23 whatever n (src/backend/precision.rs chooses per scene). The
// CPU twin: Kahan in src/backend/shaders/cpu/rbf.rs.
void sum_add(inout vec4 acc, inout vec4 comp, vec4 v) {
    if (COMPENSATED_SUM == 1u) {
        vec4 y = v - comp;
        vec4 t = acc + y;
        comp = (t - acc) - y;
        acc = t;
    } else {
        acc += v;
    }
}

// The offset from particle k (p) to the query point x (+ x_lo).
vec3 rbf_offset(vec3 x, vec3 x_lo, vec4 p, uint k) {
    vec3 d = x - p.xyz;
    if (POSITION_DS == 1u) {
        d += x_lo - particle_lo(k).xyz;
    }
    return d;
}

// Adds particle k's (p's) contribution at x (+ x_lo) to acc when x lies within its radius r.
void rbf_accumulate(inout vec4 acc, vec3 x, vec3 x_lo, vec4 p, uint k, float r) {
    vec3 d = rbf_offset(x, x_lo, p, k);
    float d2 = dot(d, d);
    if (rbf_inside(d2, r)) {
        rbf_add(acc, d2, r, p, k);
    }
}
