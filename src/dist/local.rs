//! [`LocalComm`]: P ranks as threads of one process, exchanging through shared memory. It is
//! what `aarbf render --ranks N` and the tests run, through the same code path an MPI launch
//! will take: each rank holds only its part of the step and talks to the others only through
//! the [`Comm`] collectives.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use super::DistError;
use super::comm::{Comm, CommError, Parts};

/// One collective's round: each rank deposits its outgoing buffers, then (once all have) takes
/// those addressed to it. A rank that is done taking waits for the others before the next
/// round starts, so a round's mail is never overwritten.
#[derive(Default)]
struct Round {
    /// `mail[to][from]`.
    mail: Vec<Vec<Option<Vec<u8>>>>,
    /// The collective the first depositor of this round called (the others must match).
    kind: Option<(&'static str, usize)>,
    deposited: usize,
    collected: usize,
    /// Every rank has deposited: the round's mail is being taken.
    draining: bool,
    /// The first rank that failed, and why.
    failed: Option<(usize, String)>,
}

struct Shared {
    size: usize,
    round: Mutex<Round>,
    changed: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Round> {
        // A rank that panicked holds no invariant of the round mid-way (it only panics
        // outside it); its failure is reported through `failed`.
        self.round.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn wait<'a>(&self, guard: MutexGuard<'a, Round>) -> MutexGuard<'a, Round> {
        self.changed.wait(guard).unwrap_or_else(|e| e.into_inner())
    }
}

/// One rank's handle on the threads' shared exchange.
pub struct LocalComm {
    rank: usize,
    shared: Arc<Shared>,
}

impl LocalComm {
    /// Handles for `size` ranks, rank order.
    pub fn ranks(size: usize) -> Vec<LocalComm> {
        let shared = Arc::new(Shared {
            size,
            round: Mutex::new(Round {
                mail: vec![vec![None; size]; size],
                ..Round::default()
            }),
            changed: Condvar::new(),
        });
        (0..size)
            .map(|rank| LocalComm {
                rank,
                shared: shared.clone(),
            })
            .collect()
    }

    fn peer_failed(round: &Round) -> Option<CommError> {
        round
            .failed
            .as_ref()
            .map(|(rank, message)| CommError::PeerFailed {
                rank: *rank,
                message: message.clone(),
            })
    }

    /// One round: `outgoing[to]` to each rank; returns what each rank sent here.
    fn exchange(
        &self,
        kind: &'static str,
        mut outgoing: Vec<Option<Vec<u8>>>,
    ) -> Result<Vec<Option<Vec<u8>>>, CommError> {
        let shared = &*self.shared;
        let mut round = shared.lock();
        // Wait for the last round to be taken.
        loop {
            if let Some(e) = Self::peer_failed(&round) {
                return Err(e);
            }
            if !round.draining {
                break;
            }
            round = shared.wait(round);
        }
        match round.kind {
            None => round.kind = Some((kind, self.rank)),
            Some((theirs, rank)) if theirs != kind => {
                let e = CommError::Mismatched {
                    me: self.rank,
                    mine: kind,
                    rank,
                    theirs,
                };
                round.failed = Some((self.rank, e.to_string()));
                shared.changed.notify_all();
                return Err(e);
            }
            Some(_) => {}
        }
        for (to, mail) in outgoing.iter_mut().enumerate() {
            round.mail[to][self.rank] = mail.take();
        }
        round.deposited += 1;
        if round.deposited == shared.size {
            round.draining = true;
            shared.changed.notify_all();
        }
        while !round.draining {
            if let Some(e) = Self::peer_failed(&round) {
                return Err(e);
            }
            round = shared.wait(round);
        }
        let incoming: Vec<Option<Vec<u8>>> =
            round.mail[self.rank].iter_mut().map(Option::take).collect();
        round.collected += 1;
        if round.collected == shared.size {
            round.draining = false;
            round.deposited = 0;
            round.collected = 0;
            round.kind = None;
            shared.changed.notify_all();
        }
        Ok(incoming)
    }
}

fn parts_of(incoming: Vec<Option<Vec<u8>>>) -> Parts {
    let mut parts = Parts::default();
    for part in incoming {
        parts.push(part.as_deref().unwrap_or_default());
    }
    parts
}

impl Comm for LocalComm {
    fn rank(&self) -> usize {
        self.rank
    }

    fn size(&self) -> usize {
        self.shared.size
    }

    fn barrier(&self) -> Result<(), CommError> {
        self.exchange("barrier", vec![None; self.size()])
            .map(|_| ())
    }

    fn all_gather_v(&self, mine: &[u8]) -> Result<Parts, CommError> {
        let outgoing = vec![Some(mine.to_vec()); self.size()];
        self.exchange("all_gather_v", outgoing).map(parts_of)
    }

    fn all_to_all_v(&self, send: &Parts) -> Result<Parts, CommError> {
        if send.len() != self.size() {
            return Err(CommError::WrongPartCount {
                parts: send.len(),
                size: self.size(),
            });
        }
        let outgoing = (0..send.len())
            .map(|r| Some(send.part(r).to_vec()))
            .collect();
        self.exchange("all_to_all_v", outgoing).map(parts_of)
    }

