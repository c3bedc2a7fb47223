//! What a distributed render asks of its communicator: rank and size, a barrier, and three
//! collectives of variable-length byte buffers, chosen because each is one MPI call (after
//! one fixed-size exchange of the counts): all-gather-v (`MPI_Allgather` of the counts, then
//! `MPI_Allgatherv`), all-to-all-v (`MPI_Alltoall`, then `MPI_Alltoallv`) and gather-v to a
//! root (`MPI_Gather`, then `MPI_Gatherv`). Every rank's calls come from one thread (the one
//! that owns the communicator; rayon's threads never call it), so an MPI implementation needs
//! only `MPI_THREAD_FUNNELED`. Typed helpers ([`CommExt`]) send slices of plain values as
//! their bytes.

use bytemuck::Pod;

/// The environment variables by which MPI launchers tell a process it is one of several
/// (Open MPI, and MPICH / Intel MPI / Slurm's PMI).
const LAUNCHER_SIZE_VARS: [&str; 3] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"];

/// How many processes the MPI launcher says the job has, if this process was started by one.
pub fn launched_size() -> Option<usize> {
    LAUNCHER_SIZE_VARS
        .iter()
        .find_map(|var| std::env::var(var).ok()?.trim().parse().ok())
}

/// This process's rank in the MPI job the launcher says it is one of (`None` outside one).
pub fn launched_rank() -> Option<usize> {
    launched_size()?;
    ["OMPI_COMM_WORLD_RANK", "PMI_RANK", "PMIX_RANK"]
        .iter()
        .find_map(|var| std::env::var(var).ok()?.trim().parse().ok())
}

/// How many ranks of the job share this node (Open MPI and MPICH say), if the launcher says.
pub fn node_local_size() -> Option<usize> {
    ["OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS"]
        .iter()
        .find_map(|var| std::env::var(var).ok()?.trim().parse().ok())
}

/// Why a collective did not complete.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CommError {
    /// Another rank failed (its error, or its panic): every rank's collectives end with this.
    #[error("rank {rank} failed: {message}")]
    PeerFailed {
        /// The rank that failed.
        rank: usize,
        /// Its error or panic message.
        message: String,
    },
    /// Ranks called different collectives at the same point: a bug in the caller.
    #[error("rank {rank} called {theirs} while rank {me} called {mine}")]
    Mismatched {
        /// This rank.
        me: usize,
        /// The collective this rank called.
        mine: &'static str,
        /// The rank that called another collective.
        rank: usize,
        /// The collective that rank called.
        theirs: &'static str,
    },
    /// A buffer's length is not a whole number of the values it should hold.
    #[error(
        "a message of {bytes} bytes from rank {rank} is not a whole number of {size}-byte values"
    )]
    Malformed {
        /// The rank that sent it.
        rank: usize,
        /// Its length in bytes.
        bytes: usize,
        /// The size in bytes of one value it should hold.
        size: usize,
    },
    /// More bytes than one MPI collective can address (its counts and displacements are C ints).
    #[error(
        "{bytes} bytes in one collective is more than MPI can address ({limit}): run more ranks"
    )]
    TooLarge {
        /// Bytes the collective would move.
        bytes: usize,
        /// The most bytes one collective can address (`i32::MAX`).
        limit: usize,
    },
    /// A send that names more or fewer destinations than there are ranks.
    #[error("{parts} parts sent among {size} ranks")]
    WrongPartCount {
        /// Parts the caller gave.
        parts: usize,
        /// Ranks in the communicator.
        size: usize,
    },
}

/// One buffer per rank, stored end to end (as MPI's `v` collectives take and give them).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Parts {
    bytes: Vec<u8>,
    /// `offsets[r]..offsets[r + 1]` is rank r's part.
    offsets: Vec<usize>,
}

impl Parts {
    /// The parts in rank order.
    pub fn from_parts<'a>(parts: impl IntoIterator<Item = &'a [u8]>) -> Parts {
        let mut out = Parts {
            bytes: Vec::new(),
            offsets: vec![0],
        };
        for part in parts {
            out.push(part);
        }
        out
    }

    /// Parts laid end to end in `bytes`, rank r's `counts[r]` long (what MPI's `v` collectives
    /// receive). `None` when the counts do not add up to the buffer's length.
    pub fn from_buffer(bytes: Vec<u8>, counts: &[usize]) -> Option<Parts> {
        let mut offsets = Vec::with_capacity(counts.len() + 1);
        offsets.push(0);
        for &count in counts {
            offsets.push(offsets.last()? + count);
        }
        (*offsets.last()? == bytes.len()).then_some(Parts { bytes, offsets })
    }

    /// Appends the next rank's part.
    pub fn push(&mut self, part: &[u8]) {
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        self.bytes.extend_from_slice(part);
        self.offsets.push(self.bytes.len());
    }

    /// How many parts (ranks) it holds.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Whether it holds no parts.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Rank `r`'s part.
    pub fn part(&self, r: usize) -> &[u8] {
        &self.bytes[self.offsets[r]..self.offsets[r + 1]]
    }

    /// Each part's length in bytes (MPI's counts).
    pub fn counts(&self) -> Vec<usize> {
        self.offsets.windows(2).map(|w| w[1] - w[0]).collect()
    }

    /// All parts end to end (MPI's buffer; [`Parts::counts`] delimits them).
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Bytes in all parts.
    pub fn total(&self) -> usize {
        self.bytes.len()
    }
}

