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
//! The LBVH: a linear BVH (Karras, "Maximizing parallelism in the construction of BVHs, octrees, and k-d
//! trees", HPG 2012) over cluster boxes: the CPU twin of the wgpu backend's GPU build
//! (`shaders_glsl/wgpu/lbvh_boxes.comp`, `shaders_wgsl/lbvh_*.wgsl`, `shaders_wgsl/radix_sort.wgsl`)
//! and of its traversal (`shaders_glsl/shared/lbvh.glsl`). Every stage here does what the GPU
//! stage does, in the same f32 arithmetic, so the tests compare them: integer stages (keys,
//! sort, hierarchy, parents, depth) bit for bit, float stages (boxes) within a stated tolerance,
//! and the bottom-up bounds exactly (min/max of the same f32 values).
//!
//! # Stages
//! 1. **Cluster boxes** (`lbvh_boxes.comp`): cluster `c` holds particles `cK .. cK+K` (Hilbert
//!    order, local coordinates); its box bounds `[p - r, p + r]` over members with `r > 0`
//!    (`r` = `particle_radius` of `shared/rbf.glsl`). No member left: the box is empty
//!    (`min = +inf, max = -inf`) and the cluster stays out of the tree.
//! 2. **Keys** (`lbvh_keys.wgsl`): a 30-bit Morton key of the box centre on a 1024^3 grid over
//!    the series' bounds (x in the highest bit of each triple); [`LBVH_EMPTY_KEY`] for an empty box,
//!    so empty clusters sort last. The non-empty ones are counted: `n` leaves.
//! 3. **Sort** (`radix_sort.wgsl`): a stable LSD radix sort of (key, cluster) pairs, 4-bit
//!    digits, 8 passes: equal to a stable `sort_by_key`.
//! 4. **Hierarchy** (`lbvh_hierarchy.wgsl`): Karras' internal nodes over the first `n` sorted
//!    keys; duplicate keys are told apart by their sorted index (the key extended by the
//!    index), so the tree is unique and its depth is at most 30 + 32 = 62.
//! 5. **Bottom-up bounds** (`lbvh_fit.wgsl`): each node's box is the union of its children's;
//!    each node's height too. A refit reruns stages 1 and 5 over the same topology.
//!
//! # Node layout (shared with the GPU, 32 bytes a node)
//! `nodes[j]` is 8 words: `[min.x, min.y, min.z, left, max.x, max.y, max.z, right]`, the box as
//! f32 bits and the children as pointers: [`LBVH_LEAF`]` | c` for cluster `c` (whose box is the
//! cluster box), else an internal node's index. Node 0 is a header whose word 3 holds the root
//! pointer ([`LBVH_NONE`] for an empty tree, a leaf pointer for a one-leaf tree, else 1); Karras'
//! internal node `i` is node `i + 1`. Beside it: `node_parents[j]` (the root's is [`LBVH_NONE`])
//! and `leaf_parents[c]` ([`LBVH_NONE`] for a cluster left out, [`LBVH_ROOT_LEAF`] for the only leaf).

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
