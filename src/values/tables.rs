//! 1D maps baked into equally spaced tables, the form every backend looks them up in
//! (`scene::maps` bakes them).
//!
//! A table holds `TABLE_SIZE` samples of a map at t = i / (TABLE_SIZE - 1); a lookup clamps t
//! to [0, 1] and interpolates linearly between neighbouring samples. The GPU shaders do the
//! same arithmetic (`shaders_glsl/shared/maps.glsl`), so a baked map means the same thing on
//! every backend. Maps whose control points lie on the sample grid are represented exactly.

pub use super::shader_constants::TABLE_SIZE;

/// Where `t` falls in a table: the lower sample's index and the fraction towards the next.
#[inline]
fn position(t: f64) -> (usize, f64) {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (TABLE_SIZE - 1) as f64;
    let i = (x.floor() as usize).min(TABLE_SIZE - 2);
    (i, x - i as f64)
}

#[inline]
pub fn lookup(table: &[f32], t: f64) -> f64 {
    let (i, f) = position(t);
    let (a, b) = (f64::from(table[i]), f64::from(table[i + 1]));
    a + (b - a) * f
}

#[inline]
pub fn lookup_colour(table: &[[f32; 3]], t: f64) -> [f64; 3] {
    let (i, f) = position(t);
    std::array::from_fn(|c| {
        let (a, b) = (f64::from(table[i][c]), f64::from(table[i + 1][c]));
        a + (b - a) * f
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_aligned_maps_are_exact_and_lookups_clamp() {
        let ramp: Vec<f32> = (0..TABLE_SIZE)
            .map(|i| (0.2 + 0.8 * i as f64 / (TABLE_SIZE - 1) as f64) as f32)
            .collect();
        for t in [0.0, 0.1, 0.37, 0.5, 0.999, 1.0] {
            assert!((lookup(&ramp, t) - (0.2 + 0.8 * t)).abs() < 1e-6, "{t}");
        }
        assert_eq!(lookup(&ramp, -3.0), f64::from(ramp[0]));
        assert_eq!(lookup(&ramp, 7.0), f64::from(ramp[TABLE_SIZE - 1]));
        assert_eq!(lookup(&ramp, f64::NAN), f64::from(ramp[0]));
    }
}
