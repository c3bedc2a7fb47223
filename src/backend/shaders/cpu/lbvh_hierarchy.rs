//! The CPU twin of `shaders_wgsl/lbvh_hierarchy.wgsl`: Karras' internal nodes (LBVH stage 4),
//! the library's [`Lbvh::hierarchy`] over sorted keys, each node's children by
//! [`karras_split`] ([`crate::accel::lbvh`]).

pub use crate::accel::lbvh::{Lbvh, karras_split};
