//! From the particles each rank read to the bricks each renders: the k-d decomposition from
//! an all-gathered sample, then one all-to-all-v that sends each particle to the rank whose
//! leaf holds it and, as a ghost, to every other rank whose leaf it reaches.
//!
//! How far a particle reaches is the project's one rule, [`crate::field::particle_reaches`]
//! (the radius rule under the field's maps), so a brick holds every particle whose support
//! meets its leaf: the field at any point of the leaf is the single-rank field there, summed
//! over the same terms.

use glam::DVec3;

use super::DistError;
use super::balance::CostModel;
use super::comm::{Comm, CommExt};
use super::kd::{KdTree, WeightedPoint};
use crate::values::{Attribute, HalfOpenBox, Step};

/// Points each rank gives the decomposition's sample (evenly strided through what it read;
/// all of them if it read fewer). The issue asks for at least 64.
pub const SAMPLE_PER_RANK: usize = 256;

/// The k-d tree of `comm.size()` leaves over the ranks' particles, from at most
/// [`SAMPLE_PER_RANK`] of each rank's `positions`, each weighted by the particles it stands
/// for (times its cost in `cost`, where given: [`CostModel`]) and reaching as far as its
/// ghost reach in `reaches` (none where not given), which chooses the axes that make the
/// fewest ghosts; every rank gathers the same sample and builds the same tree.
pub fn decompose(
    comm: &dyn Comm,
    positions: &[DVec3],
    reaches: Option<&[f64]>,
    cost: Option<&CostModel>,
) -> Result<KdTree, DistError> {
    let n = positions.len();
    let s = n.min(SAMPLE_PER_RANK);
    let weight = n as f64 / s.max(1) as f64;
    let mine: Vec<WeightedPoint> = (0..s)
        .map(|k| {
            let at = positions[k * n / s];
            WeightedPoint {
                at: at.to_array(),
                weight: weight * cost.map_or(1.0, |c| c.at(at)),
                reach: reaches
                    .and_then(|r| ghost_reach(at, r[k * n / s]))
                    .unwrap_or(0.0),
            }
        })
        .collect();
    let sample: Vec<WeightedPoint> = comm.all_gather_of(&mine)?.concat();
    Ok(KdTree::build(&sample, comm.size()))
}

/// The distance within which a particle of support `reach` centred at `center` is sent as a
/// ghost: the support, plus a margin for rounding (a billionth of the support and of the
/// centre's magnitude, far above the rounding of the distances the field computes in f64,
/// and far below a particle spacing). A particle of support 0 adds to no field and is no
/// ghost.
pub fn ghost_reach(center: DVec3, reach: f64) -> Option<f64> {
    (reach > 0.0).then(|| reach + 1e-9 * (reach + center.abs().max_element()))
}

/// The leaves other than `owner` within a particle's ghost reach, in increasing order.
pub fn ghost_leaves(tree: &KdTree, owner: usize, center: DVec3, reach: f64, out: &mut Vec<usize>) {
    out.clear();
    let Some(within) = ghost_reach(center, reach) else {
        return;
    };
    tree.leaves_near(center, within, out);
    out.retain(|&leaf| {
        leaf != owner && tree.leaves()[leaf].distance_squared(center) <= within * within
    });
    out.sort_unstable();
}

/// One rank's share of a step: the particles its leaf owns, then the ghosts from the other
/// leaves that reach into it.
#[derive(Clone, Debug)]
pub struct Brick {
    /// Owned particles first (from each rank in rank order, each in its reading order), then
    /// the ghosts (likewise).
    pub step: Step,
    /// How many particles at the start of `step` are owned (the rest are ghosts).
    pub owned: usize,
    /// The k-d leaf this rank owns: the part of space whose samples it renders.
    pub leaf: HalfOpenBox,
}

impl Brick {
    /// How many ghost particles `step` holds.
    pub fn ghosts(&self) -> usize {
        self.step.len() - self.owned
    }
}

