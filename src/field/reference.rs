//! The reference field of one step: Phi and Theta at points, in f64, through a grid of cells
//! (point queries, `f64_kernel`) or by brute force; the empty space along rays from the same
//! cells; and the cluster boxes with their BVH, which the splatter walks.

use std::sync::OnceLock;

use glam::DVec3;
use rayon::prelude::*;

use super::f64_kernel::Packed64;
use super::{FieldError, FieldSettings, Particles, Theta};
use crate::accel::{CellGrid, CellRuns, ClusterBoxes, ClusterBvh, ClusterSize, hilbert_order};
use crate::values::{Bounds, Step};

#[derive(Default)]
pub(super) struct Accumulator {
    pub(super) phi: f64,
    pub(super) theta: [f64; 3],
}

impl Particles {
    /// Adds particle `i`'s contribution at `x` (local coordinates) to `acc` if `x` lies within
    /// its radius.
    #[inline]
    pub(super) fn accumulate(&self, i: usize, x: DVec3, acc: &mut Accumulator) {
        let r = self.radii[i];
        if r <= 0.0 {
            return;
        }
        let d2 = (x - self.centers[i]).length_squared();
        if d2 > r * r {
            return;
        }
        let phi = self.weights[i] * self.kernel.profile(d2, r * r);
        acc.phi += phi;
        match &self.theta {
            Theta::None => {}
            Theta::Scalar(t) => acc.theta[0] += t[i] * phi,
            Theta::Rgb(c) => {
                for (a, c) in acc.theta.iter_mut().zip(c[i]) {
                    *a += c * phi;
                }
            }
        }
    }
}

/// The field at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Density Phi.
    pub phi: f64,
    /// Theta: the attribute in its own units in `theta[0]` (post-classification), or linear
    /// RGB (pre-classification); zeros where Phi is 0.
    pub theta: [f64; 3],
}

/// Phi and Theta from the sums Σ phi_i and Σ theta_i phi_i (what every backend's query
/// returns): Theta = numerator / Phi, in the attribute's units for post-classification
/// (`range` undoes the normalisation), linear RGB for pre-classification.
pub fn finish_sums(phi: f64, num: [f64; 3], post: bool, range: (f64, f64)) -> Sample {
    // Theta is undefined where Phi vanishes; a denormal Phi would make the ratio meaningless
    // (or infinite in f32 on a GPU), so both count as "no density here".
    if phi.is_nan() || phi < f64::MIN_POSITIVE {
        return Sample {
            phi: if phi.is_finite() { phi } else { 0.0 },
            theta: [0.0; 3],
        };
    }
    let mut theta = num.map(|v| v / phi);
    if post {
        let (lo, hi) = range;
        theta[0] = if hi > lo {
            lo + theta[0] * (hi - lo)
        } else {
            lo
        };
    }
    Sample { phi, theta }
}

/// The reference field of one step: prepared particles and, for point queries and the empty
/// space along rays, the particles again in a grid of cells; the cluster boxes and their BVH
/// are built when first asked for (the splatter walks them). All in the particles' local
/// coordinates; every method takes data coordinates.
pub struct ReferenceField {
    /// The step's particles with the field applied (Hilbert order, local coordinates).
    pub particles: Particles,
    cluster: ClusterSize,
    clusters: OnceLock<(ClusterBoxes, ClusterBvh)>,
    cells: CellGrid,
    /// `cell_order[p]` is the particle at position `p` of `by_cell`.
    cell_order: Vec<u32>,
    /// The particles cell by cell, as the point queries' kernel reads them.
    by_cell: Packed64,
}

impl ReferenceField {
    /// The field of `particles` (with their field applied): sorts them into a grid of cells now;
    /// the cluster boxes, of `cluster` particles each, wait for their first use.
    pub fn new(particles: Particles, cluster: ClusterSize) -> ReferenceField {
        let (cells, cell_order) = CellGrid::build(&particles.centers, &particles.radii);
        let by_cell = Packed64::gather(&particles, &cell_order);
        ReferenceField {
            particles,
            cluster,
            clusters: OnceLock::new(),
            cells,
            cell_order,
            by_cell,
        }
    }

    /// To be called after the particles' weights or theta changed (a map, not their centres
    /// or radii): the cells' copies of them are gathered again.
    pub fn values_changed(&mut self) {
        self.by_cell = Packed64::gather(&self.particles, &self.cell_order);
    }

    /// The clusters of K consecutive particles and their boxes (built on first use).
    pub fn boxes(&self) -> &ClusterBoxes {
        &self.clusters().0
    }

    /// The BVH over [`ReferenceField::boxes`] (built on first use).
    pub(super) fn bvh(&self) -> &ClusterBvh {
        &self.clusters().1
    }

    /// Builds the cluster boxes and their BVH if they were not yet; whether it built them.
    pub fn build_clusters(&self) -> bool {
        let built = self.clusters.get().is_none();
        self.clusters();
        built
    }

