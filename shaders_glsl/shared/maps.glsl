// 1D maps baked into 256-sample tables: the GLSL twin of src/values/tables.rs (twin of the f32 lookup: src/backend/shaders/cpu/maps.rs).
//
// The includer declares, before this file:
//     layout(std430, set = S, binding = B) readonly buffer MapTables { float map_tables[]; };
// holding, in order: the density map w (256), the radius map m (256), the optical-density map
// D (256), the colour map as linear RGB (3 x 256, interleaved).

// TABLE_SIZE and the TABLE_* offsets come with params.glsl (generated/constants.glsl).

// Clamp t to [0, 1] (NaN to 0) and interpolate linearly between neighbouring samples.
float table_position(float t, out uint i) {
    float c = (t >= 0.0) ? min(t, 1.0) : 0.0;
    float x = c * float(TABLE_SIZE - 1u);
    i = min(uint(floor(x)), TABLE_SIZE - 2u);
    return x - float(i);
}

float map_lookup(uint base, float t) {
    uint i;
    float f = table_position(t, i);
    float a = map_tables[base + i];
    float b = map_tables[base + i + 1u];
    return a + (b - a) * f;
}

vec3 colour_lookup(float t) {
    uint i;
    float f = table_position(t, i);
    uint k = TABLE_COLOUR + 3u * i;
    vec3 a = vec3(map_tables[k], map_tables[k + 1u], map_tables[k + 2u]);
    vec3 b = vec3(map_tables[k + 3u], map_tables[k + 4u], map_tables[k + 5u]);
    return a + (b - a) * f;
}
