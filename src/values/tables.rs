//! 1D maps baked into equally spaced tables, the form every backend looks them up in
//! (`scene::maps` bakes them).
//!
//! A table holds `TABLE_SIZE` samples of a map at t = i / (TABLE_SIZE - 1); a lookup clamps t
//! to [0, 1] and interpolates linearly between neighbouring samples. The GPU shaders do the
//! same arithmetic (`shaders_glsl/shared/maps.glsl`), so a baked map means the same thing on
//! every backend. Maps whose control points lie on the sample grid are represented exactly.

use num_traits::Float;

pub use super::shader_constants::TABLE_SIZE;

/// Where `t` falls in a table of `len` samples: the lower sample's index and the fraction
/// towards the next. Written as `maps.glsl`'s `table_position` is, in any precision: t is
/// clamped to [0, 1] (NaN to 0).
#[inline]
fn position<F: Float>(t: F, len: usize) -> (usize, F) {
    let c = if t >= F::zero() {
        t.min(F::one())
    } else {
        F::zero()
    };
    let x = c * F::from(len - 1).expect("a table size fits any float");
    // x >= 0 (NaN is gone above), so truncation is the floor, without a libm call on
    // targets without SSE4.1.
    let i = x.to_usize().unwrap_or(0).min(len - 2);
    (i, x - F::from(i).expect("an index fits any float"))
}

/// The map behind `table` at `t`: linear between neighbouring samples. At f32 this is the
/// CPU twin of `maps.glsl`'s `map_lookup` (same operations, same order); at f64 it is what the
/// reference field and the CPU renderer use.
#[inline]
pub fn lookup<F: Float>(table: &[f32], t: F) -> F {
    let (i, f) = position(t, table.len());
    let (a, b) = (as_float::<F>(table[i]), as_float::<F>(table[i + 1]));
    a + (b - a) * f
}

/// The colour map behind `table` at `t` (`maps.glsl`'s `colour_lookup`).
#[inline]
pub fn lookup_colour<F: Float>(table: &[[f32; 3]], t: F) -> [F; 3] {
    let (i, f) = position(t, table.len());
    std::array::from_fn(|c| {
        let (a, b) = (as_float::<F>(table[i][c]), as_float::<F>(table[i + 1][c]));
        a + (b - a) * f
    })
}

/// The largest sample of a table (the map's largest value as every backend sees it).
pub fn table_max(table: &[f32]) -> f64 {
    table
        .iter()
        .fold(f64::NEG_INFINITY, |m, &v| m.max(f64::from(v)))
}

/// The steepest relative slope of the map behind `table`, per unit of t: the largest
/// `|b - a| (len - 1) / min(a, b)` over neighbouring samples a, b (what a rounding of t costs
/// a looked-up value, relative to it). Where a segment falls to 0 its larger end stands in for
/// the smaller: the value near 0 adds nearly nothing beside its neighbours. 0 for a constant
/// map.
pub fn steepest_relative_slope(table: &[f32]) -> f64 {
    let steps = table.len().saturating_sub(1) as f64;
    table
        .windows(2)
        .map(|w| {
            let (a, b) = (f64::from(w[0]).abs(), f64::from(w[1]).abs());
            let base = if a.min(b) > 0.0 { a.min(b) } else { a.max(b) };
            if base > 0.0 {
                (b - a).abs() * steps / base
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}

/// The smallest positive and the largest value the map behind `table` can give: between a
/// sample and a 0 the lookup's fraction (f32, at least 2^-24 where it is not 0) scales the
/// sample. (0, 0) where every sample is 0.
pub fn value_extremes(table: &[f32]) -> (f64, f64) {
    let positive = || table.iter().map(|&v| f64::from(v)).filter(|&v| v > 0.0);
    let smallest = positive().fold(f64::INFINITY, f64::min);
    let largest = positive().fold(0.0, f64::max);
    if !smallest.is_finite() {
        return (0.0, 0.0);
    }
    let reaches_zero = table.iter().any(|&v| v <= 0.0);
    let scale = if reaches_zero {
        f64::from(f32::EPSILON) / 2.0
    } else {
        1.0
    };
    (smallest * scale, largest)
}

#[inline]
fn as_float<F: Float>(v: f32) -> F {
    F::from(v).expect("an f32 fits any float")
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
        // The f32 lookup (the GPU's arithmetic) agrees with the f64 one to f32 rounding.
        for t in [-1.0f32, 0.0, 0.3, 0.5, 0.999, 1.0, 2.0, f32::NAN] {
            let a = lookup(&ramp, t);
            let b = lookup(&ramp, f64::from(t));
            assert!((f64::from(a) - b).abs() < 1e-6, "{t}: {a} {b}");
        }
        assert_eq!(lookup(&ramp, 7.0), f64::from(ramp[TABLE_SIZE - 1]));
        assert_eq!(lookup(&ramp, f64::NAN), f64::from(ramp[0]));
    }
}
