//! The k-d decomposition of a step among P ranks: P half-open leaves that tile all of space
//! (the outer faces are infinite, so no particle and no sample is left without an owner),
//! from a weighted sample of the particles that every rank holds in full, so that every rank
//! builds the same tree. A node of P leaves splits ⌊P/2⌋ : ⌈P/2⌉ at that quantile of the
//! sample, so the leaves hold about N/P particles each for any P, along the axis whose plane
//! the fewest sampled particles reach across (each becomes a ghost of the other side), the
//! longest where they tie.
//! Unlike ranges of a space-filling curve, the leaves are boxes: convex, so a ray enters each
//! at most once, and ordered front to back for any eye by the tree ([`KdTree::front_to_back`]).

use glam::DVec3;

use crate::values::{Bounds, HalfOpenBox};

/// A point of the decomposition's sample, standing for `weight` particles.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct WeightedPoint {
    /// Position, in world units.
    pub at: [f64; 3],
    /// How many particles it stands for.
    pub weight: f64,
    /// How far its particle reaches (its ghost reach; 0: it is nobody's ghost).
    pub reach: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Node {
    Leaf(usize),
    /// Points with `x[axis] < at` lie below, the others (the plane included) above.
    Split {
        axis: usize,
        at: f64,
        below: usize,
        above: usize,
    },
}

/// P half-open boxes tiling space; leaf r is rank r's.
#[derive(Clone, Debug, PartialEq)]
pub struct KdTree {
    nodes: Vec<Node>,
    leaves: Vec<HalfOpenBox>,
}

impl KdTree {
    /// The tree of `leaves` leaves over `sample` (its order does not matter).
    pub fn build(sample: &[WeightedPoint], leaves: usize) -> KdTree {
        assert!(leaves > 0, "a decomposition has at least one leaf");
        let mut points: Vec<WeightedPoint> = sample.to_vec();
        let extent = Bounds::of_points(
            &points
                .iter()
                .map(|p| DVec3::from_array(p.at))
                .collect::<Vec<_>>(),
        );
        let mut tree = KdTree {
            nodes: Vec::with_capacity(2 * leaves - 1),
            leaves: vec![HalfOpenBox::EVERYWHERE; leaves],
        };
        tree.split(&mut points, 0, leaves, HalfOpenBox::EVERYWHERE, extent);
        tree
    }

    /// Appends the node for ranks `first..first + count` over `region`, holding `points`;
    /// returns its index. `extent` bounds the whole sample (for a node left with no points).
    fn split(
        &mut self,
        points: &mut [WeightedPoint],
        first: usize,
        count: usize,
        region: HalfOpenBox,
        extent: Bounds,
    ) -> usize {
        let index = self.nodes.len();
        if count == 1 {
            self.nodes.push(Node::Leaf(first));
            self.leaves[first] = region;
            return index;
        }
        let below_count = count / 2;
        let (axis, at) = split_plane(points, below_count as f64 / count as f64, region, extent);
        // Reserved now, written once the children's indices are known.
        self.nodes.push(Node::Leaf(usize::MAX));
        let mid = partition(points, |p| p.at[axis] < at);
        let (below_points, above_points) = points.split_at_mut(mid);
        let (mut below_region, mut above_region) = (region, region);
        below_region.hi[axis] = at;
        above_region.lo[axis] = at;
        let below = self.split(below_points, first, below_count, below_region, extent);
        let above = self.split(
            above_points,
            first + below_count,
            count - below_count,
            above_region,
            extent,
        );
        self.nodes[index] = Node::Split {
            axis,
            at,
            below,
            above,
        };
        index
    }

    /// The leaves, rank order.
    pub fn leaves(&self) -> &[HalfOpenBox] {
        &self.leaves
    }

    /// The leaf holding `x` (the one whose half-open box contains it).
    pub fn leaf_of(&self, x: DVec3) -> usize {
        let mut node = 0;
        loop {
            match self.nodes[node] {
                Node::Leaf(rank) => return rank,
                Node::Split {
                    axis,
                    at,
                    below,
                    above,
                } => node = if x[axis] < at { below } else { above },
            }
        }
    }

