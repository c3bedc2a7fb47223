//! Balancing the decomposition by measured cost (`--balance cost`).
//!
//! A k-d split at the quantile of the particles gives every leaf the same particles, but a
//! brick's render work follows the samples its leaf holds: a leaf that reaches into empty
//! space, or that the camera sees through its long side, renders more for the same
//! particles (`docs/distributed.md`, "Scaling"). A [`CostModel`] keeps what a render
//! measured: each leaf's render seconds per particle it owned. The next decomposition weights
//! every sampled particle by the cost of the leaf that held it, so the quantile splits cost
//! instead of count. The image does not depend on the decomposition, only the time does.

use glam::DVec3;

use super::kd::KdTree;

/// What the leaves of a decomposition are balanced by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Balance {
    /// The same number of particles in each leaf.
    #[default]
    Count,
    /// The same measured render time in each leaf: a pilot render at a quarter of the size
    /// measures each brick's time, and later images of a sequence reuse the last image's.
    Cost,
}

impl std::fmt::Display for Balance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Balance::Count => "count",
            Balance::Cost => "cost",
        })
    }
}

/// The size of the pilot image that measures the cost of the first decomposition balanced
/// by cost: a quarter of each side, a sixteenth of the samples.
pub fn pilot_size(width: u32, height: u32) -> (u32, u32) {
    (width.div_ceil(4), height.div_ceil(4))
}

/// Render seconds per owned particle of each leaf of a decomposition, as measured.
#[derive(Clone, Debug, PartialEq)]
pub struct CostModel {
    tree: KdTree,
    per_particle: Vec<f64>,
}

impl CostModel {
    /// The model of `tree` from each rank's particles owned and render seconds, rank order.
    /// A leaf that owned nothing takes the mean cost of a particle (a particle may move into
    /// it by the next step), and no leaf's cost falls below a thousandth of the mean (a leaf
    /// out of view still costs its exchange and build, and a weight of zero would let one
    /// leaf take every particle that costs nothing now).
    pub fn new(tree: KdTree, owned_and_seconds: &[[f64; 2]]) -> CostModel {
        let (owned, seconds) = owned_and_seconds
            .iter()
            .fold((0.0, 0.0), |(n, t), &[o, s]| (n + o, t + s));
        let mean = if owned > 0.0 && seconds > 0.0 {
            seconds / owned
        } else {
            1.0
        };
        let per_particle = owned_and_seconds
            .iter()
            .map(|&[o, s]| {
                if o > 0.0 {
                    (s / o).max(1e-3 * mean)
                } else {
                    mean
                }
            })
            .collect();
        CostModel { tree, per_particle }
    }

    /// The cost of a particle at `x`: that of the leaf holding it.
    pub fn at(&self, x: DVec3) -> f64 {
        self.per_particle
            .get(self.tree.leaf_of(x))
            .copied()
            .unwrap_or(1.0)
    }

    /// The largest leaf's cost against the mean, as measured (1 is perfect balance).
    pub fn imbalance(seconds: &[f64]) -> f64 {
        let mean = seconds.iter().sum::<f64>() / seconds.len().max(1) as f64;
        let max = seconds.iter().copied().fold(0.0, f64::max);
        if mean > 0.0 { max / mean } else { 1.0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dist::kd::WeightedPoint;

    fn line(n: usize, weight: impl Fn(f64) -> f64) -> Vec<WeightedPoint> {
        (0..n)
            .map(|i| {
                let x = (i as f64 + 0.5) / n as f64;
                WeightedPoint {
                    at: [x, 0.5 * x, 0.25],
                    weight: weight(x),
                    reach: 0.0,
                }
            })
            .collect()
    }

    /// Particles spread evenly on a line, the lower half measured three times as costly a
    /// particle: weighted by the model, the next split gives equal cost, at x = 1/3.
    #[test]
    fn a_costly_leaf_gets_fewer_particles() {
        let by_count = KdTree::build(&line(999, |_| 1.0), 2);
        let split = by_count.leaves()[0].hi.x;
        assert!((split - 0.5).abs() < 2e-3, "{split}");
        let model = CostModel::new(by_count, &[[500.0, 3.0], [499.0, 0.998]]);
        let weighted = line(999, |x| model.at(DVec3::new(x, 0.5 * x, 0.25)));
        let by_cost = KdTree::build(&weighted, 2);
        let split = by_cost.leaves()[0].hi.x;
        assert!((split - 1.0 / 3.0).abs() < 3e-3, "{split}");
    }

    /// An empty leaf costs the mean, a free one a thousandth of it, never zero.
    #[test]
    fn no_leaf_costs_nothing() {
        let tree = KdTree::build(&line(100, |_| 1.0), 3);
        let model = CostModel::new(tree, &[[50.0, 1.0], [0.0, 0.0], [50.0, 0.0]]);
        assert_eq!(model.per_particle, vec![0.02, 0.01, 1e-5]);
        assert_eq!(CostModel::imbalance(&[1.0, 2.0, 3.0]), 1.5);
    }
}
