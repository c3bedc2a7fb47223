//! How far apart the particles are: the distance from a particle to its nearest neighbour,
//! from which the default radius is derived (SPH users expect a kernel that joins neighbours,
//! about twice their spacing, not a fraction of the box).

use std::num::NonZero;

use glam::DVec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// Particles whose nearest neighbour is measured: the median of this many is stable to a few
/// per cent, and the queries cost far less than building the tree.
pub const SAMPLE: usize = 2048;

/// Neighbours asked for per sampled particle, so a few co-located copies of it (duplicated
/// boundary particles, restarts) are passed over to the first particle at a distance.
pub const NEIGHBOURS: usize = 8;

/// The median, over an evenly strided sample of at most [`SAMPLE`] particles, of the distance
/// to the nearest particle at another position. `None` when no sampled particle has one (a
/// single particle, or every particle at one point).
pub fn median_nearest_distance(positions: &[DVec3]) -> Option<f64> {
    if positions.len() < 2 {
        return None;
    }
    let points: Vec<[f64; 3]> = positions.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(&points);
    let stride = points.len().div_ceil(SAMPLE);
    let k = NonZero::new(NEIGHBOURS.min(points.len())).expect("at least two points");
    let mut nearest: Vec<f64> = points
        .iter()
        .step_by(stride)
        .filter_map(|q| {
            nearest_apart(
                tree.nearest_n::<SquaredEuclidean>(q, k)
                    .into_iter()
                    .map(|n| n.distance),
            )
        })
        .collect();
    median_of(&mut nearest)
}

/// A sampled particle's nearest distance from its [`NEIGHBOURS`] nearest squared distances in
/// increasing order (itself and its co-located copies among them): the first one apart.
pub fn nearest_apart(squared: impl IntoIterator<Item = f64>) -> Option<f64> {
    squared.into_iter().find(|&d2| d2 > 0.0).map(f64::sqrt)
}

/// The median of the sampled nearest distances: the one at rank `n / 2` (`None` for none).
pub fn median_of(nearest: &mut [f64]) -> Option<f64> {
    if nearest.is_empty() {
        return None;
    }
    let middle = nearest.len() / 2;
    let (_, median, _) = nearest.select_nth_unstable_by(middle, f64::total_cmp);
    Some(*median)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lattice_gives_its_spacing_whatever_its_offset() {
        // A lattice off the origin, as a simulation writes it (shared coordinates on every
        // axis, which some k-d trees cannot split).
        let dx = 0.04;
        let mut points = Vec::new();
        for i in 0..13 {
            for j in 0..11 {
                for k in 0..17 {
                    points.push(
                        DVec3::new(1e4, -3e3, 7.0) + dx * DVec3::new(i as f64, j as f64, k as f64),
                    );
                }
            }
        }
        let d = median_nearest_distance(&points).unwrap();
        assert!((d - dx).abs() < 1e-9, "{d}");
        // Each particle written twice (co-located copies) changes nothing.
        let doubled: Vec<DVec3> = points.iter().flat_map(|&p| [p, p]).collect();
        let d2 = median_nearest_distance(&doubled).unwrap();
        assert!((d2 - dx).abs() < 1e-9, "{d2}");
    }

    #[test]
    fn degenerate_sets_have_no_spacing() {
        assert_eq!(median_nearest_distance(&[]), None);
        assert_eq!(median_nearest_distance(&[DVec3::ONE]), None);
        assert_eq!(median_nearest_distance(&[DVec3::ONE; 5]), None);
        let two = [DVec3::ZERO, DVec3::new(0.0, 3.0, 4.0)];
        assert_eq!(median_nearest_distance(&two), Some(5.0));
    }
}
