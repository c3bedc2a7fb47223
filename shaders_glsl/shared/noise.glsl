// Random numbers for the renderer: the GPU twins of src/noise/white.rs (`lowbias32`, `white`)
// and of BlueNoiseMask::get in src/noise/mask.rs. Keep them line-for-line equal to the Rust:
// white_noise is bit-identical to aarbf::noise::white, stbn_value returns the same number as
// BlueNoiseMask::get.
//
// GLSL 4.50, no extensions. The includer includes params.glsl (whose generated constants give
// the mask's size, STBN_WIDTH, STBN_HEIGHT and STBN_DEPTH) and declares, before this file:
//
//     layout(std430, set = S, binding = B) readonly buffer StbnMask { uint stbn_words[]; };
//
// stbn_words holds the mask's u16 values packed two per u32, little-endian: value i is in word
// i / 2, the low half for even i (BlueNoiseMask::packed_words); values are slice-major then
// row-major, index ((frame * H) + y) * W + x.

// Chris Wellons' lowbias32 integer hash (a bijection on uint).
uint lowbias32(uint x) {
    uint h = x;
    h ^= h >> 16u;
    h *= 0x7feb352du;
    h ^= h >> 15u;
    h *= 0x846ca68bu;
    h ^= h >> 16u;
    return h;
}

// A uniform number in [0, 1) for pixel (x, y), frame, the dimension-th decision, and seed.
float white_noise(uint pixel_x, uint pixel_y, uint frame, uint dimension, uint seed) {
    uint h = lowbias32(seed);
    h = lowbias32(h ^ dimension);
    h = lowbias32(h ^ frame);
    h = lowbias32(h ^ pixel_y);
    h = lowbias32(h ^ pixel_x);
    return float(h >> 8u) * (1.0 / 16777216.0);
}

// The mask's toroidal shift for frame's cycle of STBN_DEPTH frames, new every cycle (from the
// seed and the cycle's index), so accumulation keeps converging past one cycle: the twin of
// BlueNoiseMask::cycle_shift.
uvec2 stbn_shift(uint seed, uint frame) {
    uint h = lowbias32(lowbias32(seed) ^ (frame / STBN_DEPTH));
    return uvec2(h & 0xffffu, h >> 16u);
}

// The blue-noise mask's number in [0, 1) at pixel (x, y) of frame `frame`; all three wrap.
float stbn_value(uint x, uint y, uint frame) {
    uint i = ((frame % STBN_DEPTH) * STBN_HEIGHT + (y % STBN_HEIGHT)) * STBN_WIDTH + (x % STBN_WIDTH);
    uint v = (stbn_words[i >> 1u] >> ((i & 1u) * 16u)) & 0xffffu;
    return float(v) * (1.0 / 65536.0);
}
