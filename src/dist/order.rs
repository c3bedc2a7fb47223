//! Exact order statistics of values spread over the ranks: the k-th smallest of all the
//! ranks' values, the value a single process finds by sorting them all (in `f64::total_cmp`'s
//! order, [`crate::values::exact::order_key`]), without any rank holding them all.
//!
//! A radix selection on the values' 64-bit order keys, a byte at a time from the top: each
//! rank counts its candidates per byte value, one all-gather adds the counts, every rank picks
//! the byte under which the k-th lies and keeps only its candidates there. Eight all-gathers
//! of 256 counts per query, whatever the number of values; every query of a call shares them.

use super::DistError;
use super::comm::{Comm, CommExt};
use crate::values::exact::{from_order_key, order_key};

/// For each query `(values, k)`, the k-th smallest (from 0) of every rank's `values` together.
/// Collective: every rank asks the same number of queries, with the same `k` each.
pub fn kth_smallest(comm: &dyn Comm, queries: &[(&[f64], u64)]) -> Result<Vec<f64>, DistError> {
    let q = queries.len();
    if q == 0 {
        return Ok(Vec::new());
    }
    let mut prefix = vec![0u64; q];
    let mut rank_left: Vec<u64> = queries.iter().map(|&(_, k)| k).collect();
    // Each query's candidates: after the first byte, the keys under the bytes chosen so far.
    let mut candidates: Vec<Vec<u64>> = vec![Vec::new(); q];
    for byte in 0..8 {
        let shift = 56 - 8 * byte;
        let mut counts = vec![0u64; q * 256];
        for (j, &(values, _)) in queries.iter().enumerate() {
            let count = &mut counts[j * 256..(j + 1) * 256];
            if byte == 0 {
                for &v in values {
                    count[(order_key(v) >> 56) as usize] += 1;
                }
            } else {
                for &key in &candidates[j] {
                    count[((key >> shift) & 255) as usize] += 1;
                }
            }
        }
        let all = comm.all_gather_of(&counts)?;
        for j in 0..q {
            let mut below = 0u64;
            let mut chosen = None;
            for digit in 0..256 {
                let n: u64 = all
                    .iter()
                    .map(|c| c.get(j * 256 + digit).copied().unwrap_or(0))
                    .sum();
                if rank_left[j] < below + n {
                    chosen = Some(digit as u64);
                    break;
                }
                below += n;
            }
            let Some(digit) = chosen else {
                return Err(DistError::Malformed(format!(
                    "the {}-th smallest of {below} values asked for",
                    queries[j].1
                )));
            };
            rank_left[j] -= below;
            prefix[j] |= digit << shift;
            if byte == 0 {
                candidates[j] = queries[j]
                    .0
                    .iter()
                    .map(|&v| order_key(v))
                    .filter(|key| key >> 56 == digit)
                    .collect();
            } else {
                candidates[j].retain(|key| (key >> shift) & 255 == digit);
            }
        }
    }
    Ok(prefix.into_iter().map(from_order_key).collect())
}

/// The median of every rank's `values` together: the value at rank `n / 2` in sorted order of
/// all `n` (`None` for none), as a single process that holds them all takes it.
pub fn median(comm: &dyn Comm, values: &[f64]) -> Result<Option<f64>, DistError> {
    let n: u64 = comm
        .all_gather_of(&[values.len() as u64])?
        .iter()
        .map(|c| c.first().copied().unwrap_or(0))
        .sum();
    if n == 0 {
        return Ok(None);
    }
    Ok(kth_smallest(comm, &[(values, n / 2)])?.first().copied())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::run_local;

    /// Values as simulations hold them: repeats, both zeros, subnormals, a wide range.
    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
        (0..n)
            .map(|i| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let u = (state >> 11) as f64 / (1u64 << 53) as f64;
                match i % 7 {
                    0 => 0.0,
                    1 => -0.0,
                    2 => (u * 10.0).floor(),
                    3 => 5e-324 * (u * 4.0).floor(),
                    4 => -(u * 1e300),
                    _ => (u - 0.5) * 17.3,
                }
            })
            .collect()
    }

    #[test]
    fn every_rank_finds_the_whole_sort_s_value() {
        for ranks in [1, 2, 3, 5, 9] {
            for n in [1usize, 2, 7, 100, 1001] {
                let all = values(n, (ranks * 1000 + n) as u64);
                let mut sorted = all.clone();
                sorted.sort_by(f64::total_cmp);
                let ks: Vec<u64> = [0, n / 100, n / 2, (99 * (n - 1)).div_ceil(100), n - 1]
                    .map(|k| k as u64)
                    .to_vec();
                let found = run_local(ranks, |comm| {
                    // Uneven parts, some empty.
                    let r = comm.rank();
                    let cut = |r: usize| (r * r * n) / (ranks * ranks);
                    let mine = &all[cut(r)..cut(r + 1)];
                    let queries: Vec<(&[f64], u64)> = ks.iter().map(|&k| (mine, k)).collect();
                    kth_smallest(comm, &queries)
                })
                .unwrap();
                for (rank, got) in found.iter().enumerate() {
                    for (&k, g) in ks.iter().zip(got) {
                        assert_eq!(
                            g.to_bits(),
                            sorted[k as usize].to_bits(),
                            "P = {ranks}, n = {n}, k = {k}, rank {rank}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_rank_past_the_values_is_an_error() {
        let result = run_local(3, |comm| kth_smallest(comm, &[(&[1.0, 2.0][..], 6)]));
        assert!(result.is_err());
    }
}