/// A communicator among `size()` ranks. Each rank calls the same collectives in the same
/// order; a collective returns only when every rank has called it (or one has failed).
pub trait Comm {
    /// This rank's index, `0..size()`.
    fn rank(&self) -> usize;

    /// How many ranks the communicator has.
    fn size(&self) -> usize;

    /// Returns when every rank has called it.
    fn barrier(&self) -> Result<(), CommError>;

    /// Every rank's `mine`, in rank order.
    fn all_gather_v(&self, mine: &[u8]) -> Result<Parts, CommError>;

    /// Sends `send.part(r)` to rank r (`send` holds one part per rank, this one's included)
    /// and returns what each rank sent to this one, in rank order.
    fn all_to_all_v(&self, send: &Parts) -> Result<Parts, CommError>;

    /// Every rank's `mine` at `root`, in rank order; `None` on the other ranks.
    fn gather_v(&self, root: usize, mine: &[u8]) -> Result<Option<Parts>, CommError>;

    /// Ends every rank's pending and later collectives with [`CommError::PeerFailed`] naming
    /// this rank and `message` (`MPI_Abort` under MPI, which ends the processes).
    fn abort(&self, message: &str);
}

fn typed<T: Pod>(rank: usize, bytes: &[u8]) -> Result<Vec<T>, CommError> {
    let size = std::mem::size_of::<T>();
    if size == 0 || !bytes.len().is_multiple_of(size) {
        return Err(CommError::Malformed {
            rank,
            bytes: bytes.len(),
            size,
        });
    }
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    // Copied: a part's bytes need not be aligned for T.
    Ok(bytemuck::pod_collect_to_vec(bytes))
}

fn typed_parts<T: Pod>(parts: &Parts) -> Result<Vec<Vec<T>>, CommError> {
    (0..parts.len()).map(|r| typed(r, parts.part(r))).collect()
}

/// The collectives on slices of plain values (sent as their bytes: every rank runs the same
/// build, so layouts and byte order agree).
pub trait CommExt: Comm {
    /// Every rank's `mine`, in rank order.
    fn all_gather_of<T: Pod>(&self, mine: &[T]) -> Result<Vec<Vec<T>>, CommError> {
        typed_parts(&self.all_gather_v(bytemuck::cast_slice(mine))?)
    }

    /// `send[r]` to rank r; what each rank sent here, in rank order.
    fn all_to_all_of<T: Pod>(&self, send: &[Vec<T>]) -> Result<Vec<Vec<T>>, CommError> {
        if send.len() != self.size() {
            return Err(CommError::WrongPartCount {
                parts: send.len(),
                size: self.size(),
            });
        }
        let parts = Parts::from_parts(send.iter().map(|s| bytemuck::cast_slice::<T, u8>(s)));
        typed_parts(&self.all_to_all_v(&parts)?)
    }

    /// Every rank's `mine` at `root`, in rank order; `None` elsewhere.
    fn gather_of<T: Pod>(&self, root: usize, mine: &[T]) -> Result<Option<Vec<Vec<T>>>, CommError> {
        self.gather_v(root, bytemuck::cast_slice(mine))?
            .map(|parts| typed_parts(&parts))
            .transpose()
    }
}

impl<C: Comm + ?Sized> CommExt for C {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_keep_their_boundaries_and_refuse_partial_values() {
        let parts = Parts::from_parts([&[1u8, 2, 3][..], &[], &[4, 5]]);
        assert_eq!(parts.len(), 3);
        assert_eq!(parts.counts(), vec![3, 0, 2]);
        assert_eq!(parts.part(2), &[4, 5]);
        assert_eq!(parts.total(), 5);
        assert!(matches!(
            typed::<u16>(0, parts.part(0)),
            Err(CommError::Malformed {
                size: 2,
                bytes: 3,
                ..
            })
        ));
        assert_eq!(
            typed::<u16>(2, parts.part(2)).unwrap(),
            vec![u16::from_ne_bytes([4, 5])]
        );
        assert!(typed::<f64>(1, parts.part(1)).unwrap().is_empty());
        let rebuilt = Parts::from_buffer(parts.bytes().to_vec(), &parts.counts()).unwrap();
        assert_eq!(rebuilt, parts);
        assert!(Parts::from_buffer(vec![1, 2], &[1]).is_none());
    }
}
