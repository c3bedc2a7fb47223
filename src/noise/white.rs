//! White noise from an integer hash: one independent uniform number per
//! (pixel, frame, dimension, seed), with no state.
//!
//! The hash is Chris Wellons' `lowbias32` (from his "hash prospector", 2020), a 32-bit
//! xor-shift-multiply finaliser with very low avalanche bias. The inputs are folded in one at a
//! time, each followed by a full hash round, so that neighbouring pixels, frames, dimensions and
//! seeds give unrelated streams.
//!
//! Everything here is u32 wrapping multiply, xor and shift, so the GLSL twin in
//! `shaders_glsl/shared/noise.glsl` (`lowbias32`, `white_noise`) is a line-for-line copy and
//! returns bit-identical results: keep the two in step when editing either.

/// Chris Wellons' `lowbias32` integer hash (a bijection on u32).
#[inline]
pub fn lowbias32(x: u32) -> u32 {
    let mut h = x;
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    h
}

/// A uniform number in [0, 1) for pixel (`pixel_x`, `pixel_y`) of frame `frame`, for the
/// `dimension`-th random decision in that pixel (jitter, free-flight distance, ...), under
/// `seed`. The result has 24 random bits: `(h >> 8) * 2^-24`, exact in f32.
#[inline]
pub fn white(pixel_x: u32, pixel_y: u32, frame: u32, dimension: u32, seed: u32) -> f32 {
    let mut h = lowbias32(seed);
    h = lowbias32(h ^ dimension);
    h = lowbias32(h ^ frame);
    h = lowbias32(h ^ pixel_y);
    h = lowbias32(h ^ pixel_x);
    (h >> 8) as f32 * (1.0 / 16_777_216.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lowbias32_known_values() {
        // Reference values from an independent (Python) implementation, so that a change to
        // the constants is caught; the GLSL twin must produce the same numbers.
        assert_eq!(lowbias32(0), 0);
        assert_eq!(lowbias32(1), 0x6889_90c0);
        assert_eq!(lowbias32(0xdead_beef), 0xe628_c683);
        assert_eq!(white(3, 5, 7, 11, 13) * 16_777_216.0, 3_618_398.0);
    }

    #[test]
    fn white_is_in_unit_interval_with_mean_one_half() {
        let mut sum = 0.0f64;
        let mut sum_sq = 0.0f64;
        let mut n = 0u32;
        for y in 0..64 {
            for x in 0..64 {
                for frame in 0..16 {
                    let v = white(x, y, frame, 0, 7);
                    assert!((0.0..1.0).contains(&v), "{v}");
                    sum += f64::from(v);
                    sum_sq += f64::from(v) * f64::from(v);
                    n += 1;
                }
            }
        }
        let mean = sum / f64::from(n);
        let var = sum_sq / f64::from(n) - mean * mean;
        // n = 65536: the standard error of the mean is 0.289 / 256 = 0.0011.
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        assert!((var - 1.0 / 12.0).abs() < 0.002, "variance {var}");
    }

    /// Pearson correlation of two streams over a 64 x 64 x 4 block.
    fn correlation(a: impl Fn(u32, u32, u32) -> f32, b: impl Fn(u32, u32, u32) -> f32) -> f64 {
        let (mut sa, mut sb, mut saa, mut sbb, mut sab, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for f in 0..4 {
            for y in 0..64 {
                for x in 0..64 {
                    let (u, v) = (f64::from(a(x, y, f)), f64::from(b(x, y, f)));
                    sa += u;
                    sb += v;
                    saa += u * u;
                    sbb += v * v;
                    sab += u * v;
                    n += 1.0;
                }
            }
        }
        let cov = sab / n - sa / n * sb / n;
        let var_a = saa / n - (sa / n) * (sa / n);
        let var_b = sbb / n - (sb / n) * (sb / n);
        cov / (var_a * var_b).sqrt()
    }

    #[test]
    fn streams_are_uncorrelated() {
        // n = 16384 samples: |r| of independent streams is ~ 1/sqrt(n) = 0.008.
        let bound = 0.04;
        let base = |x, y, f| white(x, y, f, 0, 1);
        type Stream<'a> = &'a dyn Fn(u32, u32, u32) -> f32;
        let cases: [(&str, Stream); 6] = [
            ("dimension", &|x, y, f| white(x, y, f, 1, 1)),
            ("seed", &|x, y, f| white(x, y, f, 0, 2)),
            ("next frame", &|x, y, f| white(x, y, f + 1, 0, 1)),
            ("next pixel in x", &|x, y, f| white(x + 1, y, f, 0, 1)),
            ("next pixel in y", &|x, y, f| white(x, y + 1, f, 0, 1)),
            ("swapped x and y", &|x, y, f| white(y, x, f, 0, 1)),
        ];
        for (name, other) in cases {
            let r = correlation(base, other);
            assert!(r.abs() < bound, "{name}: correlation {r}");
        }
    }

    #[test]
    fn deterministic_and_sensitive_to_every_input() {
        let v = white(3, 5, 7, 11, 13);
        assert_eq!(v, white(3, 5, 7, 11, 13));
        for other in [
            white(4, 5, 7, 11, 13),
            white(3, 6, 7, 11, 13),
            white(3, 5, 8, 11, 13),
            white(3, 5, 7, 12, 13),
            white(3, 5, 7, 11, 14),
        ] {
            assert_ne!(v, other);
        }
    }
}
