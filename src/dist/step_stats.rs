//! A series' statistics of a step ([`StepStats`]: its count, bounds, and each attribute's
//! range, robust range and mean) from the ranks' parts of it, so that opening a series that
//! has no index reads no step whole in any process ([`crate::scene::StepsScan`]). The result
//! is [`StepStats::of`] the whole step, bit for bit:
//! - counts and bytes add; bounds and ranges are minima and maxima;
//! - a mean is the exactly rounded sum over the count ([`crate::values::exact`]): each rank
//!   sends its part's exact sum (integer buckets), and every rank adds them exactly;
//! - the robust range's percentiles are order statistics at the whole step's ranks, found by
//!   an exact selection over the ranks ([`super::order::kth_smallest`]).
//!
//! One all-gather of each part's summary and eight of byte counts per step.

use super::DistError;
use super::comm::{Comm, CommExt};
use super::knn::RankLengths;
use super::order::kth_smallest;
use crate::io::{AttributeSelection, DataError, Part, Problem, StepRef};
use crate::scene::index::{AttributeStats, StepStats, robust_ranks};
use crate::scene::smoothing::{self, Smoothing};
use crate::values::Bounds;
use crate::values::exact::ExactSum;
use glam::DVec3;

/// The statistics of `steps[i]` for each `i` of `which`, in that order, each rank reading its
/// part of each step (`[rN/P, (r+1)N/P)`) with `selection`, and the smoothing lengths from
/// neighbours `smoothing` asks for found by all ranks together ([`super::knn`]). Every rank
/// calls it with the same arguments and gets the same statistics. Returns the records this rank decoded too (its
/// parts' own, for a format that reads a part alone).
pub fn of_parts(
    comm: &dyn Comm,
    steps: &[StepRef],
    which: &[usize],
    selection: &AttributeSelection,
    smoothing: Option<Smoothing>,
) -> Result<(Vec<StepStats>, usize), DistError> {
    // The ranks must agree on what they scan, or their collectives would pair different steps.
    let asked: Vec<u64> = which.iter().map(|&i| i as u64).collect();
    if comm.all_gather_of(&asked)?.iter().any(|a| *a != asked) {
        return Err(DistError::Malformed(
            "the ranks differ in the steps the series' index lacks (was it written while they \
             opened the series?); run again"
                .into(),
        ));
    }
    let mut decoded = 0;
    let mut stats = Vec::with_capacity(which.len());
    for &i in which {
        let Some(step) = steps.get(i) else {
            return Err(DistError::Malformed(format!(
                "step {i} of a series of {}",
                steps.len()
            )));
        };
        let (s, d) = of_part(comm, step, selection, smoothing)?;
        stats.push(s);
        decoded += d;
    }
    Ok((stats, decoded))
}

/// One step's statistics from this rank's part of it, and the records it decoded.
fn of_part(
    comm: &dyn Comm,
    step: &StepRef,
    selection: &AttributeSelection,
    smoothing: Option<Smoothing>,
) -> Result<(StepStats, usize), DistError> {
    let read = smoothing::read_part(
        step,
        selection,
        smoothing,
        Part::new(comm.rank(), comm.size()),
        &RankLengths { comm },
    )?;
    let part = read.step;
    let bounds = part.bounds();
    // The summary, in words: count, bytes, bounds (bits), attributes; per attribute its
    // count, least and largest value (bits) and its exact sum ([`ExactSum::to_words`], length
    // first).
    let mut summary: Vec<u64> = vec![part.len() as u64, part.bytes() as u64];
    summary.extend(bounds.min.to_array().map(f64::to_bits));
    summary.extend(bounds.max.to_array().map(f64::to_bits));
    summary.push(part.attributes.len() as u64);
    for a in &part.attributes {
        let (min, max) =
            crate::values::value_range(&a.values).unwrap_or((f64::INFINITY, f64::NEG_INFINITY));
        let sum = ExactSum::of(&a.values).to_words();
        summary.extend([
            a.values.len() as u64,
            min.to_bits(),
            max.to_bits(),
            sum.len() as u64,
        ]);
        summary.extend(sum);
    }
    let all = comm.all_gather_of(&summary)?;
    let malformed = |what: &str| DistError::Malformed(format!("{}: {what}", step.name));
    let attributes = part.attributes.len();
    let mut count = 0usize;
    let mut bytes = 0usize;
    let mut bounds = Bounds::EMPTY;
    let mut per_attribute = vec![
        (
            0usize,
            f64::INFINITY,
            f64::NEG_INFINITY,
            ExactSum::default()
        );
        attributes
    ];
    for s in &all {
        let at = |k: usize| {
            s.get(k)
                .copied()
                .ok_or_else(|| malformed("a short summary"))
        };
        let real = |k: usize| at(k).map(f64::from_bits);
        count += at(0)? as usize;
        bytes += at(1)? as usize;
        bounds = bounds.union(Bounds {
            min: DVec3::new(real(2)?, real(3)?, real(4)?),
            max: DVec3::new(real(5)?, real(6)?, real(7)?),
        });
        if at(8)? as usize != attributes {
            return Err(malformed("the ranks' parts hold different attributes"));
        }
        let mut k = 9;
        for a in &mut per_attribute {
            a.0 += at(k)? as usize;
            a.1 = a.1.min(real(k + 1)?);
            a.2 = a.2.max(real(k + 2)?);
            let end = k + 4 + at(k + 3)? as usize;
            let words = s
                .get(k + 4..end)
                .ok_or_else(|| malformed("a short summary"))?;
            a.3.merge(&ExactSum::from_words(words).ok_or_else(|| malformed("a sum"))?);
            k = end;
        }
    }
    if count == 0 {
        // As a read of the whole step says.
        return Err(DataError::new(
            &step.path,
            Some(&step.name),
            Problem::EmptyStep(String::new()),
        )
        .into());
    }
    // The robust range's ranks in the whole step.
    let queries: Vec<(&[f64], u64)> = part
        .attributes
        .iter()
        .zip(&per_attribute)
        .flat_map(|(a, &(n, ..))| {
            // n > 0: the step holds particles, and each of them every attribute.
            let (lo, hi) = robust_ranks(n).unwrap_or((0, 0));
            [(&a.values[..], lo as u64), (&a.values[..], hi as u64)]
        })
        .collect();
    let percentiles = kth_smallest(comm, &queries)?;
    let attributes = part
        .attributes
        .iter()
        .zip(per_attribute)
        .zip(percentiles.chunks(2))
        .map(|((a, (n, min, max, sum)), p)| AttributeStats {
            name: a.name.clone(),
            min,
            max,
            p01: p[0],
            p99: p[1],
            mean: sum.value() / n as f64,
            count: n,
        })
        .collect();
    Ok((
        StepStats {
            count,
            bounds,
            bytes,
            attributes,
            all_attributes: *selection == AttributeSelection::All,
        },
        read.decoded,
    ))
}
