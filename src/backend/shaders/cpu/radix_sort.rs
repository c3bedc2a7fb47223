//! The CPU twin of `shaders_wgsl/radix_sort.wgsl` (LBVH stage 3, and the sorts that prepare a
//! step) and of the ash backend's `shaders_glsl/vulkan/radix_sort.comp`: a stable sort by key,
//! the library's ([`crate::accel::lbvh::sort_pairs`]).

pub use crate::accel::lbvh::sort_pairs;
