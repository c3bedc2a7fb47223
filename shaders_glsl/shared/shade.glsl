// A pixel's primary ray, a sample's extinction and colour, and where a ray meets a box: the part of the integrators
// (integrators.glsl) the splatter (splat_pixel.glsl) shares. Twins: FrameParams::primary_ray,
// FrameParams::shade and ray_box in src/backend/cpu/integrators.rs.
//
// The includer defines, before this file, `Frame frame` (params.glsl) and includes maps.glsl.

// Extinction (w) and colour (rgb) of a sample with field value f = (Phi, Theta numerator).
vec4 shade(vec4 f) {
    float phi = f.x;
    float x = phi / frame.shading.x;
    float sigma = frame.shading.y * map_lookup(TABLE_OPTICAL, x);
    vec3 rgb = vec3(0.0);
    if (COLOUR_MODE == COLOUR_DENSITY) {
        rgb = colour_lookup(x);
    } else if (phi >= PHI_EPSILON) {
        if (COLOUR_MODE == COLOUR_POST) {
            rgb = colour_lookup(f.y / phi);
        } else {
            rgb = f.yzw / phi;
        }
    }
    return vec4(rgb, sigma);
}

// Where a ray meets a box: (t_enter, t_exit) clipped to t >= 0; empty when t_enter >= t_exit.
vec2 ray_box(vec3 origin, vec3 dir, vec3 lo, vec3 hi) {
    vec3 inv = 1.0 / dir;
    vec3 t1 = (lo - origin) * inv;
    vec3 t2 = (hi - origin) * inv;
    vec3 tmin = min(t1, t2);
    vec3 tmax = max(t1, t2);
    float t_enter = max(max(max(tmin.x, tmin.y), tmin.z), 0.0);
    float t_exit = min(min(tmax.x, tmax.y), tmax.z);
    // An inverted or unbounded box (no particles) is missed: a march to t = inf would never
    // end. Callers test !(span.x < span.y), which also rejects NaN.
    if (any(greaterThan(lo, hi)) || !(t_exit < 3.0e38)) {
        return vec2(0.0, -1.0);
    }
    return vec2(t_enter, t_exit);
}


// The primary ray of a pixel: the camera's eye and the unit direction through the pixel centre.
void primary_ray(uvec2 pixel, out vec3 origin, out vec3 dir) {
    float sx = 2.0 * (float(pixel.x) + 0.5) / float(frame.image.x) - 1.0;
    float sy = 1.0 - 2.0 * (float(pixel.y) + 0.5) / float(frame.image.y);
    origin = frame.eye.xyz;
    dir = normalize(frame.forward.xyz + frame.right.xyz * sx + frame.up.xyz * sy);
}

// The primary ray of a pixel, and the part of it in the march box: (enter, exit), empty
// (!(x < y)) where the ray misses the box.
vec2 primary_span(uvec2 pixel, out vec3 origin, out vec3 dir) {
    primary_ray(pixel, origin, dir);
    return ray_box(origin, dir, frame.box_min.xyz, frame.box_max.xyz);
}
