//! The CPU twin of `shaders_glsl/shared/lbvh.glsl` (the point-query traversal,
//! [`Lbvh::for_each_cluster_at`]) over the LBVH as the GPU holds it: both are the library's
//! ([`crate::accel::lbvh`], whose documentation describes the build and the node layout), which
//! the ash backend builds its tree with; the twins of the build's stages are the files beside
//! this one.

pub use crate::accel::lbvh::{
    BOX_BYTES, EMPTY_BOX, GpuBox, LBVH_EMPTY_KEY, LBVH_LEAF, LBVH_NONE, LBVH_ROOT_LEAF,
    LBVH_SENTINEL, LBVH_STACK_SIZE, Lbvh, MORTON_CELLS, NODE_BYTES, NODE_WORDS, box_contains,
    box_is_empty, children, structure_bytes,
};
