//! The reference field on a regular grid, by scattering each particle onto the block of grid
//! points within its radius instead of one tree query per point: on a grid, which points a
//! particle reaches follows from its centre and radius, so no traversal is needed and each
//! particle's data is read once per block instead of once per query that visits it.
//!
//! The Gaussian is separable, exp(-4.5 d²/r²) = Π over axes of exp(-4.5 d_a²/r²), so a
//! particle costs one exponential per grid line it spans (about 3 x 6) instead of one per
//! point it reaches (about 50): the rest is two multiplications a point. Which points a
//! particle reaches is decided by the reference's own test (d² summed x, y, z from the same
//! local coordinates, against r²), so a grid value differs from [`ReferenceField::eval`] at
//! [`RegularGrid::point`] only by rounding: the product of three exponentials against one of
//! the sum, and the order of the sum over particles (a few ulps; the tests allow 1e-13).

use glam::DVec3;
use rayon::prelude::*;

use super::reference::Accumulator;
use super::{Particles, ReferenceField, Sample, Theta};

/// Points `origin + i·spacing[0]·e[axes[0]] + j·spacing[1]·e[axes[1]] + k·spacing[2]·e[axes[2]]`
/// for `i < dims[0]`, `j < dims[1]`, `k < dims[2]`, stored with i fastest: `axes` says which
/// data axis each grid index runs along (a permutation of 0, 1, 2), and a spacing may be
/// negative (image rows run down while y runs up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegularGrid {
    pub origin: DVec3,
    pub axes: [usize; 3],
    pub spacing: [f64; 3],
    pub dims: [usize; 3],
}

impl RegularGrid {
    /// The grid of `dims` points along x, y and z with cell-centred samples filling `lo..hi`
    /// (a volume export, as yt's covering grids sample).
    pub fn cell_centred(lo: DVec3, hi: DVec3, dims: [usize; 3]) -> RegularGrid {
        let step = (hi - lo) / DVec3::new(dims[0] as f64, dims[1] as f64, dims[2] as f64);
        RegularGrid {
            origin: lo + 0.5 * step,
            axes: [0, 1, 2],
            spacing: step.to_array(),
            dims,
        }
    }

    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every point's data coordinates, in the grid's order (i fastest).
    pub fn points(&self) -> Vec<DVec3> {
        let [nx, ny, _] = self.dims;
        (0..self.len())
            .map(|p| self.point([p % nx, (p / nx) % ny, p / (nx * ny)]))
            .collect()
    }

    /// The data coordinates of grid point (i, j, k).
    #[inline]
    pub fn point(&self, index: [usize; 3]) -> DVec3 {
        let mut p = self.origin;
        for (d, &i) in index.iter().enumerate() {
            p[self.axes[d]] = self.origin[self.axes[d]] + i as f64 * self.spacing[d];
        }
        p
    }

    /// The grid indices along dimension `d` of the points within `reach` of `centre` (data
    /// coordinates), widened by 1e-7 of a cell each side so that rounding never loses a point
    /// the exact distance test would keep.
    fn span(&self, d: usize, centre: DVec3, reach: f64) -> std::ops::Range<usize> {
        let n = self.dims[d];
        let s = self.spacing[d];
        if n <= 1 || s == 0.0 || !s.is_finite() {
            return 0..n;
        }
        let c = centre[self.axes[d]] - self.origin[self.axes[d]];
        let (a, b) = ((c - reach) / s, (c + reach) / s);
        let (lo, hi) = ((a.min(b) - 1e-7).ceil(), (a.max(b) + 1e-7).floor());
        if hi < 0.0 || lo >= n as f64 || lo.is_nan() || hi.is_nan() {
            return 0..0;
        }
        (lo.max(0.0) as usize)..((hi + 1.0).min(n as f64) as usize)
    }

    /// The local coordinates (data coordinates minus `origin`) of the grid's points along
    /// dimension `d`, computed as [`RegularGrid::point`] computes them.
    fn local_coordinates(&self, d: usize, origin: DVec3) -> Vec<f64> {
        let a = self.axes[d];
        (0..self.dims[d])
            .map(|i| (self.origin[a] + i as f64 * self.spacing[d]) - origin[a])
            .collect()
    }
}

impl ReferenceField {
    /// The field at every point of `grid` ([`Particles::eval_grid`]).
    pub fn eval_grid(&self, grid: &RegularGrid) -> Vec<Sample> {
        self.particles.eval_grid(grid)
    }

    /// Phi and the Theta numerator at every point of `grid` ([`Particles::eval_grid_sums`]).
    pub fn eval_grid_sums(&self, grid: &RegularGrid) -> Vec<(f64, [f64; 3])> {
        self.particles.eval_grid_sums(grid)
    }
}

impl Particles {
    /// The field at every point of `grid`, in the grid's order (what the reference's `eval`
    /// gives at each [`RegularGrid::point`], summed in another order), with no tree built.
    pub fn eval_grid(&self, grid: &RegularGrid) -> Vec<Sample> {
        self.eval_grid_sums(grid)
            .into_par_iter()
            .map(|(phi, theta)| self.finish(Accumulator { phi, theta }))
            .collect()
    }

