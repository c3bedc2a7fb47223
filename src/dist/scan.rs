//! The exclusive scan of per-pixel optical depths over the bricks in an order: what each
//! brick needs of the bricks before it (the primary rays' depth in front for stochastic
//! marching, the light map's depth nearer the light for shadows). Every rank knows every
//! brick's rectangle (they follow from the k-d tree, the same on all ranks), so each rank
//! sends to each later brick only its values where their rectangles meet, in one all-to-all-v:
//! the traffic is the overlap of the footprints, not the image.

use super::DistError;
use super::comm::{Comm, CommExt};
use crate::values::PixelRect;

/// What [`exclusive_scan`] gave this rank.
#[derive(Clone, Debug)]
pub struct Scanned {
    /// Over `need[rank]`, row-major: the sum of the values of the ranks before this one in the
    /// order (0 where none holds a value), added in that order.
    pub sums: Vec<f64>,
    /// Bytes this rank sent.
    pub bytes_sent: usize,
}

/// Each rank holds `mine` over its rectangle `have[rank]` (row-major) and needs, over
/// `need[rank]`, the sum of the values of every rank before it in `order` (a permutation of
/// the ranks). One all-to-all-v.
pub fn exclusive_scan(
    comm: &dyn Comm,
    order: &[usize],
    have: &[PixelRect],
    need: &[PixelRect],
    mine: &[f64],
) -> Result<Scanned, DistError> {
    let (me, size) = (comm.rank(), comm.size());
    if order.len() != size || have.len() != size || need.len() != size {
        return Err(DistError::Malformed(format!(
            "a scan over {size} ranks with an order of {}, {} rectangles held and {} needed",
            order.len(),
            have.len(),
            need.len()
        )));
    }
    let mut position = vec![usize::MAX; size];
    for (k, &r) in order.iter().enumerate() {
        position[r] = k;
    }
    let mut send = vec![Vec::new(); size];
    let mut bytes_sent = 0;
    for r in 0..size {
        if position[r] <= position[me] {
            continue;
        }
        let overlap = have[me].intersection(&need[r]);
        let values: Vec<f64> = overlap
            .pixels()
            .map(|(x, y)| mine[have[me].index(x, y)])
            .collect();
        bytes_sent += std::mem::size_of_val(values.as_slice());
        send[r] = values;
    }
    let received = comm.all_to_all_of(&send)?;
    let mine_needed = need[me];
    let mut sums = vec![0.0; mine_needed.len()];
    for &s in &order[..position[me]] {
        let overlap = have[s].intersection(&mine_needed);
        let values = &received[s];
        if values.len() != overlap.len() {
            return Err(DistError::Malformed(format!(
                "rank {s} sent {} values for a scan's overlap of {} pixels",
                values.len(),
                overlap.len()
            )));
        }
        for ((x, y), v) in overlap.pixels().zip(values) {
            sums[mine_needed.index(x, y)] += v;
        }
    }
    Ok(Scanned { sums, bytes_sent })
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::dist::run_local;

    /// Against the sum written out: random rectangles and values, any order, P = 1 … 9.
    #[test]
    fn each_rank_gets_the_sum_of_the_ranks_before_it() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for p in 1..=9 {
            let rect = |rng: &mut rand_pcg::Pcg64| {
                let (x0, y0) = (rng.random_range(0..20), rng.random_range(0..20));
                PixelRect {
                    x0,
                    y0,
                    x1: x0 + rng.random_range(0..15),
                    y1: y0 + rng.random_range(0..15),
                }
            };
            let have: Vec<PixelRect> = (0..p).map(|_| rect(&mut rng)).collect();
            let need: Vec<PixelRect> = (0..p).map(|_| rect(&mut rng)).collect();
            let mut order: Vec<usize> = (0..p).collect();
            for i in (1..p).rev() {
                order.swap(i, rng.random_range(0..=i));
            }
            // Values as a function of rank and pixel, so the expected sum can be written out.
            let value = |r: usize, x: u32, y: u32| (r as f64 + 1.0) * 0.37 + f64::from(x * 31 + y);
            let results = run_local(p, |comm| {
                let me = comm.rank();
                let mine: Vec<f64> = have[me].pixels().map(|(x, y)| value(me, x, y)).collect();
                exclusive_scan(comm, &order, &have, &need, &mine).map(|s| s.sums)
            })
            .unwrap();
            for (me, sums) in results.into_iter().enumerate() {
                let before = &order[..order.iter().position(|&r| r == me).unwrap()];
                assert_eq!(sums.len(), need[me].len());
                for (x, y) in need[me].pixels() {
                    let mut expected = 0.0;
                    for &s in before {
                        if have[s].contains(x, y) {
                            expected += value(s, x, y);
                        }
                    }
                    assert_eq!(sums[need[me].index(x, y)], expected, "P = {p}, rank {me}");
                }
            }
        }
    }
}
