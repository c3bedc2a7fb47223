// The integrators, per pixel: the GLSL twin of src/backend/cpu/integrators.rs (read that file's
// documentation; the two are kept statement for statement alike, f32 here, f64 there).
//
// The includer defines, before this file: `Frame frame` (params.glsl, e.g. as a uniform
// block member), the noise inputs (noise.glsl), and `vec4 field_query(vec3 x)` returning
// (Phi, Theta numerator) at a local position: the only part each backend supplies.

// PHI_EPSILON and noise_offset(dim), the blue-noise mask's offset per random dimension, come
// with params.glsl (generated/constants.glsl).

float random_number(uvec2 pixel, uint dim) {
    uint seed = frame.image.w;
    if (NOISE_KIND == 0u && dim < 3u) {
        uvec2 o = noise_offset(dim) + stbn_shift(seed, frame.image.z);
        return stbn_value(pixel.x + o.x, pixel.y + o.y, frame.image.z);
    }
    return white_noise(pixel.x, pixel.y, frame.image.z, dim, seed);
}

#include "shared/shade.glsl"

// The index of the first march sample t0 + (k + jitter) dt at or after a (k >= 0).
float first_sample(float t0, float a, float dt, float jitter) {
    return max(ceil((a - t0) / dt - jitter), 0.0);
}

#ifdef OWNED_BRICK
#include "shared/owned.glsl"
#endif

// Transmittance from x towards the light to the march box's exit: exp(-Σ sigma dt). In a
// brick (OWNED_BRICK), marched to the brick's exit, plus the depth nearer the light that the
// bricks before it left.
float shadow_transmittance(vec3 x, float jitter) {
    vec3 dir = frame.light.xyz;
#ifdef OWNED_BRICK
    vec2 span = ray_box(x, dir, brick.clip_lo.xyz, brick.clip_hi.xyz);
    float tau = light_depth_at(x);
#else
    vec2 span = ray_box(x, dir, frame.box_min.xyz, frame.box_max.xyz);
    float tau = 0.0;
#endif
    if (!(span.x < span.y)) {
        return exp(-tau);
    }
    float dt = frame.box_min.w;
    for (float k = 0.0;; k += 1.0) {
        float t = (k + jitter) * dt;
        if (t >= span.y || tau >= 745.0) {
            break;
        }
        tau += shade(field_query(x + dir * t)).w * dt;
    }
    return exp(-tau);
}

vec3 scattered(vec3 x, vec3 albedo, float shadow_jitter) {
    float light = frame.light.w * shadow_transmittance(x, shadow_jitter) + frame.background.w;
    return albedo * light;
}

// What a march of a ray's samples gathered (march_samples).
struct Marched {
    vec3 colour;          // emission-absorption: premultiplied; stochastic marching: the light
                          // scattered where it stopped
    float transmittance;  // emission-absorption: what is left from 1
    bool did_scatter;     // stochastic marching: whether its depth passed the free flight
};

// The samples t_enter + (k + jitter) dt of the ray in [a, b) (with `owned_only`, in a brick,
// only those its half-open box holds), composited front to back from transmittance 1 (with a
// shadow ray each for the SS reference) and stopped where exp(-tau), at most the transmittance
// in front (1 for a whole frame), times the ray's own falls to 1 - the opacity threshold; or,
// stochastic marching, their optical depth added to `tau` until it passes `target_tau`, where
// the ray scatters. The loop of march_packet (src/backend/cpu/integrators.rs), for a whole frame and
// a brick alike.
Marched march_samples(vec3 origin, vec3 dir, float t_enter, float a, float b, float jitter,
                      float shadow_jitter, float tau, float target_tau, bool owned_only) {
    bool scatter = INTEGRATOR == INTEGRATOR_SS_REFERENCE;
    bool stochastic = INTEGRATOR == INTEGRATOR_MARCHING;
    float dt = frame.box_min.w;
    float front_transmittance = stochastic ? 1.0 : exp(-tau);
    Marched m = Marched(vec3(0.0), 1.0, false);
    for (float k = first_sample(t_enter, a, dt, jitter);; k += 1.0) {
        float t = t_enter + (k + jitter) * dt;
        if (t >= b) {
            break;
        }
        vec3 at = origin + dir * t;
#ifdef OWNED_BRICK
        // Another box's sample is another rank's (the ray marches on).
        if (owned_only && !owned_contains(at)) {
            continue;
        }
#endif
        vec4 s = shade(field_query(at));
        if (stochastic) {
            tau += s.w * dt;
            if (tau > target_tau) {
                m.colour = scattered(at, s.rgb, shadow_jitter);
                m.did_scatter = true;
                return m;
            }
            continue;
        }
        if (s.w <= 0.0) {
            continue;
        }
        float alpha = 1.0 - exp(-s.w * dt);
        vec3 emitted = scatter ? scattered(at, s.rgb, shadow_jitter) : s.rgb;
        m.colour += m.transmittance * alpha * emitted;
        m.transmittance *= 1.0 - alpha;
        if (1.0 - front_transmittance * m.transmittance >= frame.box_max.w) {
            break;
        }
    }
    return m;
}

