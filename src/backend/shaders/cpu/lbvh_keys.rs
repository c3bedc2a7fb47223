//! The CPU twin of `shaders_wgsl/lbvh_keys.wgsl`: Morton keys of cluster boxes (LBVH stage 2),
//! the library's ([`crate::accel::lbvh`]).

pub use crate::accel::lbvh::{KeyGrid, expand_bits, morton_key, morton_keys};
