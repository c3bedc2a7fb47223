//! [`Comm`] over MPI (rsmpi, the `mpi` feature): the ranks are the processes `mpirun` starts.
//! Each variable-length collective is two MPI calls, the fixed-size exchange of the counts and
//! then the `v` collective itself; MPI's counts and displacements are C ints, so one
//! collective moves at most 2 GiB (more fails with [`CommError::TooLarge`], naming the size).
//! MPI is initialised at thread level Funneled: only the thread that made the communicator
//! calls it (see [`crate::dist::comm`]). An MPI error is fatal to the job (MPI's default
//! handler), and [`Comm::abort`] is `MPI_Abort`: a failing rank ends every rank.

use ::mpi::Count;
use ::mpi::datatype::{Partition, PartitionMut};
use ::mpi::environment::Universe;
use ::mpi::topology::SimpleCommunicator;
use ::mpi::traits::*;

use super::comm::{Comm, CommError, Parts};

/// The world communicator of an MPI job; MPI is finalised when it is dropped.
pub struct MpiComm {
    world: SimpleCommunicator,
    rank: usize,
    size: usize,
    // Last: dropped after the communicator, it finalises MPI.
    _universe: Universe,
}

impl MpiComm {
    /// Initialises MPI (thread level Funneled). `None` when MPI was already initialised in this
    /// process or the library cannot give Funneled.
    pub fn init() -> Option<MpiComm> {
        let (universe, threading) = ::mpi::initialize_with_threading(::mpi::Threading::Funneled)?;
        if threading < ::mpi::Threading::Funneled {
            return None;
        }
        let world = universe.world();
        Some(MpiComm {
            rank: world.rank() as usize,
            size: world.size() as usize,
            world,
            _universe: universe,
        })
    }
}

/// `len` as one of MPI's counts.
fn count(len: usize) -> Result<Count, CommError> {
    Count::try_from(len).map_err(|_| CommError::TooLarge {
        bytes: len,
        limit: Count::MAX as usize,
    })
}

/// The displacements of parts `counts` long laid end to end, and their total.
fn displacements(counts: &[Count]) -> Result<(Vec<Count>, usize), CommError> {
    let mut displs = Vec::with_capacity(counts.len());
    let mut total = 0usize;
    for &c in counts {
        displs.push(count(total)?);
        total += c as usize;
    }
    count(total)?;
    Ok((displs, total))
}

/// Where an empty buffer's (dangling) address is 1, Open MPI reads `MPI_IN_PLACE`, which is
/// `(void *) 1`: empty buffers are handed to MPI at the address of a real byte instead.
static REAL_ADDRESS: [u8; 1] = [0];

/// `bytes`, at an address MPI cannot take for `MPI_IN_PLACE` when it is empty.
fn addressed(bytes: &[u8]) -> &[u8] {
    if bytes.is_empty() {
        &REAL_ADDRESS[..0]
    } else {
        bytes
    }
}

/// A receive buffer of `total` bytes, allocated (at least one byte) even when empty; see
/// [`REAL_ADDRESS`].
fn receive_buffer(total: usize) -> Vec<u8> {
    vec![0u8; total.max(1)]
}

/// What arrived, as [`Parts`].
fn received(mut buffer: Vec<u8>, counts: &[Count]) -> Parts {
    buffer.truncate(counts.iter().map(|&c| c as usize).sum());
    let counts: Vec<usize> = counts.iter().map(|&c| c as usize).collect();
    Parts::from_buffer(buffer, &counts).expect("the receive buffer is the counts' sum")
}

impl Comm for MpiComm {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.size
    }

    fn barrier(&self) -> Result<(), CommError> {
        self.world.barrier();
        Ok(())
    }

    fn all_gather_v(&self, mine: &[u8]) -> Result<Parts, CommError> {
        let my_count = count(mine.len())?;
        let mut counts = vec![0 as Count; self.size];
        self.world.all_gather_into(&my_count, &mut counts[..]);
        let (displs, total) = displacements(&counts)?;
        let mut buffer = receive_buffer(total);
        {
            let mut into = PartitionMut::new(&mut buffer[..total], &counts[..], &displs[..]);
            self.world
                .all_gather_varcount_into(addressed(mine), &mut into);
        }
        Ok(received(buffer, &counts))
    }

    fn all_to_all_v(&self, send: &Parts) -> Result<Parts, CommError> {
        if send.len() != self.size {
            return Err(CommError::WrongPartCount {
                parts: send.len(),
                size: self.size,
            });
        }
        let send_counts: Vec<Count> = send
            .counts()
            .into_iter()
            .map(count)
            .collect::<Result<_, _>>()?;
        let (send_displs, _) = displacements(&send_counts)?;
        let mut recv_counts = vec![0 as Count; self.size];
        self.world
            .all_to_all_into(&send_counts[..], &mut recv_counts[..]);
        let (recv_displs, total) = displacements(&recv_counts)?;
        let mut buffer = receive_buffer(total);
        {
            let from = Partition::new(addressed(send.bytes()), &send_counts[..], &send_displs[..]);
            let mut into =
                PartitionMut::new(&mut buffer[..total], &recv_counts[..], &recv_displs[..]);
            self.world.all_to_all_varcount_into(&from, &mut into);
        }
        Ok(received(buffer, &recv_counts))
    }

    fn gather_v(&self, root: usize, mine: &[u8]) -> Result<Option<Parts>, CommError> {
        let root_process = self.world.process_at_rank(root as ::mpi::Rank);
        let my_count = count(mine.len())?;
        if self.rank != root {
            root_process.gather_into(&my_count);
            root_process.gather_varcount_into(addressed(mine));
            return Ok(None);
        }
        let mut counts = vec![0 as Count; self.size];
        root_process.gather_into_root(&my_count, &mut counts[..]);
        let (displs, total) = displacements(&counts)?;
        let mut buffer = receive_buffer(total);
        {
            let mut into = PartitionMut::new(&mut buffer[..total], &counts[..], &displs[..]);
            root_process.gather_varcount_into_root(addressed(mine), &mut into);
        }
        Ok(Some(received(buffer, &counts)))
    }

    fn abort(&self, message: &str) {
        eprintln!(
            "aarbf: rank {} of {} failed, ending every rank: {message}",
            self.rank, self.size
        );
        self.world.abort(1)
    }
}
