// What a brick reads of its share of a distributed frame (params.glsl's Brick): whether it owns
// a sample, the depth of the bricks in front along a primary ray, and the depth nearer the
// light at a point. Twins: HalfOpenBox::contains (src/values/region.rs),
// BrickShare::depth_in_front and LightPrefix::depth_at (src/backend/brick.rs).
//
// Included by integrators.glsl where the includer defines OWNED_BRICK, and declares before it
// `brick` (a Brick) and `float brick_input(uint j)`, the j-th float of the brick's inputs: the
// depth in front (per pixel of brick.rect), then the light prefix (from brick.prefix_at.x).

// Whether the brick's half-open box holds x: lo <= x < hi (an infinite face holds everything
// beyond it).
bool owned_contains(vec3 x) {
    return all(greaterThanEqual(x, brick.owned_lo.xyz)) && all(lessThan(x, brick.owned_hi.xyz));
}

// The optical depth of the bricks in front along pixel's primary ray (0 when not given).
float owned_depth_in_front(uvec2 pixel) {
    if (brick.task.y == 0u) {
        return 0.0;
    }
    uvec4 r = brick.rect;
    return brick_input((pixel.y - r.y) * (r.z - r.x) + (pixel.x - r.x));
}

// The prefix's depth at texel (i, j) of its rectangle.
float light_prefix_texel(uint i, uint j) {
    uvec4 r = brick.prefix;
    return brick_input(brick.prefix_at.x + (j - r.y) * (r.z - r.x) + (i - r.x));
}

// The optical depth nearer the light than the brick at x: bilinear between the four texels
// around it, clamped to the rectangle held; 0 where none is held (local shadows).
float light_depth_at(vec3 x) {
    uvec4 r = brick.prefix;
    if (r.x >= r.z || r.y >= r.w) {
        return 0.0;
    }
    // LightMap::texel_coordinates.
    vec3 d = x - brick.light_centre.xyz;
    vec2 t = vec2((dot(d, brick.light_u.xyz) - brick.light_u.w) / brick.light_texel.x - 0.5,
                  (dot(d, brick.light_v.xyz) - brick.light_v.w) / brick.light_texel.y - 0.5);
    vec2 first = vec2(r.xy);
    vec2 last = vec2(r.zw - uvec2(1u));
    t = clamp(t, first, last);
    vec2 i0 = min(floor(t), last);
    vec2 i1 = min(i0 + 1.0, last);
    vec2 f = t - i0;
    uvec2 a = uvec2(i0);
    uvec2 b = uvec2(i1);
    float below = light_prefix_texel(a.x, a.y) * (1.0 - f.x) + light_prefix_texel(b.x, a.y) * f.x;
    float above = light_prefix_texel(a.x, b.y) * (1.0 - f.x) + light_prefix_texel(b.x, b.y) * f.x;
    return below * (1.0 - f.y) + above * f.y;
}
