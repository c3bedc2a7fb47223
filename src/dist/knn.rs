//! Smoothing lengths from the K-th nearest neighbour ([`crate::scene::smoothing`]) of a step
//! the ranks hold in parts, without any rank holding the whole step: each particle's length is
//! the single process's ([`knn_lengths`] of the whole step), bit for bit.
//!
//! 1. A k-d tree of P leaves from a sample of the parts ([`decompose`]); one all-to-all-v sends
//!    each position to the rank whose leaf holds it.
//! 2. Each owner finds the K + 1 nearest of its own points (the point itself among them) to
//!    each: the K + 1-th distance bounds the true one from above.
//! 3. A point whose bound reaches past its leaf asks each leaf within it (one all-to-all-v of
//!    queries); the leaf's owner answers with the distances, among its own K + 1 nearest, that
//!    lie within the bound (another). The K + 1-th smallest of the point's own and the answers'
//!    distances is the whole step's: a point of another leaf nearer than the bound lies in a
//!    leaf within the bound, which answered it.
//! 4. Lengths of 0 (K copies of one position) take the step's least positive length, over all
//!    ranks; the owners send each length back to the rank that read the particle, in its
//!    reading order (one all-to-all-v).
//!
//! Every distance is kiddo's squared Euclidean distance of the same two points the single
//! process compares, so the K + 1-th of them is the same number.

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZero;

use super::DistError;
use super::comm::{Comm, CommExt};
use super::exchange::decompose;
use crate::io::{DataError, Part, Problem, StepRef};
use crate::scene::smoothing::{self, NO_SCALE, NeighbourLengths, least_positive_or};

/// The smoothing lengths of this rank's `positions` for `neighbours` (K): the K-th nearest
/// other particle among every rank's positions, as [`crate::scene::smoothing::knn_lengths`]
/// computes it for the whole step. Collective.
pub fn lengths(
    comm: &dyn Comm,
    positions: &[DVec3],
    neighbours: usize,
) -> Result<Vec<f64>, DistError> {
    let total = part_counts(comm, positions)?.iter().sum();
    lengths_among(comm, positions, neighbours, total)
}

/// Every rank's count of `positions`, rank order (one all-gather).
fn part_counts(comm: &dyn Comm, positions: &[DVec3]) -> Result<Vec<usize>, DistError> {
    Ok(comm
        .all_gather_of(&[positions.len() as u64])?
        .iter()
        .map(|c| c.first().copied().unwrap_or(0) as usize)
        .collect())
}