// The radiance of a pixel in this frame: linear RGB and opacity.
vec4 render_pixel(uvec2 pixel) {
    vec3 origin, dir;
    vec2 span = primary_span(pixel, origin, dir);
    vec3 bg = frame.background.rgb;
    if (!(span.x < span.y)) {
        return vec4(bg, 0.0);
    }
    float t_enter = span.x;
    float t_exit = span.y;
    float dt = frame.box_min.w;

    if (INTEGRATOR != INTEGRATOR_DELTA) {
        // One march for the three marching integrators: emission-absorption composites every
        // sample (the SS reference with a shadow ray each); stochastic marching sums optical
        // depth until it passes the free-flight threshold -ln(1 - xi) and scatters there.
        bool scatter = INTEGRATOR == INTEGRATOR_SS_REFERENCE;
        bool stochastic = INTEGRATOR == INTEGRATOR_MARCHING;
        float jitter = random_number(pixel, (scatter || stochastic) ? 1u : 0u);
        float shadow_jitter = random_number(pixel, 2u);
        float target_tau = stochastic ? -log(1.0 - random_number(pixel, 0u)) : 0.0;
        Marched m = march_samples(origin, dir, t_enter, t_enter, t_exit, jitter, shadow_jitter,
                                  0.0, target_tau, false);
        if (stochastic) {
            return m.did_scatter ? vec4(m.colour, 1.0) : vec4(bg, 0.0);
        }
        return vec4(m.colour + m.transmittance * bg, 1.0 - m.transmittance);
    } else {
        float majorant = frame.shading.z;
        if (majorant <= 0.0) {
            return vec4(bg, 0.0);
        }
        uint dim = 0u;
        float t = t_enter;
        for (;;) {
            float xi = random_number(pixel, dim);
            dim = (dim == 0u) ? 3u : dim + 1u;
            t -= log(1.0 - xi) / majorant;
            if (t >= t_exit) {
                return vec4(bg, 0.0);
            }
            vec3 at = origin + dir * t;
            vec4 s = shade(field_query(at));
            float accept = random_number(pixel, dim);
            dim += 1u;
            if (accept * majorant < s.w) {
                return vec4(scattered(at, s.rgb, random_number(pixel, 2u)), 1.0);
            }
            if (dim > 100000u) {
                // Bounded work per pixel, as on the CPU.
                return vec4(bg, 0.0);
            }
        }
    }
    // Unreachable (every branch returns); naga's validator wants a return on every path.
    return vec4(bg, 0.0);
}