    fn clusters(&self) -> &(ClusterBoxes, ClusterBvh) {
        self.clusters.get_or_init(|| {
            let boxes =
                ClusterBoxes::build(&self.particles.centers, &self.particles.radii, self.cluster);
            let bvh = ClusterBvh::build(&boxes);
            (boxes, bvh)
        })
    }

    /// Builds the field of `step` in one call.
    pub fn of_step(
        step: &Step,
        settings: &FieldSettings,
        cluster: ClusterSize,
        series_bounds: Bounds,
        series_range: Option<(f64, f64)>,
    ) -> Result<ReferenceField, FieldError> {
        let particles = Particles::prepare(step, settings, series_bounds, series_range)?;
        Ok(ReferenceField::new(particles, cluster))
    }

    /// The field at `x`.
    pub fn eval(&self, x: DVec3) -> Sample {
        self.eval_with(x, &mut CellRuns::default())
    }

    /// [`ReferenceField::eval`] with the runs of the last cell kept in `scratch` (made once per
    /// thread: a query in the same cell as the last looks nothing up).
    pub fn eval_with(&self, x: DVec3, scratch: &mut CellRuns) -> Sample {
        let (phi, theta) = self.eval_sums_with(x, scratch);
        self.finish(Accumulator { phi, theta })
    }

    /// Phi and the Theta numerator at `x` as the renderer uses them: Σ phi_i and
    /// Σ theta_i phi_i with theta_i the normalised attribute t_i (post) or linear RGB (pre).
    pub fn eval_sums(&self, x: DVec3) -> (f64, [f64; 3]) {
        self.eval_sums_with(x, &mut CellRuns::default())
    }

    /// [`ReferenceField::eval_sums`] with the runs of the last cell kept in `scratch`. Each
    /// term is `Particles::accumulate`'s, bit for bit (`f64_kernel`); the candidates are the
    /// particles of the 27 cells around `x`'s on each level of radii (`accel::cells`).
    pub fn eval_sums_with(&self, x: DVec3, scratch: &mut CellRuns) -> (f64, [f64; 3]) {
        let l = x - self.particles.origin;
        let runs = self.cells.runs_at(l, scratch);
        self.by_cell.sums(runs, l)
    }

    /// The disjoint, ordered sub-intervals of `[t0, t1]` along a ray that cross a cell some
    /// particle may reach: outside them the field is 0.
    pub fn occupied_intervals(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        out: &mut Vec<(f64, f64)>,
    ) {
        self.cells
            .occupied(origin - self.particles.origin, dir, t0, t1, out);
    }

    /// Bytes of the cells and the particles sorted into them, and of the cluster boxes and
    /// their BVH where they were built.
    pub fn structure_bytes(&self) -> usize {
        let clusters = self.clusters.get().map_or(0, |(boxes, bvh)| {
            boxes.len() * std::mem::size_of::<Bounds>() + bvh.bytes()
        });
        clusters + self.cells.bytes() + self.by_cell.bytes() + 4 * self.cell_order.len()
    }

    /// The field at `x` by visiting every particle.
    pub fn eval_brute_force(&self, x: DVec3) -> Sample {
        let x = x - self.particles.origin;
        let mut acc = Accumulator::default();
        for i in 0..self.particles.len() {
            self.particles.accumulate(i, x, &mut acc);
        }
        self.finish(acc)
    }

    /// The field at many points, in parallel, with a progress bar for long runs. Queries are
    /// visited in Hilbert order (neighbouring queries share cells, and their candidates stay in
    /// cache) and the results returned in input order.
    pub fn eval_many(&self, queries: &[DVec3]) -> Vec<Sample> {
        let order = hilbert_order(queries, Bounds::of_points(queries));
        let bar = crate::progress::bar(queries.len() as u64, "evaluating");
        let chunk = 4096;
        let sorted: Vec<Sample> = order
            .par_chunks(chunk)
            .flat_map_iter(|c| {
                let mut scratch = CellRuns::default();
                let r: Vec<Sample> = c
                    .iter()
                    .map(|&i| self.eval_with(queries[i as usize], &mut scratch))
                    .collect();
                bar.inc(c.len() as u64);
                r
            })
            .collect();
        bar.finish_and_clear();
        let mut out = vec![Sample::default(); queries.len()];
        for (&i, s) in order.iter().zip(sorted) {
            out[i as usize] = s;
        }
        out
    }

    pub(super) fn finish(&self, acc: Accumulator) -> Sample {
        self.particles.finish(acc)
    }
}

impl Particles {
    /// The field's value from its sums over these particles ([`finish_sums`]).
    pub(super) fn finish(&self, acc: Accumulator) -> Sample {
        let post = matches!(self.theta, Theta::Scalar(_));
        finish_sums(acc.phi, acc.theta, post, self.range)
    }
}
