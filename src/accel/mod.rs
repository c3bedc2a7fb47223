//! Acceleration structures on the CPU: Hilbert keys and order, clusters of K consecutive
//! Hilbert-sorted particles with their bounding boxes, a BVH (obvhs) over those boxes for rays,
//! an LBVH over them in f32 laid out as the GPU holds it (the GPU backends' tree), and a
//! uniform grid of cells for point queries; the particles' spacing (nearest-neighbour distances).

pub mod bvh;
pub mod cells;
pub mod clusters;
pub mod hilbert;
pub mod lbvh;
pub mod overlap;
pub mod spacing;

pub use bvh::ClusterBvh;
pub use cells::{CellGrid, CellRuns};
pub use clusters::{ClusterBoxes, ClusterSize};
pub use hilbert::{HilbertQuantizer, hilbert_key, hilbert_order};
pub use overlap::max_reach_count;
