//! Acceleration structures on the CPU: Hilbert keys and order, clusters of K consecutive
//! Hilbert-sorted particles with their bounding boxes, and a BVH (obvhs) over those boxes.

pub mod bvh;
pub mod clusters;
pub mod hilbert;

pub use bvh::ClusterBvh;
pub use clusters::{ClusterBoxes, ClusterSize};
pub use hilbert::{HilbertQuantizer, hilbert_key, hilbert_order};