#ifdef OWNED_BRICK
// A brick's share of pixel `pixel`: the twin of render_owned_pixels_with (march_packet and
// delta_tracking with Some(brick)) in src/backend/cpu/integrators.rs. The whole frame's
// lattice t_enter + (k + jitter) dt and numbers; only the samples whose points the brick's
// half-open box holds count. Returns premultiplied colour and transmittance [r, g, b, T] from
// T = 1 with no background; single scattering [L, 0] where it scatters in this brick, else
// [0, 0, 0, 1].
vec4 render_owned_pixel(uvec2 pixel) {
    vec4 miss = vec4(0.0, 0.0, 0.0, 1.0);
    vec3 origin, dir;
    vec2 span = primary_span(pixel, origin, dir);
    if (!(span.x < span.y)) {
        return miss;
    }
    float t_enter = span.x;
    float t_exit = span.y;
    float dt = frame.box_min.w;

    if (INTEGRATOR != INTEGRATOR_DELTA) {
        // clip_to_owned: the part of the ray that can meet the box, grown by a step.
        vec2 part = ray_box(origin, dir, brick.march_lo.xyz, brick.march_hi.xyz);
        float a = max(part.x, t_enter);
        float b = min(part.y, t_exit);
        if (!(a < b)) {
            return miss;
        }
        bool scatter = INTEGRATOR == INTEGRATOR_SS_REFERENCE;
        bool stochastic = INTEGRATOR == INTEGRATOR_MARCHING;
        float jitter = random_number(pixel, (scatter || stochastic) ? 1u : 0u);
        float shadow_jitter = random_number(pixel, 2u);
        float target_tau = stochastic ? -log(1.0 - random_number(pixel, 0u)) : 3.0e38;
        // Stochastic marching goes on from the depth of the bricks in front; past the
        // free-flight depth already, the ray scattered in front of this brick.
        // Emission-absorption ends where the transmittance in front times its own falls to
        // 1 - threshold; where that in front does, before its first sample.
        float tau = owned_depth_in_front(pixel);
        bool ended_in_front = !stochastic && 1.0 - exp(-tau) >= frame.box_max.w;
        if (!(tau <= target_tau) || ended_in_front) {
            return miss;
        }
        Marched m = march_samples(origin, dir, t_enter, a, b, jitter, shadow_jitter, tau,
                                  target_tau, true);
        if (stochastic) {
            return m.did_scatter ? vec4(m.colour, 0.0) : miss;
        }
        return vec4(m.colour, m.transmittance);
    } else {
        // The ray's segment in the brick's box exactly (its samples are its own), tracked
        // with the brick's numbers (the host writes the brick's seed into the frame).
        vec2 part = ray_box(origin, dir, brick.clip_lo.xyz, brick.clip_hi.xyz);
        float a = max(part.x, t_enter);
        float b = min(part.y, t_exit);
        float majorant = frame.shading.z;
        if (majorant <= 0.0 || !(a < b)) {
            return miss;
        }
        uint dim = 0u;
        float t = a;
        for (;;) {
            float xi = random_number(pixel, dim);
            dim = (dim == 0u) ? 3u : dim + 1u;
            t -= log(1.0 - xi) / majorant;
            if (t >= b) {
                return miss;
            }
            vec3 at = origin + dir * t;
            vec4 s = shade(field_query(at));
            float accept = random_number(pixel, dim);
            dim += 1u;
            if (accept * majorant < s.w) {
                return vec4(scattered(at, s.rgb, random_number(pixel, 2u)), 0.0);
            }
            if (dim > 100000u) {
                return miss;
            }
        }
    }
    return miss;
}

// The optical depth Σ sigma dt of the samples the brick owns along one ray of a depth pass:
// the twin of depth_packet (with DepthRay::of) in src/backend/cpu/owned.rs. A primary ray
// on stochastic marching's lattice (jitter dimension 1), stopped past its free-flight depth
// (dimension 0); an occluding primary ray on emission-absorption's (dimension 0), stopped past
// brick.depth_stop.x; a light map texel's ray marched whole.
float owned_depth_ray(uvec2 texel) {
    vec3 origin, dir;
    float jitter;
    float stop_past;
    if (brick.task.x == OWNED_TASK_PRIMARY_DEPTH) {
        primary_ray(texel, origin, dir);
        jitter = random_number(texel, 1u);
        stop_past = -log(1.0 - random_number(texel, 0u));
    } else if (brick.task.x == OWNED_TASK_OCCLUDING_DEPTH) {
        primary_ray(texel, origin, dir);
        jitter = random_number(texel, 0u);
        stop_past = brick.depth_stop.x;
    } else {
        // LightMap::texel_ray.
        float u = brick.light_u.w + (float(texel.x) + 0.5) * brick.light_texel.x;
        float v = brick.light_v.w + (float(texel.y) + 0.5) * brick.light_texel.y;
        dir = brick.light_dir.xyz;
        origin = brick.light_centre.xyz + brick.light_u.xyz * u + brick.light_v.xyz * v
            - dir * brick.light_centre.w;
        jitter = white_noise(texel.x, texel.y, 0u, 0u, LIGHT_MAP_SEED);
        stop_past = 3.0e38;
    }
    vec2 span = ray_box(origin, dir, frame.box_min.xyz, frame.box_max.xyz);
    if (!(span.x < span.y)) {
        return 0.0;
    }
    float t_enter = span.x;
    float dt = frame.box_min.w;
    vec2 part = ray_box(origin, dir, brick.march_lo.xyz, brick.march_hi.xyz);
    float a = max(part.x, t_enter);
    float b = min(part.y, span.y);
    float tau = 0.0;
    if (!(a < b)) {
        return tau;
    }
    for (float k = first_sample(t_enter, a, dt, jitter);; k += 1.0) {
        float t = t_enter + (k + jitter) * dt;
        if (t >= b) {
            break;
        }
        vec3 at = origin + dir * t;
        if (!owned_contains(at)) {
            continue;
        }
        tau += shade(field_query(at)).w * dt;
        if (tau > stop_past) {
            break;
        }
    }
    return tau;
}
#endif
