//! The CPU twin of `shaders_wgsl/radix_sort.wgsl` (LBVH stage 3, and the sorts that prepare a
//! step) and of the ash backend's `shaders_glsl/vulkan/radix_sort.comp`: a
//! stable sort by key.

/// Stage 3: (key, value) pairs sorted stably by key, values the input indices.
pub fn sort_pairs(keys: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut values: Vec<u32> = (0..keys.len() as u32).collect();
    values.sort_by_key(|&i| keys[i as usize]);
    (values.iter().map(|&i| keys[i as usize]).collect(), values)
}
