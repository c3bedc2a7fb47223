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
//!
//! A particle's points along a grid row are evaluated eight at a time, branch-free (a point
//! beyond the radius adds 0), by a block kernel compiled twice like the f32 field kernel: for
//! baseline x86-64 and, chosen at run time, for AVX2 + FMA (the same roundings, so the same
//! bits; tested).

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
    /// The first point (i = j = k = 0), in data coordinates.
    pub origin: DVec3,
    /// The data axis (0 = x, 1 = y, 2 = z) each grid index (i, j, k) runs along: a permutation
    /// of 0, 1 and 2.
    pub axes: [usize; 3],
    /// The distance between neighbouring points along each grid index, in data units
    /// (negative: the index runs down its axis).
    pub spacing: [f64; 3],
    /// Points along each grid index (i, j, k).
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

    /// The number of points: the product of `dims`.
    pub fn len(&self) -> usize {
        self.dims.iter().product()
    }

    /// Whether the grid has no points (a dimension is 0).
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
        // A few blocks a thread, so that uneven data still shares out: each block repeats
        // the exponentials along x and y of the particles reaching it from a neighbour's
        // planes, so many small blocks cost more than they balance (measured: 16 a thread
        // against 4, docs/notes/2026-12-01-field-grid.md).
        let blocks = (4 * rayon::current_num_threads()).min(rows).max(1);
        let rows_per_block = rows.div_ceil(blocks);
        let blocks = rows.div_ceil(rows_per_block);
        // The particles that reach a grid point, each with the grid points within its
        // radius along each dimension (first and end index), in order.
        let reaching: Vec<(u32, [u32; 6])> = (0..particles.len())
            .into_par_iter()
            .filter_map(|p| {
                let r = particles.radii[p];
                if r.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return None;
                }
                let centre = particles.origin + particles.centers[p];
                let [i, j, k] = [0, 1, 2].map(|d| grid.span(d, centre, r));
                let span = [i.start, i.end, j.start, j.end, k.start, k.end].map(|v| v as u32);
                (!i.is_empty() && !j.is_empty() && !k.is_empty()).then_some((p as u32, span))
            })
            .collect();
        // Those reaching each block, in order (indices into `reaching`).
        let mut members: Vec<Vec<u32>> = vec![Vec::new(); blocks];
        for (at, (_, span)) in reaching.iter().enumerate() {
            let [_, _, j0, j1, k0, k1] = span.map(|v| v as usize);
            let first = (k0 * ny + j0) / rows_per_block;
            let last = ((k1 - 1) * ny + j1 - 1) / rows_per_block;
            for members in &mut members[first..=last] {
                members.push(at as u32);
            }
        }
        // Distances are summed x, y, z (data axes), as the reference sums them, so the cut-off
        // test d <= r decides exactly as a query does. Along a grid row only the term of grid
        // dimension 0 varies; the sum is `(tx + u) + v` when that dimension is data axis x or
        // y (addition commutes), and `s + tx` when it is z.
        let x_last = grid.axes[0] == 2;
        let coords = [0, 1, 2].map(|d| grid.local_coordinates(d, particles.origin));
        let channels = match &particles.theta {
            Theta::None => 0,
            Theta::Scalar(_) => 1,
            Theta::Rgb(_) => 3,
        };
        let scatter = Scatter {
            particles,
            grid,
            reaching: &reaching,
            coords: &coords,
            x_last,
        };
        let mut out = vec![(0.0, [0.0; 3]); grid.len()];
        out.par_chunks_mut(rows_per_block * nx)
            .zip(members.par_iter())
            .enumerate()
            .for_each(|(b, (out, members))| {
                let row0 = b * rows_per_block;
                let rows = row0..row0 + out.len() / nx;
                let mut sums = [0.0; 4];
                let mut write = |acc: &[Vec<f64>]| {
                    let stride = nx + LANES;
                    for (at, o) in out.iter_mut().enumerate() {
                        let a = (at / nx) * stride + at % nx;
                        for (s, acc) in sums.iter_mut().zip(acc) {
                            *s = acc[a];
                        }
                        *o = (sums[0], [sums[1], sums[2], sums[3]]);
                    }
                };
                match channels {
                    0 => write(&scatter.block::<1>(members, rows)),
                    1 => write(&scatter.block::<2>(members, rows)),
                    _ => write(&scatter.block::<4>(members, rows)),
                }
            });
        out
    }
}

