//! The CPU twin of `shaders_glsl/shared/maps.glsl`: table lookups in f32.

/// `maps.glsl`'s `map_lookup` in f32: clamp t to [0, 1] (NaN to 0) and interpolate.
pub fn table_lookup_f32(table: &[f32], t: f32) -> f32 {
    let size = table.len() as u32;
    let c = if t >= 0.0 { t.min(1.0) } else { 0.0 };
    let x = c * (size - 1) as f32;
    let i = (x.floor() as u32).min(size - 2);
    let f = x - i as f32;
    let (a, b) = (table[i as usize], table[i as usize + 1]);
    a + (b - a) * f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_lookup_matches_the_f64_tables() {
        let table: Vec<f32> = (0..256).map(|i| (i as f32 / 255.0).powi(2)).collect();
        for t in [-1.0f32, 0.0, 0.3, 0.5, 0.999, 1.0, 2.0, f32::NAN] {
            let a = table_lookup_f32(&table, t);
            let b = crate::values::tables::lookup(&table, f64::from(t));
            assert!((f64::from(a) - b).abs() < 1e-6, "{t}: {a} {b}");
        }
    }
}
