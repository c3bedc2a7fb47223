//! The CPU twin of `shaders_wgsl/hilbert_keys.wgsl` and `shaders_glsl/vulkan/hilbert_keys.comp`
//! (preparing a step on the device, the first stage): each particle's 63-bit Hilbert key from its f32 local coordinates, the key
//! [`crate::accel::hilbert_order`] sorts by ([`HilbertQuantizer::key_of_local`]: the cell in
//! two correctly rounded f32 operations, then the 24-state table). The device holds a key as
//! two words, the low 32 bits and the high 31, and sorts by the low word first, then stably by
//! the high one: the order of the 63-bit key, ties in input order.

use rayon::prelude::*;

use crate::accel::HilbertQuantizer;

/// Stage 1: the key of each particle (xyz its local position).
pub fn hilbert_keys(points: &[[f32; 4]], quantizer: &HilbertQuantizer) -> Vec<u64> {
    points
        .par_iter()
        .map(|p| quantizer.key_of_local([p[0], p[1], p[2]]))
        .collect()
}

/// The key's two words as the device holds them: (low 32 bits, high bits).
pub fn key_words(key: u64) -> (u32, u32) {
    (key as u32, (key >> 32) as u32)
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::accel::hilbert_order;
    use crate::values::Bounds;

    /// Sorting the twin's keys (ties by index) is `hilbert_order`, for data far from the
    /// origin written in f64.
    #[test]
    fn sorting_the_keys_of_local_coordinates_is_the_hilbert_order() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let positions: Vec<DVec3> = (0..5000)
            .map(|_| DVec3::new(next(), next(), next()) * 3.7 + DVec3::new(1e6, -2e5, 7.0))
            .collect();
        let bounds = Bounds::of_points(&positions);
        let q = HilbertQuantizer::new(bounds);
        let points: Vec<[f32; 4]> = positions
            .iter()
            .map(|&p| {
                let l = q.local(p);
                [l[0], l[1], l[2], 0.0]
            })
            .collect();
        let keys = hilbert_keys(&points, &q);
        let mut order: Vec<u32> = (0..keys.len() as u32).collect();
        order.sort_by_key(|&i| keys[i as usize]);
        assert_eq!(order, hilbert_order(&positions, bounds));
        assert_eq!(key_words(0x7fff_ffff_0000_0001), (1, 0x7fff_ffff));
    }
}