/// One block of grid rows' share of [`Particles::eval_grid_sums`]: what every block reads.
struct Scatter<'a> {
    particles: &'a Particles,
    grid: &'a RegularGrid,
    /// The particles that reach the grid, with the grid points within reach along each
    /// dimension (first and end index).
    reaching: &'a [(u32, [u32; 6])],
    /// The grid's points along each dimension, in local coordinates.
    coords: &'a [Vec<f64>; 3],
    /// Whether grid dimension 0 runs along data axis z (see the caller).
    x_last: bool,
}

impl Scatter<'_> {
    /// Phi and the Theta numerators (`S - 1` channels) of every point of grid rows `rows`,
    /// `S` values a point, from the particles `members` (in order).
    fn block<const S: usize>(
        &self,
        members: &[u32],
        rows: std::ops::Range<usize>,
    ) -> [Vec<f64>; S] {
        #[cfg(target_arch = "x86_64")]
        if crate::field::f32_kernel::simd_in_use() {
            // SAFETY: the CPU has AVX2 and FMA (checked at run time by `simd_in_use`).
            return unsafe { self.block_avx2::<S>(members, rows) };
        }
        self.block_lanes::<S>(members, rows)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn block_avx2<const S: usize>(
        &self,
        members: &[u32],
        rows: std::ops::Range<usize>,
    ) -> [Vec<f64>; S] {
        self.block_lanes::<S>(members, rows)
    }

    /// The block, written once for both builds: Rust never fuses `a * b + c`, so the AVX2 build
    /// rounds exactly as the baseline one (the result is the same bit for bit). Returns each
    /// channel's sums (Phi, then the Theta numerators) over the rows, `nx + LANES` values a
    /// row (the padding lets a row's last lanes run past its end).
    #[inline(always)]
    fn block_lanes<const S: usize>(
        &self,
        members: &[u32],
        rows: std::ops::Range<usize>,
    ) -> [Vec<f64>; S] {
        if self.particles.kernel.is_sph() {
            self.block_kernel::<S, true>(members, rows)
        } else {
            self.block_kernel::<S, false>(members, rows)
        }
    }

    /// [`Self::block_lanes`] for the Gaussian (separable: `SPH` false) or an SPH kernel (its
    /// profile per point, from the same d² the reference computes).
    #[inline(always)]
    fn block_kernel<const S: usize, const SPH: bool>(
        &self,
        members: &[u32],
        rows: std::ops::Range<usize>,
    ) -> [Vec<f64>; S] {
        let kernel = self.particles.kernel;
        let [nx, ny, _] = self.grid.dims;
        let stride = nx + LANES;
        let particles = self.particles;
        let mut acc: [Vec<f64>; S] = std::array::from_fn(|_| vec![0.0f64; rows.len() * stride]);
        // Per dimension and point of the particle's span: the squared distance along that
        // axis and its Gaussian factor (the kernel is separable: exp(-4.5 d²/r²) is the
        // product of the three axes' factors). Along x, padded with LANES points out of reach.
        let mut t: [Vec<f64>; 3] = Default::default();
        let mut e: [Vec<f64>; 3] = Default::default();
        let yz_in_order = self.grid.axes[1] < self.grid.axes[2];
        for &at in members {
            let (p, span) = self.reaching[at as usize];
            let p = p as usize;
            let span = [0, 1, 2].map(|d| span[2 * d] as usize..span[2 * d + 1] as usize);
            // A particle reaching several blocks pays its exponentials along k only for the
            // planes of this one (blocks are runs of whole rows; one spans a few planes).
            let k = span[2].start.max(rows.start / ny)..span[2].end.min((rows.end - 1) / ny + 1);
            if k.is_empty() {
                continue;
            }
            let span = [span[0].clone(), span[1].clone(), k];
            let r = particles.radii[p];
            let r2 = r * r;
            let c = particles.centers[p];
            for d in 0..3 {
                let centre = c[self.grid.axes[d]];
                t[d].clear();
                t[d].extend(
                    self.coords[d][span[d].clone()]
                        .iter()
                        .map(|&x| (x - centre) * (x - centre)),
                );
                e[d].clear();
                if SPH {
                    // Not separable: the profile is taken per point below.
                    e[d].resize(t[d].len(), 1.0);
                } else {
                    e[d].extend(t[d].iter().map(|&t| (-4.5 * t / r2).exp()));
                }
            }
            t[0].extend([f64::INFINITY; LANES]);
            e[0].extend([0.0; LANES]);
            let w = particles.weights[p];
            // What a point's sums gain per unit of phi: 1, then theta.
            let mut gain = [1.0; S];
            match &particles.theta {
                Theta::None => {}
                Theta::Scalar(t) => gain[1] = t[p],
                Theta::Rgb(c) => gain[1..].copy_from_slice(&c[p][..S - 1]),
            }
            let [i, j, k] = &span;
            for kk in k.clone() {
                let j0 = j.start.max(rows.start.saturating_sub(kk * ny));
                let j1 = j.end.min(rows.end.saturating_sub(kk * ny));
                let (tz, ez) = (t[2][kk - k.start], e[2][kk - k.start]);
                for jj in j0..j1 {
                    let (ty, ey) = (t[1][jj - j.start], e[1][jj - j.start]);
                    let weight = w * ey * ez;
                    let row = (kk * ny + jj - rows.start) * stride + i.start;
                    // The other two terms in the data axes' order (see `x_last`).
                    let [u, v] = if yz_in_order { [ty, tz] } else { [tz, ty] };
                    for chunk in (0..i.len()).step_by(LANES) {
                        let lanes = |v: &[f64]| -> [f64; LANES] {
                            v[chunk..chunk + LANES].try_into().expect("padded")
                        };
                        let (tx, ex) = (lanes(&t[0]), lanes(&e[0]));
                        let mut phi = [0.0; LANES];
                        for l in 0..LANES {
                            let d2 = if self.x_last {
                                (u + v) + tx[l]
                            } else {
                                (tx[l] + u) + v
                            };
                            // Without a branch: a point beyond the radius adds 0 (the
                            // padding lies beyond every radius).
                            phi[l] = if d2 > r2 {
                                0.0
                            } else if SPH {
                                weight * kernel.profile(d2, r2)
                            } else {
                                weight * ex[l]
                            };
                        }
                        for (acc, g) in acc.iter_mut().zip(gain) {
                            let acc: &mut [f64; LANES] = (&mut acc
                                [row + chunk..row + chunk + LANES])
                                .try_into()
                                .expect("padded");
                            for l in 0..LANES {
                                acc[l] += g * phi[l];
                            }
                        }
                    }
                }
            }
        }
        acc
    }
}

