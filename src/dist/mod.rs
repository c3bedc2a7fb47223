//! Distributed rendering: one step split among P ranks, each rendering the samples of its own
//! part of space, composited into the single-rank image (issue 49, `docs/distributed.md`).
//!
//! The flow of a frame, every stage one collective of a [`Comm`]:
//! 1. [`exchange::decompose`]: a k-d tree of P half-open leaves ([`kd`]) from an all-gathered
//!    sample of each rank's particles, the same on every rank;
//! 2. [`exchange::exchange`]: one all-to-all-v sends each particle to the rank owning its leaf,
//!    and as a ghost to every rank whose leaf it reaches (the field's own radius rule);
//! 3. each rank renders its brick: the frame's own sample lattice and noise, only the samples
//!    whose points its leaf holds ([`crate::backend::Backend::render_owned`]), after a pass
//!    that gives it the optical depth of the bricks in front where its rays need it
//!    (stochastic marching's free flight; emission–absorption's early termination across
//!    bricks, [`occlusion`]);
//! 4. [`composite::direct_send`]: one all-to-all-v of the tiles each brick's screen rectangle
//!    touches to their owners, blended in the leaves' front-to-back order;
//! 5. one gather-v of the accumulated tiles to rank 0.
//!
//! [`LocalComm`] runs the ranks as threads of one process (`aarbf render --ranks N`, and the
//! tests); `MpiComm` (the `mpi` feature) runs them as the processes of an MPI job
//! (`mpirun -np N aarbf render`). Every integrator, on the CPU backend: single scattering's
//! free flight and shadow rays cross bricks by exclusive scans of optical depth ([`scan`]),
//! in view order for stochastic marching and in the order from the light for shadows (a light
//! map, [`crate::backend::LightPrefix`]).
//!
//! Before the frames, [`auto`] computes the automatic values that come from the first step
//! (Phi_ref, the mean overlap that chooses the cluster size) from the ranks' parts of it, so
//! that no rank reads a whole step.

pub mod auto;
pub mod balance;
pub(crate) mod clock;
pub mod comm;
pub mod composite;
pub mod exchange;
pub mod kd;
pub mod knn;
pub mod local;
#[cfg(feature = "mpi")]
pub mod mpi_comm;
pub mod occlusion;
pub mod order;
mod render;
pub mod scan;
pub mod step_stats;
pub mod target;

pub use balance::{Balance, CostModel};
pub use comm::{Comm, CommError, CommExt, Parts, launched_rank, launched_size, node_local_size};
pub use local::{LocalComm, run_local};
#[cfg(feature = "mpi")]
pub use mpi_comm::MpiComm;
pub use render::{
    DEFAULT_SHADOW_MAP, DistImage, DistScene, DistShadows, PreparedBrick, RankReport,
    prepare_brick, render_balanced, render_distributed, render_frames_on, render_piloted,
    shadow_map_for, slice_of,
};

use crate::backend::BackendError;
use crate::field::FieldError;

/// Why a distributed render failed.
#[derive(Debug, thiserror::Error)]
pub enum DistError {
    /// A collective failed.
    #[error(transparent)]
    Comm(#[from] CommError),
    /// The backend failed to build or render a brick.
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// This rank's part of the step could not be read.
    #[error(transparent)]
    Read(#[from] crate::io::DataError),
    /// The field settings are invalid for this step.
    #[error(transparent)]
    Field(#[from] FieldError),

    /// A render's settings, or its chunks of frames (a targeted render's), failed.
    #[error(transparent)]
    Render(Box<crate::render::RenderError>),
    /// What a distributed render cannot do yet.
    #[error("{0}")]
    NotDistributed(String),
    /// A message that does not hold what its collective should: a bug, or ranks that disagree.
    #[error("malformed message: {0}")]
    Malformed(String),
    /// The communicator has no ranks.
    #[error("a distributed render needs at least one rank")]
    NoRanks,
    /// A rank's render panicked (threads of [`LocalComm`] only).
    #[error("panicked: {message}")]
    Panicked {
        /// The panic's payload, as text.
        message: String,
    },
    /// A rank's own failure, naming it.
    #[error("rank {rank}: {source}")]
    Rank {
        /// The rank that failed.
        rank: usize,
        /// Its error.
        #[source]
        source: Box<DistError>,
    },
}

impl From<crate::render::RenderError> for DistError {
    fn from(e: crate::render::RenderError) -> DistError {
        DistError::Render(Box::new(e))
    }
}

impl DistError {
    /// A rank's read error as the reader said it (naming the file, the field and the value);
    /// any other error as `otherwise` words it.
    pub fn into_data_error(
        self,
        otherwise: impl FnOnce(DistError) -> crate::io::DataError,
    ) -> crate::io::DataError {
        let e = match self {
            DistError::Rank { source, .. } => *source,
            e => e,
        };
        match e {
            DistError::Read(e) => e,
            other => otherwise(other),
        }
    }

    /// Whether this only reports that another rank failed.
    pub fn is_peer_failure(&self) -> bool {
        match self {
            DistError::Comm(CommError::PeerFailed { .. }) => true,
            DistError::Rank { source, .. } => source.is_peer_failure(),
            DistError::Render(e) => match &**e {
                crate::render::RenderError::Ranks(e) => e
                    .downcast_ref::<DistError>()
                    .is_some_and(DistError::is_peer_failure),
                _ => false,
            },
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests;
