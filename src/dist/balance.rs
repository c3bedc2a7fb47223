//! Balancing the decomposition by measured cost (`--balance cost`).
//!
//! A k-d split at the quantile of the particles gives every leaf the same particles, but a
//! brick's render work follows the samples its leaf holds: a leaf that reaches into empty
//! space, or that the camera sees through its long side, renders more for the same
//! particles (`docs/distributed.md`, "Scaling"). A [`CostModel`] keeps what renders
//! measured: each leaf's seconds (its render and its light map) per particle it owned,
//! corrected by each later
//! render's leaves. The next decomposition weights every sampled particle by its cost there,
//! so the quantile splits cost instead of count. The image does not depend on the
//! decomposition, only the time does.

use glam::DVec3;

use super::kd::KdTree;

/// What the leaves of a decomposition are balanced by.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Balance {
    /// The same number of particles in each leaf.
    #[default]
    Count,
    /// The same measured render time in each leaf: two pilot renders at a quarter of the size
    /// measure each brick's time (the second balanced by the first), and each later image of
    /// a sequence corrects the balance by the last image's.
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
    (pilot_side(width), pilot_side(height))
}

/// A side of a pilot's image, or of its light map: a quarter of the image's (the map's), so
/// that the pilot's light map is to its render what the image's is to the image's, and the
/// measured cost of a brick weighs the two as the image will.
pub fn pilot_side(side: u32) -> u32 {
    side.div_ceil(4)
}

/// How many decompositions' measurements a [`CostModel`] keeps: each corrects the model the
/// decomposition was balanced by, leaf by leaf, so together they resolve the cost more finely
/// than any one decomposition's P leaves (where a brick's cost moves with the decomposition
/// itself, as where the bricks in front end the rays of those behind, one leaf's mean cost
/// mispredicts the next leaf's).
pub const KEPT_MEASUREMENTS: usize = 3;

/// A render's cost per particle, as measured: a product of corrections, each a factor per leaf
/// of one decomposition ([`CostModel::at`]).
#[derive(Clone, Debug, PartialEq)]
pub struct CostModel {
    /// Oldest first, at most [`KEPT_MEASUREMENTS`].
    layers: Vec<(KdTree, Vec<f64>)>,
}

impl CostModel {
    /// The model of `tree` from each rank's particles owned and render seconds, rank order:
    /// each leaf's seconds per particle. See [`CostModel::refined`].
    pub fn new(tree: KdTree, owned_and_seconds: &[[f64; 2]]) -> CostModel {
        let predicted: Vec<[f64; 3]> = owned_and_seconds.iter().map(|&[o, s]| [o, s, o]).collect();
        CostModel::refined(None, tree, &predicted)
    }

    /// What a render of the decomposition `tree`, balanced by `used` (by count where `None`),
    /// measured, from each rank's `[particles owned, render seconds, the cost `used` predicted
    /// for its owned particles (their count where `None`)]`, rank order: `used` times a factor
    /// per leaf of `tree`, the leaf's seconds over its predicted cost. A leaf that owned
    /// nothing takes the mean factor (a particle may move into it by the next step), and no
    /// factor falls below a thousandth of the mean (a leaf out of view still costs its exchange
    /// and build, and a weight of zero would let one leaf take every particle that costs
    /// nothing now).
    pub fn refined(
        used: Option<&CostModel>,
        tree: KdTree,
        owned_seconds_predicted: &[[f64; 3]],
    ) -> CostModel {
        let (predicted, seconds) = owned_seconds_predicted
            .iter()
            .fold((0.0, 0.0), |(p, t), &[_, s, c]| (p + c, t + s));
        let mean = if predicted > 0.0 && seconds > 0.0 {
            seconds / predicted
        } else {
            1.0
        };
        let factors = owned_seconds_predicted
            .iter()
            .map(|&[o, s, c]| {
                if o > 0.0 && c > 0.0 {
                    (s / c).max(1e-3 * mean)
                } else {
                    mean
                }
            })
            .collect();
        let mut layers = used.map_or_else(Vec::new, |u| u.layers.clone());
        layers.push((tree, factors));
        if layers.len() > KEPT_MEASUREMENTS {
            layers.drain(..layers.len() - KEPT_MEASUREMENTS);
        }
        CostModel { layers }
    }

    /// The cost of a particle at `x`: the product of the factors of the leaves holding it.
    pub fn at(&self, x: DVec3) -> f64 {
        self.layers
            .iter()
            .map(|(tree, factors)| factors.get(tree.leaf_of(x)).copied().unwrap_or(1.0))
            .product()
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

    /// Where the cost is not constant over a leaf, one measurement mispredicts the next
    /// decomposition's leaves; the corrections of a second and third render resolve it more
    /// finely: a cost rising steeply along a line, four leaves.
    #[test]
    fn later_measurements_correct_the_model_leaf_by_leaf() {
        let cost = |x: f64| 0.2 + 12.0 * x.powi(3);
        let points = |model: Option<&CostModel>| {
            line(4001, |x| {
                model.map_or(1.0, |m| m.at(DVec3::new(x, 0.5 * x, 0.25)))
            })
        };
        // What a render of `tree` balanced by `model` measures: each leaf's particles, true
        // seconds and predicted cost.
        let measure = |tree: &KdTree, model: Option<&CostModel>| -> Vec<[f64; 3]> {
            let mut m = vec![[0.0; 3]; 4];
            for p in points(None) {
                let x = DVec3::from_array(p.at);
                let leaf = &mut m[tree.leaf_of(x)];
                leaf[0] += 1.0;
                leaf[1] += cost(p.at[0]);
                leaf[2] += model.map_or(1.0, |c| c.at(x));
            }
            m
        };
        let mut model: Option<CostModel> = None;
        let mut imbalances = Vec::new();
        for _ in 0..4 {
            let tree = KdTree::build(&points(model.as_ref()), 4);
            let measured = measure(&tree, model.as_ref());
            imbalances.push(CostModel::imbalance(
                &measured.iter().map(|m| m[1]).collect::<Vec<_>>(),
            ));
            model = Some(CostModel::refined(model.as_ref(), tree, &measured));
        }
        eprintln!("slowest leaf / mean, by count then each correction: {imbalances:.3?}");
        assert_eq!(model.unwrap().layers.len(), KEPT_MEASUREMENTS);
        // By count, one correction, two, three.
        assert!(imbalances[0] > 2.5, "{imbalances:?}");
        assert!(imbalances[1] > 1.1, "{imbalances:?}");
        assert!(imbalances[2] < 1.1, "{imbalances:?}");
        assert!(imbalances[3] < 1.05, "{imbalances:?}");
    }

    /// An empty leaf costs the mean, a free one a thousandth of it, never zero.
    #[test]
    fn no_leaf_costs_nothing() {
        let tree = KdTree::build(&line(100, |_| 1.0), 3);
        let model = CostModel::new(tree, &[[50.0, 1.0], [0.0, 0.0], [50.0, 0.0]]);
        assert_eq!(model.layers[0].1, vec![0.02, 0.01, 1e-5]);
        assert_eq!(CostModel::imbalance(&[1.0, 2.0, 3.0]), 1.5);
    }
}
