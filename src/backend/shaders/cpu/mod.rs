//! The CPU twins of the GPU stages, one file per stage (as vello's `cpu/`), each doing what its
//! stage does in the same f32 arithmetic so the tests can compare them. A twin has its stage's
//! name (`lbvh_boxes.rs` ↔ `shaders_glsl/wgpu/lbvh_boxes.comp` ↔ `on_wgpu::LBVH_BOXES`); a
//! twin of a shared include has the include's (`rbf.rs` ↔ `shaders_glsl/shared/rbf.glsl`).
//! `shaders::table`'s tests fail when a shader has no twin or a twin no shader.
//!
//! Preparing a step on the device (`wgpu_lbvh::prepare`): Hilbert keys of the particles' f32
//! local coordinates (`hilbert_keys.wgsl`, 63 bits as two words), a stable radix sort by the
//! low word and then by the high one (`radix_sort.wgsl`, with the high words gathered into
//! the order of the first sort between the two, `gather.wgsl`), and the particles, lo parts and
//! radius attribute gathered into the sorted order (`gather.wgsl`): keys and order bit for bit
//! those of [`crate::accel::hilbert_order`].
//!
//! The LBVH's twins (`lbvh*.rs`, `radix_sort.rs`, the box rule in `cluster_box.rs`) are thin:
//! the LBVH is the library's ([`crate::accel::lbvh`], whose documentation describes its stages
//! and node layout), built in the same f32 arithmetic as the wgpu backend's GPU build
//! (`shaders_glsl/wgpu/lbvh_boxes.comp`, `shaders_wgsl/lbvh_*.wgsl`,
//! `shaders_wgsl/radix_sort.wgsl`) and walked as its traversal (`shaders_glsl/shared/lbvh.glsl`)
//! walks it, and the ash backend builds its software-traversal tree with it; so the tests that
//! compare the GPU's stages with these twins check the ash backend's builder too.

pub mod blas_boxes;
pub mod cluster_box;
pub mod gather;
pub mod hilbert_keys;
pub mod lbvh;
pub mod lbvh_boxes;
pub mod lbvh_fit;
pub mod lbvh_hierarchy;
pub mod lbvh_keys;
pub mod radix_sort;
pub mod rbf;

pub use lbvh::Lbvh;