/// Grid points evaluated together along a row.
const LANES: usize = 8;

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
        field_with(classification, crate::field::Kernel::GaussianRbf)
    }

    fn field_with(classification: Classification, kernel: crate::field::Kernel) -> ReferenceField {
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
        let m = (0..n).map(|_| 0.5 + rng.random::<f64>()).collect();
        let rho = (0..n)
            .map(|_| 900.0 + 200.0 * rng.random::<f64>())
            .collect();
        let attribute = |name: &str, values| Attribute {
            name: name.into(),
            values,
        };
        let step = Step {
            name: "grid".into(),
            positions,
            attributes: vec![
                attribute("s", s),
                attribute("h", h),
                attribute("m", m),
                attribute("rho", rho),
            ],
        };
        let mut settings = FieldSettings::new(Some("s"), 0.11);
        if kernel.is_sph() {
            settings.kernel = kernel;
            settings.mass = Some(crate::field::PerParticle::Attribute("m".into()));
            settings.density = Some(crate::field::PerParticle::Attribute("rho".into()));
        }
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
            // Fine along x: a particle reaches more than one chunk of eight points of a row.
            assert_matches_queries(&f, &RegularGrid::cell_centred(lo, hi, [131, 9, 5]));
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

    /// An SPH kernel (not separable: its profile is taken per point) scatters onto the grid
    /// the values a query per point gives.
    #[test]
    fn an_sph_kernel_scatters_what_the_queries_give() {
        for kernel in crate::field::Kernel::ALL.into_iter().filter(|k| k.is_sph()) {
            let f = field_with(Classification::Post, kernel);
            let lo = DVec3::splat(1e3) - 0.05;
            let hi = DVec3::splat(1e3) + DVec3::new(2.0, 1.0, 0.7) + 0.05;
            assert_matches_queries(&f, &RegularGrid::cell_centred(lo, hi, [37, 23, 11]));
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
        // The baseline build of the block kernel gives the same bits as the AVX2 one.
        crate::field::f32_kernel::allow_simd(false);
        let baseline = f.eval_grid(&grid);
        crate::field::f32_kernel::allow_simd(true);
        assert_eq!(one, baseline);
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