    /// Appends to `out` the leaves whose closed boxes may lie within `reach` of `x` (those
    /// the planes do not separate from the ball; the caller tests each box's distance). A
    /// plane separates only by more than a millionth of the reach, so that no rounding of
    /// the caller's distance keeps a leaf this drops.
    pub fn leaves_near(&self, x: DVec3, reach: f64, out: &mut Vec<usize>) {
        let reach = reach * (1.0 + 1e-6);
        let mut stack = vec![0];
        while let Some(node) = stack.pop() {
            match self.nodes[node] {
                Node::Leaf(rank) => out.push(rank),
                Node::Split {
                    axis,
                    at,
                    below,
                    above,
                } => {
                    if x[axis] < at || x[axis] - at <= reach {
                        stack.push(below);
                    }
                    if x[axis] >= at || at - x[axis] <= reach {
                        stack.push(above);
                    }
                }
            }
        }
    }

    /// The leaves in the order a ray from `eye` can meet them: at each split the side holding
    /// the eye first. A ray crosses a plane at most once, from the eye's side to the other, so
    /// every leaf it meets comes after those it met before (the painter's order of a BSP).
    pub fn front_to_back(&self, eye: DVec3) -> Vec<usize> {
        self.ordered(|axis, at| eye[axis] < at)
    }

    /// The leaves in the order rays travelling against `toward` (from a directional light
    /// infinitely far along it) can meet them: at each split the side nearer the light first.
    /// The order [`KdTree::front_to_back`] gives for an eye far along `toward`.
    pub fn nearest_first_along(&self, toward: DVec3) -> Vec<usize> {
        self.ordered(|axis, _| toward[axis] < 0.0)
    }

    /// The leaves, at each split the side below it first where `below_first(axis, at)`.
    fn ordered(&self, below_first: impl Fn(usize, f64) -> bool) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.leaves.len());
        let mut stack = vec![0];
        while let Some(node) = stack.pop() {
            match self.nodes[node] {
                Node::Leaf(rank) => order.push(rank),
                Node::Split {
                    axis,
                    at,
                    below,
                    above,
                } => {
                    let (near, far) = if below_first(axis, at) {
                        (below, above)
                    } else {
                        (above, below)
                    };
                    // Popped first: the near side.
                    stack.push(far);
                    stack.push(near);
                }
            }
        }
        order
    }
}