    fn gather_v(&self, root: usize, mine: &[u8]) -> Result<Option<Parts>, CommError> {
        let mut outgoing = vec![None; self.size()];
        outgoing[root] = Some(mine.to_vec());
        let incoming = self.exchange("gather_v", outgoing)?;
        Ok((self.rank == root).then(|| parts_of(incoming)))
    }

    fn abort(&self, message: &str) {
        let mut round = self.shared.lock();
        if round.failed.is_none() {
            round.failed = Some((self.rank, message.to_owned()));
        }
        self.shared.changed.notify_all();
    }
}

/// The text of a panic's payload.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic".to_owned())
}

/// Runs `body` on `ranks` ranks, each a thread with its [`LocalComm`], and returns their
/// results in rank order. A rank that fails (returns an error or panics) aborts the others'
/// collectives; the error returned is the failing rank's own, naming it (not the others'
/// report that a peer failed).
pub fn run_local<T: Send>(
    ranks: usize,
    body: impl Fn(&LocalComm) -> Result<T, DistError> + Sync,
) -> Result<Vec<T>, DistError> {
    if ranks == 0 {
        return Err(DistError::NoRanks);
    }
    let comms = LocalComm::ranks(ranks);
    let body = &body;
    let results: Vec<Result<T, DistError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = comms
            .into_iter()
            .map(|comm| {
                std::thread::Builder::new()
                    .name(format!("rank-{}", comm.rank))
                    .spawn_scoped(scope, move || {
                        let rank = comm.rank;
                        let result = match catch_unwind(AssertUnwindSafe(|| body(&comm))) {
                            Ok(result) => result,
                            Err(payload) => Err(DistError::Panicked {
                                message: panic_text(payload.as_ref()),
                            }),
                        };
                        result.map_err(|e| {
                            comm.abort(&e.to_string());
                            DistError::Rank {
                                rank,
                                source: Box::new(e),
                            }
                        })
                    })
                    .expect("a thread for a rank")
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("rank threads catch their panics"))
            .collect()
    });
    let mut first_failure = None;
    let mut out = Vec::with_capacity(ranks);
    for result in results {
        match result {
            Ok(value) => out.push(value),
            Err(e) => {
                let own = !e.is_peer_failure();
                match &first_failure {
                    Some((true, _)) => {}
                    Some((false, _)) if !own => {}
                    _ => first_failure = Some((own, e)),
                }
            }
        }
    }
    match first_failure {
        Some((_, e)) => Err(e),
        None => Ok(out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::comm::CommExt;

    #[test]
    fn collectives_deliver_every_rank_s_parts_in_rank_order() {
        for p in [1, 2, 3, 5] {
            let out = run_local(p, |comm| {
                let r = comm.rank();
                // Three rounds in a row: a fast rank must not overwrite a slow one's mail.
                let mut seen = Vec::new();
                for round in 0..3u32 {
                    let gathered = comm.all_gather_of(&[r as u32 * 10 + round])?;
                    assert_eq!(
                        gathered,
                        (0..p)
                            .map(|s| vec![s as u32 * 10 + round])
                            .collect::<Vec<_>>()
                    );
                    // Rank r sends (to + 1) copies of r * 100 + to to each rank `to`.
                    let send: Vec<Vec<u64>> = (0..p)
                        .map(|to| vec![(r * 100 + to) as u64; to + 1])
                        .collect();
                    let got = comm.all_to_all_of(&send)?;
                    for (from, part) in got.iter().enumerate() {
                        assert_eq!(part, &vec![(from * 100 + r) as u64; r + 1]);
                    }
                    let at_root = comm.gather_of(p - 1, &[r as f64; 2])?;
                    if r == p - 1 {
                        let at_root = at_root.expect("the root gets the parts");
                        assert_eq!(at_root.len(), p);
                        for (from, part) in at_root.iter().enumerate() {
                            assert_eq!(part, &vec![from as f64; 2]);
                        }
                    } else {
                        assert!(at_root.is_none());
                    }
                    comm.barrier()?;
                    seen.push(round);
                }
                Ok(seen)
            })
            .unwrap();
            assert_eq!(out, vec![vec![0, 1, 2]; p]);
        }
    }

    #[test]
    fn a_failing_rank_ends_the_others_and_is_named() {
        for fails_by_panic in [false, true] {
            let err = run_local(4, |comm| {
                comm.barrier()?;
                if comm.rank() == 2 {
                    if fails_by_panic {
                        panic!("rank two fell over");
                    }
                    return Err(DistError::NotDistributed("a test's refusal".into()));
                }
                // The others wait in a collective rank 2 never joins.
                comm.all_gather_of(&[1u8])?;
                Ok(())
            })
            .unwrap_err();
            let text = err.to_string();
            assert!(text.starts_with("rank 2: "), "{text}");
            let expected = if fails_by_panic {
                "rank two fell over"
            } else {
                "a test's refusal"
            };
            assert!(text.contains(expected), "{text}");
        }
    }

    #[test]
    fn mismatched_collectives_are_reported_not_hung() {
        let err = run_local(2, |comm| {
            if comm.rank() == 0 {
                comm.barrier()?;
            } else {
                comm.all_gather_of(&[1u8])?;
            }
            Ok(())
        })
        .unwrap_err();
        assert!(err.to_string().contains("called"), "{err}");
    }
}
