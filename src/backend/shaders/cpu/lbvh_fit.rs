//! The CPU twin of `shaders_wgsl/lbvh_fit.wgsl`: bottom-up bounds and heights (LBVH stage 5),
//! for builds ([`Lbvh::fit`]) and refits ([`Lbvh::refit`]), the library's
//! ([`crate::accel::lbvh`]).

pub use crate::accel::lbvh::Lbvh;