/// Reorders `points` so those for which `below` holds come first; returns how many do.
fn partition(points: &mut [WeightedPoint], below: impl Fn(&WeightedPoint) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..points.len() {
        if below(&points[i]) {
            points.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

/// The axis and the plane splitting `points` so that the fraction `q` of their weight lies
/// below it (as near as the points allow: those on the plane go above). Of the axes along which
/// the points spread, the one whose plane the least weight reaches across (the particles it
/// makes ghosts), the longest of the points' bounds where that ties (as where no point reaches
/// at all); where there are no points, the longest of the region's finite part.
fn split_plane(
    points: &mut [WeightedPoint],
    q: f64,
    region: HalfOpenBox,
    extent: Bounds,
) -> (usize, f64) {
    let bounds = if points.is_empty() {
        region.clipped_to(extent)
    } else {
        Bounds::of_points(
            &points
                .iter()
                .map(|p| DVec3::from_array(p.at))
                .collect::<Vec<_>>(),
        )
    };
    let size = bounds.max - bounds.min;
    let longest = if size.is_finite() && size.max_element() > 0.0 {
        size.max_position()
    } else {
        0
    };
    if points.is_empty() {
        // No particle to balance: halve what the sample spans of the region (or its
        // plane, if it spans nothing).
        let axis = longest;
        let at = if size.is_finite() && !bounds.is_empty() {
            0.5 * (bounds.min[axis] + bounds.max[axis])
        } else if region.lo[axis].is_finite() {
            region.lo[axis]
        } else if region.hi[axis].is_finite() {
            region.hi[axis]
        } else {
            0.0
        };
        return (axis, at);
    }
    let mut best = (longest, balanced_plane(points, q, longest));
    let mut least = cut_weight(points, best.0, best.1);
    for axis in (0..3).filter(|&a| a != longest && size[a] > 0.0 && size[a].is_finite()) {
        let at = balanced_plane(points, q, axis);
        let cut = cut_weight(points, axis, at);
        if cut < least {
            (best, least) = ((axis, at), cut);
        }
    }
    best
}

/// The plane along `axis` with the fraction `q` of the points' weight below it, midway
/// between the last point below and the first above (the gap between them is where the
/// fewest particles reach across).
fn balanced_plane(points: &mut [WeightedPoint], q: f64, axis: usize) -> f64 {
    points.sort_by(|a, b| a.at[axis].total_cmp(&b.at[axis]));
    let total: f64 = points.iter().map(|p| p.weight).sum();
    let target = q * total;
    let mut before = 0.0;
    let mut last_below = f64::NEG_INFINITY;
    for p in points.iter() {
        let x = p.at[axis];
        if before >= target {
            let midway = 0.5 * (last_below + x);
            // Strictly above the last point below, so that it stays below.
            return if midway > last_below && midway <= x {
                midway
            } else {
                x
            };
        }
        before += p.weight;
        last_below = x;
    }
    // All the weight lies below the last point: put the plane just above it.
    points.last().expect("not empty").at[axis].next_up()
}

/// The weight of the points that reach across the plane `x[axis] = at`.
fn cut_weight(points: &[WeightedPoint], axis: usize, at: f64) -> f64 {
    points
        .iter()
        .filter(|p| (p.at[axis] - at).abs() <= p.reach)
        .map(|p| p.weight)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn cloud(n: usize, seed: u64) -> Vec<WeightedPoint> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|_| WeightedPoint {
                // An anisotropic cloud: the longest axis changes as it is split.
                at: [
                    rng.random::<f64>() * 4.0,
                    rng.random::<f64>() * 2.0,
                    rng.random::<f64>().powi(3),
                ],
                weight: 1.0,
                reach: 0.0,
            })
            .collect()
    }

    #[test]
    fn leaves_tile_space_and_balance_the_sample() {
        for p in (1..=9).chain([16]) {
            let sample = cloud(64 * p, p as u64);
            let tree = KdTree::build(&sample, p);
            assert_eq!(tree.leaves().len(), p);
            let mut counts = vec![0usize; p];
            let mut rng = rand_pcg::Pcg64::seed_from_u64(99);
            let probes = sample.iter().map(|s| DVec3::from_array(s.at)).chain(
                (0..2000).map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * 8.0 - 2.0),
            );
            for (i, x) in probes.enumerate() {
                let holders: Vec<usize> =
                    (0..p).filter(|&r| tree.leaves()[r].contains(x)).collect();
                assert_eq!(holders, vec![tree.leaf_of(x)], "P = {p}: {x}");
                if i < sample.len() {
                    counts[holders[0]] += 1;
                }
            }
            // Each leaf holds its share of the sample, to the one point a split can miss by.
            let depth = (p as f64).log2().ceil() as usize;
            for (r, &c) in counts.iter().enumerate() {
                assert!(
                    c.abs_diff(64) <= depth,
                    "P = {p}: leaf {r} holds {c} of the sample"
                );
            }
        }
    }

    #[test]
    fn the_split_takes_the_axis_its_particles_reach_across_least() {
        // Two layers 2 apart along y, each spread over 4 along x: the longest axis, x, cuts
        // through both layers, where y's balanced plane runs between them.
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let mut layers = |reach: f64| -> Vec<WeightedPoint> {
            (0..400)
                .map(|i| WeightedPoint {
                    at: [
                        rng.random::<f64>() * 4.0,
                        if i % 2 == 0 { 0.0 } else { 2.0 } + rng.random::<f64>() * 0.1,
                        rng.random::<f64>(),
                    ],
                    weight: 1.0,
                    reach,
                })
                .collect()
        };
        let tree = KdTree::build(&layers(0.3), 2);
        assert!(
            tree.leaves()[0].hi.y.is_finite() && tree.leaves()[0].hi.x.is_infinite(),
            "{:?}",
            tree.leaves()
        );
        // Reaching nowhere, every axis cuts nothing: the longest, as before.
        let tree = KdTree::build(&layers(0.0), 2);
        assert!(tree.leaves()[0].hi.x.is_finite(), "{:?}", tree.leaves());
    }

    #[test]
    fn unequal_weights_move_the_split() {
        // Two clusters; the right one's points stand for three particles each.
        let mut sample: Vec<WeightedPoint> = (0..100)
            .map(|i| WeightedPoint {
                at: [f64::from(i) * 0.01, 0.0, 0.0],
                weight: 1.0,
                reach: 0.0,
            })
            .collect();
        sample.extend((0..100).map(|i| WeightedPoint {
            at: [10.0 + f64::from(i) * 0.01, 0.0, 0.0],
            weight: 3.0,
            reach: 0.0,
        }));
        let tree = KdTree::build(&sample, 2);
        // Half of the weight (400 of 800) lies below x = 10 + 1/3.
        let plane = tree.leaves()[0].hi.x;
        assert!((plane - 10.33).abs() < 0.011, "{plane}");
    }

    #[test]
    fn degenerate_samples_still_give_p_leaves() {
        for sample in [
            Vec::new(),
            vec![
                WeightedPoint {
                    at: [1.0, 2.0, 3.0],
                    weight: 1.0,
                    reach: 0.0,
                };
                50
            ],
        ] {
            for p in [1, 2, 3, 7] {
                let tree = KdTree::build(&sample, p);
                assert_eq!(tree.leaves().len(), p);
                let x = DVec3::new(1.0, 2.0, 3.0);
                assert_eq!((0..p).filter(|&r| tree.leaves()[r].contains(x)).count(), 1);
            }
        }
    }

    /// Every ray from the eye meets the leaves in the order `front_to_back` gives.
    #[test]
    fn front_to_back_order_holds_along_random_rays() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for p in (2..=9).chain([16]) {
            let tree = KdTree::build(&cloud(64 * p, 100 + p as u64), p);
            for _ in 0..40 {
                // Eyes inside and around the cloud.
                let eye = DVec3::new(rng.random(), rng.random(), rng.random()) * 8.0 - 2.0;
                let order = tree.front_to_back(eye);
                let mut position = vec![0; p];
                for (k, &r) in order.iter().enumerate() {
                    position[r] = k;
                }
                let mut sorted = order.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..p).collect::<Vec<_>>());
                for _ in 0..50 {
                    let dir = DVec3::new(
                        rng.random::<f64>() - 0.5,
                        rng.random::<f64>() - 0.5,
                        rng.random::<f64>() - 0.5,
                    )
                    .normalize();
                    // The leaves along the ray, by walking it finely.
                    let mut last = None;
                    for k in 0..4000 {
                        let leaf = tree.leaf_of(eye + dir * (f64::from(k) * 0.005));
                        if let Some(prev) = last
                            && prev != leaf
                        {
                            assert!(
                                position[leaf] > position[prev],
                                "P = {p}, eye {eye}: the ray meets leaf {leaf} after leaf {prev}, against the order {order:?}"
                            );
                        }
                        last = Some(leaf);
                    }
                }
            }
        }
    }

    /// Every ray travelling away from a directional light meets the leaves in the order
    /// `nearest_first_along` gives.
    #[test]
    fn the_order_from_a_light_holds_along_its_rays() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        for p in (2..=9).chain([16]) {
            let tree = KdTree::build(&cloud(64 * p, 300 + p as u64), p);
            for case in 0..30 {
                let mut toward = DVec3::new(
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                    rng.random::<f64>() - 0.5,
                )
                .normalize();
                if case == 0 {
                    // Along an axis: rays parallel to the other splits.
                    toward = DVec3::Y;
                }
                let order = tree.nearest_first_along(toward);
                let mut position = vec![0; p];
                for (k, &r) in order.iter().enumerate() {
                    position[r] = k;
                }
                for _ in 0..40 {
                    let start = DVec3::new(rng.random(), rng.random(), rng.random()) * 8.0 - 2.0
                        + toward * 10.0;
                    let mut last = None;
                    for k in 0..4000 {
                        let leaf = tree.leaf_of(start - toward * (f64::from(k) * 0.005));
                        if let Some(prev) = last
                            && prev != leaf
                        {
                            assert!(
                                position[leaf] > position[prev],
                                "P = {p}: light ray meets leaf {leaf} after {prev}, against {order:?}"
                            );
                        }
                        last = Some(leaf);
                    }
                }
            }
        }
    }
}