/// What the exchange moved from this rank.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExchangeCounts {
    /// Bytes this rank sent to other ranks (its own share stays).
    pub bytes_sent: usize,
    /// Ghost copies this rank sent.
    pub ghosts_sent: usize,
}

/// Values a particle's record holds: position, then each attribute.
fn record_len(step: &Step) -> usize {
    3 + step.attributes.len()
}

fn push_record(out: &mut Vec<f64>, step: &Step, i: usize) {
    out.extend_from_slice(&step.positions[i].to_array());
    out.extend(step.attributes.iter().map(|a| a.values[i]));
}

/// Sends each of `local`'s particles to its owner and as a ghost to the leaves it reaches
/// (`reaches[i]` is particle i's support), in one all-to-all-v, and returns this rank's brick.
/// Every rank's step must carry the same attributes in the same order.
pub fn exchange(
    comm: &dyn Comm,
    tree: &KdTree,
    local: &Step,
    reaches: &[f64],
) -> Result<(Brick, ExchangeCounts), DistError> {
    assert_eq!(reaches.len(), local.len(), "one reach per particle");
    let ranks = comm.size();
    let width = record_len(local);
    let mut owned: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    let mut ghosts: Vec<Vec<f64>> = vec![Vec::new(); ranks];
    let mut near = Vec::new();
    let mut ghosts_sent = 0;
    for (i, &center) in local.positions.iter().enumerate() {
        let owner = tree.leaf_of(center);
        push_record(&mut owned[owner], local, i);
        ghost_leaves(tree, owner, center, reaches[i], &mut near);
        for &leaf in &near {
            push_record(&mut ghosts[leaf], local, i);
        }
        ghosts_sent += near.len();
    }
    // Each destination's message: the count of owned records (its bits), then the owned
    // records, then the ghosts.
    let send: Vec<Vec<f64>> = owned
        .into_iter()
        .zip(ghosts)
        .map(|(owned, ghosts)| {
            let mut message = Vec::with_capacity(1 + owned.len() + ghosts.len());
            message.push(f64::from_bits((owned.len() / width) as u64));
            message.extend(owned);
            message.extend(ghosts);
            message
        })
        .collect();
    let me = comm.rank();
    let bytes_sent = send
        .iter()
        .enumerate()
        .filter(|(to, _)| *to != me)
        .map(|(_, m)| m.len() * 8)
        .sum();
    let received = comm.all_to_all_of(&send)?;
    drop(send);
    let mut parts = Vec::with_capacity(ranks);
    for (from, message) in received.iter().enumerate() {
        let Some((&count, records)) = message.split_first() else {
            return Err(DistError::Malformed(format!(
                "rank {from} sent an empty particle message"
            )));
        };
        let owned_values = count.to_bits() as usize * width;
        if !records.len().is_multiple_of(width) || owned_values > records.len() {
            return Err(DistError::Malformed(format!(
                "rank {from} sent {} values for {} owned particles of {width} values each \
                 (do all ranks' steps carry the same attributes?)",
                records.len(),
                count.to_bits()
            )));
        }
        parts.push(records.split_at(owned_values));
    }
    let records = parts
        .iter()
        .map(|(owned, _)| *owned)
        .chain(parts.iter().map(|(_, ghosts)| *ghosts));
    let mut positions = Vec::new();
    let mut attributes: Vec<Attribute> = local
        .attributes
        .iter()
        .map(|a| Attribute {
            name: a.name.clone(),
            values: Vec::new(),
        })
        .collect();
    for values in records {
        for record in values.chunks_exact(width) {
            positions.push(DVec3::new(record[0], record[1], record[2]));
            for (a, &v) in attributes.iter_mut().zip(&record[3..]) {
                a.values.push(v);
            }
        }
    }
    let owned_count = parts.iter().map(|(o, _)| o.len() / width).sum();
    Ok((
        Brick {
            step: Step {
                name: local.name.clone(),
                positions,
                attributes,
            },
            owned: owned_count,
            leaf: tree.leaves()[me],
        },
        ExchangeCounts {
            bytes_sent,
            ghosts_sent,
        },
    ))
}