    /// Phi and the Theta numerator at every point of `grid` (what the reference's `eval_sums`
    /// gives there), scattering each particle onto the grid points it reaches: no tree.
    /// Parallel over blocks of grid rows; each block takes the particles that reach it, in
    /// Hilbert order, so the result does not depend on the number of threads.
    pub fn eval_grid_sums(&self, grid: &RegularGrid) -> Vec<(f64, [f64; 3])> {
        let [nx, ny, nz] = grid.dims;
        let rows = ny * nz;
        if grid.is_empty() {
            return Vec::new();
        }
        let particles = self;
        // About 16 blocks a thread, at least 1 row each.
        let blocks = (16 * rayon::current_num_threads()).min(rows).max(1);
        let rows_per_block = rows.div_ceil(blocks);
        let blocks = rows.div_ceil(rows_per_block);
        let spans: Vec<Option<[std::ops::Range<usize>; 3]>> = (0..particles.len())
            .into_par_iter()
            .map(|p| {
                let r = particles.radii[p];
                if r.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return None;
                }
                let centre = particles.origin + particles.centers[p];
                let span = [0, 1, 2].map(|d| grid.span(d, centre, r));
                span.iter().all(|s| !s.is_empty()).then_some(span)
            })
            .collect();
        // The particles reaching each block, in order.
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); blocks];
        for (p, span) in spans.iter().enumerate() {
            let Some([_, j, k]) = span else { continue };
            // Blocks only grow with k: each is pushed once (`next` is the first not pushed).
            let mut next = 0;
            for kk in k.clone() {
                let first = (kk * ny + j.start) / rows_per_block;
                let end = (kk * ny + j.end - 1) / rows_per_block;
                for members in members.iter_mut().take(end + 1).skip(first.max(next)) {
                    members.push(p as u32);
                }
                next = next.max(end + 1);
            }
        }
        // Grid dimension of each data axis: distances are summed x, y, z, as the reference
        // sums them, so the cut-off test d <= r decides exactly as a query does.
        let mut dim_of_axis = [0usize; 3];
        for (d, &a) in grid.axes.iter().enumerate() {
            dim_of_axis[a] = d;
        }
        let identity = grid.axes == [0, 1, 2];
        let coords = [0, 1, 2].map(|d| grid.local_coordinates(d, particles.origin));
        let mut out = vec![(0.0, [0.0; 3]); grid.len()];
        out.par_chunks_mut(rows_per_block * nx)
            .zip(members.par_iter())
            .enumerate()
            .for_each(|(b, (out, members))| {
                let row0 = b * rows_per_block;
                let row1 = row0 + out.len() / nx;
                // Phi and the three Theta numerators of each point, side by side.
                let mut acc = vec![[0.0f64; 4]; out.len()];
                // Per dimension and point of the particle's span: the squared distance along
                // that axis and its Gaussian factor (the kernel is separable:
                // exp(-4.5 d²/r²) is the product of the three axes' factors).
                let mut along: [Vec<(f64, f64)>; 3] = Default::default();
                for &p in members {
                    let p = p as usize;
                    let Some(span) = &spans[p] else { continue };
                    let r = particles.radii[p];
                    let r2 = r * r;
                    let c = particles.centers[p];
                    for d in 0..3 {
                        along[d].clear();
                        let centre = c[grid.axes[d]];
                        along[d].extend(coords[d][span[d].clone()].iter().map(|&x| {
                            let t = (x - centre) * (x - centre);
                            (t, (-4.5 * t / r2).exp())
                        }));
                    }
                    let w = particles.weights[p];
                    // What a point's sums gain per unit of phi: 1, then theta (0 where the
                    // field carries none: adding 0 changes no sum).
                    let gain = match &particles.theta {
                        Theta::None => [1.0, 0.0, 0.0, 0.0],
                        Theta::Scalar(t) => [1.0, t[p], 0.0, 0.0],
                        Theta::Rgb(c) => [1.0, c[p][0], c[p][1], c[p][2]],
                    };
                    let [i, j, k] = span;
                    for kk in k.clone() {
                        let j0 = j.start.max(row0.saturating_sub(kk * ny));
                        let j1 = j.end.min(row1.saturating_sub(kk * ny));
                        let (tz, ez) = along[2][kk - k.start];
                        for jj in j0..j1 {
                            let (ty, ey) = along[1][jj - j.start];
                            let weight = w * ey * ez;
                            let row = (kk * ny + jj - row0) * nx;
                            let acc = &mut acc[row + i.start..row + i.end];
                            // Without a branch: a point beyond the radius adds 0.
                            for (a, &(tx, ex)) in acc.iter_mut().zip(&along[0]) {
                                let d2 = if identity {
                                    (tx + ty) + tz
                                } else {
                                    let t = [tx, ty, tz];
                                    (t[dim_of_axis[0]] + t[dim_of_axis[1]]) + t[dim_of_axis[2]]
                                };
                                let phi = if d2 <= r2 { weight * ex } else { 0.0 };
                                for (a, g) in a.iter_mut().zip(gain) {
                                    *a += g * phi;
                                }
                            }
                        }
                    }
                }
                for (o, a) in out.iter_mut().zip(acc) {
                    *o = (a[0], [a[1], a[2], a[3]]);
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::accel::ClusterSize;
    use crate::field::{Classification, FieldSettings};
    use crate::values::{Attribute, Bounds, Step};

    /// Particles as a simulation writes them (full f64 coordinates off the origin, radii of
    /// several sizes through a radius attribute), an awkward count.
    fn field(classification: Classification) -> ReferenceField {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let n = 1237;
        let positions: Vec<DVec3> = (0..n)
            .map(|_| {
                DVec3::new(rng.random(), rng.random(), rng.random()) * DVec3::new(2.0, 1.0, 0.7)
                    + 1e3
            })
            .collect();
        let s = (0..n).map(|_| rng.random::<f64>() * 40.0 - 3.0).collect();
        let h = (0..n).map(|_| 0.5 + rng.random::<f64>()).collect();
        let step = Step {
            name: "grid".into(),
            positions,
            attributes: vec![
                Attribute {
                    name: "s".into(),
                    values: s,
                },
                Attribute {
                    name: "h".into(),
                    values: h,
                },
            ],
        };
        let mut settings = FieldSettings::new(Some("s"), 0.11);
        settings.radius_attribute = Some("h".into());
        settings.classification = classification;
        settings.density_map =
            crate::scene::maps::DensityMap::new("0:0.2,0.37:1,1:0.5".parse().unwrap()).unwrap();
        let bounds = Bounds::of_points(&step.positions);
        ReferenceField::of_step(&step, &settings, ClusterSize::new(4).unwrap(), bounds, None)
            .unwrap()
    }

    fn assert_matches_queries(f: &ReferenceField, grid: &RegularGrid) {
        let got = f.eval_grid(grid);
        assert_eq!(got.len(), grid.len());
        let mut nonzero = 0;
        for k in 0..grid.dims[2] {
            for j in 0..grid.dims[1] {
                for i in 0..grid.dims[0] {
                    let g = got[(k * grid.dims[1] + j) * grid.dims[0] + i];
                    let e = f.eval(grid.point([i, j, k]));
                    assert!(
                        (g.phi - e.phi).abs() <= 1e-13 * e.phi.abs().max(1e-300),
                        "Phi at {i} {j} {k}: {} vs {}",
                        g.phi,
                        e.phi
                    );
                    for c in 0..3 {
                        assert!(
                            (g.theta[c] - e.theta[c]).abs() <= 1e-11 * e.theta[c].abs().max(1.0),
                            "Theta at {i} {j} {k}: {:?} vs {:?}",
                            g.theta,
                            e.theta
                        );
                    }
                    nonzero += usize::from(e.phi > 0.0);
                }
            }
        }
        assert!(
            nonzero * 3 > grid.len(),
            "only {nonzero} of {} points see a particle",
            grid.len()
        );
    }

    #[test]
    fn a_scattered_grid_equals_a_query_per_point() {
        for classification in [Classification::Post, Classification::Pre] {
            let f = field(classification);
            let lo = DVec3::splat(1e3) - 0.05;
            let hi = DVec3::splat(1e3) + DVec3::new(2.0, 1.0, 0.7) + 0.05;
            assert_matches_queries(&f, &RegularGrid::cell_centred(lo, hi, [37, 23, 11]));
            // A slice as `aarbf slice --axis x` takes it: grid i along z, j down y, one x.
            let slice = RegularGrid {
                origin: DVec3::new(1e3 + 0.7, 1e3 + 1.0, 1e3),
                axes: [2, 1, 0],
                spacing: [0.7 / 29.0, -1.0 / 17.0, 0.0],
                dims: [30, 18, 1],
            };
            assert_matches_queries(&f, &slice);
        }
    }

    #[test]
    fn a_scattered_grid_does_not_depend_on_the_threads() {
        let f = field(Classification::Post);
        let grid = RegularGrid::cell_centred(
            DVec3::splat(1e3),
            DVec3::splat(1e3) + DVec3::new(2.0, 1.0, 0.7),
            [19, 31, 7],
        );
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| f.eval_grid(&grid));
        let three = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap()
            .install(|| f.eval_grid(&grid));
        assert_eq!(one, three);
        assert!(RegularGrid::cell_centred(DVec3::ZERO, DVec3::ONE, [0, 4, 4]).is_empty());
        assert!(
            f.eval_grid(&RegularGrid::cell_centred(
                DVec3::ZERO,
                DVec3::ONE,
                [0, 4, 4]
            ))
            .is_empty()
        );
    }
}