/// [`lengths`] where the ranks' positions number `total` in all.
fn lengths_among(
    comm: &dyn Comm,
    positions: &[DVec3],
    neighbours: usize,
    total: usize,
) -> Result<Vec<f64>, DistError> {
    if total == 0 {
        return Ok(Vec::new());
    }
    let k = neighbours.min(total - 1);
    let ranks = comm.size();
    let tree = decompose(comm, positions, None, None)?;

    // 1. Each position to its owner, in reading order.
    let owners: Vec<usize> = positions.iter().map(|&p| tree.leaf_of(p)).collect();
    let mut send: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    for (p, &owner) in positions.iter().zip(&owners) {
        send[owner].extend_from_slice(&p.to_array());
    }
    let received = comm.all_to_all_of(&send)?;
    drop(send);
    let from_counts: Vec<usize> = received.iter().map(|r| r.len() / 3).collect();
    let owned: Vec<[f64; 3]> = received
        .iter()
        .flat_map(|r| r.chunks_exact(3).map(|c| [c[0], c[1], c[2]]))
        .collect();
    drop(received);

    // 2. The K + 1 nearest among the owned points (squared distances, ascending).
    let nearest = NonZero::new(k + 1).expect("k + 1 >= 1");
    let local_tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&owned);
    let nearest_in = |tree: &ImmutableKdTree<f64, 3>, q: &[f64; 3]| -> Vec<f64> {
        tree.nearest_n::<SquaredEuclidean>(q, nearest)
            .into_iter()
            .map(|n| n.distance)
            .collect()
    };
    let bound = |d: &[f64]| {
        if d.len() == k + 1 {
            d[k]
        } else {
            f64::INFINITY
        }
    };
    // The other leaves within a point's bound. The box's distance is rounded differently from
    // a point's: a margin of 1e-9 of the bound asks a leaf more, never less (an answer beyond
    // the bound is harmless).
    let me = comm.rank();
    let leaves_within = |at: DVec3, within: f64, out: &mut Vec<usize>| {
        out.clear();
        tree.leaves_near(at, within.sqrt(), out);
        out.retain(|&leaf| {
            leaf != me && tree.leaves()[leaf].distance_squared(at) <= within * (1.0 + 1e-9)
        });
    };
    // A point no other leaf comes within the bound of has its length; the others keep their
    // distances for the answers to join (only those: a point's K + 1 distances are 33 f64 for
    // K = 32, and most points lie deep inside their leaf).
    let mut found: Vec<Found> = owned
        .par_iter()
        .map_init(Vec::new, |near, q| {
            let d = nearest_in(&local_tree, q);
            let within = bound(&d);
            leaves_within(DVec3::from_array(*q), within, near);
            if near.is_empty() {
                Found::Length(within)
            } else {
                Found::Asks(d)
            }
        })
        .collect();

    // 3. Queries to the leaves within each bound: (point, bound) to the leaf's owner.
    let mut queries: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    let mut asked: Vec<Vec<u32>> = vec![Vec::new(); ranks];
    let mut near = Vec::new();
    for (i, (q, f)) in owned.iter().zip(&found).enumerate() {
        let Found::Asks(d) = f else { continue };
        let within = bound(d);
        leaves_within(DVec3::from_array(*q), within, &mut near);
        for &leaf in &near {
            queries[leaf].extend_from_slice(&[q[0], q[1], q[2], within]);
            asked[leaf].push(i as u32);
        }
    }
    let incoming = comm.all_to_all_of(&queries)?;
    drop(queries);
    let answers: Vec<Vec<f64>> = incoming
        .par_iter()
        .map(|from| {
            let mut answer = Vec::new();
            for query in from.chunks_exact(4) {
                let q = [query[0], query[1], query[2]];
                let within = query[3];
                let d: Vec<f64> = if owned.is_empty() {
                    Vec::new()
                } else {
                    nearest_in(&local_tree, &q)
                        .into_iter()
                        .filter(|&d| d <= within)
                        .collect()
                };
                answer.push(d.len() as f64);
                answer.extend(d);
            }
            answer
        })
        .collect();
    drop(incoming);
    let replies = comm.all_to_all_of(&answers)?;
    drop(answers);
    for (leaf, reply) in replies.iter().enumerate() {
        let mut at = 0;
        for &i in &asked[leaf] {
            let count = reply
                .get(at)
                .map(|&c| c as usize)
                .filter(|&c| at + 1 + c <= reply.len())
                .ok_or_else(|| {
                    DistError::Malformed(format!("rank {leaf} answered too few neighbour queries"))
                })?;
            if let Found::Asks(d) = &mut found[i as usize] {
                d.extend_from_slice(&reply[at + 1..at + 1 + count]);
            }
            at += 1 + count;
        }
    }
    drop(replies);
    let mut h: Vec<f64> = found
        .into_par_iter()
        .map(|f| match f {
            Found::Length(d) => Ok(d.sqrt()),
            Found::Asks(mut d) => {
                // At least K + 1 distances: a bound of infinity asked every leaf, and the
                // step holds K + 1 particles.
                if d.len() <= k {
                    return Err(DistError::Malformed(format!(
                        "{} neighbour distances for the {}-th nearest",
                        d.len(),
                        k + 1
                    )));
                }
                d.select_nth_unstable_by(k, f64::total_cmp);
                Ok(d[k].sqrt())
            }
        })
        .collect::<Result<_, _>>()?;

    // 4. The least positive length of the step for the lengths of 0, and each length back.
    let mine = least_positive_or(&h, f64::INFINITY);
    let floor = least_positive_or(
        &comm
            .all_gather_of(&[mine])?
            .iter()
            .filter_map(|m| m.first().copied())
            .collect::<Vec<_>>(),
        NO_SCALE,
    );
    for v in &mut h {
        if !(*v > 0.0 && v.is_finite()) {
            *v = floor;
        }
    }
    let mut back: Vec<Vec<f64>> = Vec::with_capacity(ranks);
    let mut at = 0;
    for &count in &from_counts {
        back.push(h[at..at + count].to_vec());
        at += count;
    }
    drop(h);
    let returned = comm.all_to_all_of(&back)?;
    let mut next = vec![0usize; ranks];
    owners
        .iter()
        .map(|&owner| {
            let v = returned[owner].get(next[owner]).copied();
            next[owner] += 1;
            v.ok_or_else(|| {
                DistError::Malformed(format!("rank {owner} returned too few smoothing lengths"))
            })
        })
        .collect()
}

/// What the owner found of a point among its own points.
enum Found {
    /// The squared distance to its K + 1-th nearest, which no other leaf comes nearer than.
    Length(f64),
    /// Its K + 1 nearest squared distances among the owner's points (fewer where the owner
    /// holds fewer), to join with other leaves' answers.
    Asks(Vec<f64>),
}

/// The ranks' [`NeighbourLengths`]: each rank's share of the lengths cached beside the file
/// where every rank finds it there ([`smoothing::cached_part`]), else [`lengths`] over all
/// ranks' parts, written into the cache by every rank at its share's offset. Collective.
pub struct RankLengths<'c> {
    /// The ranks that hold the step's parts.
    pub comm: &'c dyn Comm,
}

impl NeighbourLengths for RankLengths<'_> {
    fn lengths(
        &self,
        step: &StepRef,
        part: Part,
        positions: &[DVec3],
        neighbours: usize,
    ) -> Result<Vec<f64>, DataError> {
        cached_or_found(self.comm, step, positions, neighbours).map_err(|e| {
            e.into_data_error(|other| {
                DataError::new(
                    &step.path,
                    Some(&step.name),
                    Problem::Malformed(format!(
                        "smoothing lengths of rank {} of {}'s part: {other}",
                        part.rank, part.ranks
                    )),
                )
            })
        })
    }
}

fn cached_or_found(
    comm: &dyn Comm,
    step: &StepRef,
    positions: &[DVec3],
    neighbours: usize,
) -> Result<Vec<f64>, DistError> {
    // Where this rank's particles stand in the step: after the parts of the ranks before it.
    let counts = part_counts(comm, positions)?;
    let total: usize = counts.iter().sum();
    let start: usize = counts[..comm.rank()].iter().sum();
    let range = start..start + positions.len();
    let cached = smoothing::cached_part(step, neighbours, total, range.clone());
    let everyone = comm
        .all_gather_of(&[u8::from(cached.is_some())])?
        .iter()
        .all(|c| c.first() == Some(&1));
    if everyone && let Some(h) = cached {
        return Ok(h);
    }
    let h = lengths_among(comm, positions, neighbours, total)?;
    // Rank 0 makes the cache file and names it; each rank writes its share; rank 0 renames
    // it once all have. A cache that cannot be written is skipped.
    let made = if comm.rank() == 0 {
        match smoothing::SharedCache::create(step, neighbours, total) {
            Ok(cache) => Some(cache),
            Err(e) => {
                tracing::debug!("{}: smoothing lengths not cached ({e})", step.name);
                None
            }
        }
    } else {
        None
    };
    let named = made
        .as_ref()
        .map(|c| c.partial.to_string_lossy().into_owned().into_bytes())
        .unwrap_or_default();
    let partial = comm.all_gather_of(&named)?.swap_remove(0);
    let written = if partial.is_empty() {
        false
    } else {
        let path = std::path::PathBuf::from(String::from_utf8_lossy(&partial).into_owned());
        smoothing::SharedCache::write_at(&path, start, &h)
            .inspect_err(|e| tracing::debug!("{}: smoothing lengths not cached ({e})", step.name))
            .is_ok()
    };
    let all_written = comm
        .all_gather_of(&[u8::from(written)])?
        .iter()
        .all(|c| c.first() == Some(&1));
    if let Some(cache) = made
        && let Err(e) = cache.publish(all_written)
    {
        tracing::debug!("{}: smoothing lengths not cached ({e})", step.name);
    }
    Ok(h)
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::dist::run_local;
    use crate::scene::smoothing::knn_lengths;

    /// Clusters of very different densities, copies of one position, a far outlier; in an
    /// order unrelated to space (as a simulation's particle ids leave them).
    fn cloud(n: usize, seed: u64) -> Vec<DVec3> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut points: Vec<DVec3> = (0..n)
            .map(|i| {
                let centre = DVec3::new((i % 3) as f64, 0.5 * (i % 2) as f64, 1e3);
                let scale = [1e-3, 0.1, 0.5][i % 3];
                centre + scale * DVec3::new(rng.random(), rng.random(), rng.random())
            })
            .collect();
        if n > 12 {
            for k in 0..9 {
                points[k + 3] = points[2];
            }
            points[n - 1] = DVec3::new(40.0, -7.0, 1e3);
        }
        points
    }

    /// Each rank's part, cut unevenly (some empty) from the whole step.
    fn parts(n: usize, ranks: usize) -> Vec<std::ops::Range<usize>> {
        let mut cuts: Vec<usize> = (1..ranks).map(|r| (r * r * n) / (ranks * ranks)).collect();
        cuts.insert(0, 0);
        cuts.push(n);
        cuts.windows(2).map(|w| w[0]..w[1]).collect()
    }

    #[test]
    fn the_ranks_lengths_are_the_whole_step_s_bit_for_bit() {
        for (n, seed) in [(1usize, 1u64), (2, 2), (40, 3), (1013, 4)] {
            let points = cloud(n, seed);
            for neighbours in [1, 8, 32, 2000] {
                let whole = knn_lengths(&points, neighbours);
                for ranks in (1..=9).chain([16]) {
                    let cut = parts(n, ranks);
                    let got = run_local(ranks, |comm| {
                        lengths(comm, &points[cut[comm.rank()].clone()], neighbours)
                    })
                    .unwrap();
                    let joined: Vec<u64> = got.concat().iter().map(|h| h.to_bits()).collect();
                    let expected: Vec<u64> = whole.iter().map(|h| h.to_bits()).collect();
                    assert_eq!(joined, expected, "n {n}, K {neighbours}, P {ranks}");
                }
            }
        }
    }
}
