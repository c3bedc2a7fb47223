//! The field in f32 on the CPU: a step's particles (the reference's, already evaluated:
//! radius, weight and theta) packed as f32 structure-of-arrays in local coordinates, sorted
//! into a uniform grid of cells at least as wide as the largest radius, and evaluated eight
//! at a time by [`f32_kernel`](super::f32_kernel). What it costs in error is the GPU backends'
//! f32 rule (`backend::gpu_data::f32_phi_error` for the positions, about 1e-6 for the
//! arithmetic); the CPU backend uses it where that rule allows, and the f64 reference
//! everywhere else.
//!
//! Why cells and not the cluster BVH the reference and the GPUs traverse: a particle reaches at
//! most one cell beyond its own, so a point's candidates are the particles of its cell's 27
//! neighbours, nine contiguous runs of the cell-sorted arrays, found with arithmetic instead of
//! a tree walk and evaluated where they lie (no copy). A query keeps its cell's runs, and the
//! next query in the same cell (consecutive samples of a ray, Hilbert-ordered query points)
//! looks nothing up. Empty space along a ray is skipped cell by cell (a 3D
//! DDA over the cells some particle may reach). The cost is overfetch: candidates fill the
//! 3x3x3 cells around a point, about 27 / (4/3 π) = 6.4 times the particles within the
//! largest radius; eight lanes at a time pay for it several times over (`benches/cpu_roofline`).
//! A packet of neighbouring rays' samples ([`F32Field::eval_sums_packet`]) shares one lookup
//! and one narrowing of its candidates to those within reach of all of them, and evaluates
//! them a sample per lane: samples along rays lie much closer together than a radius.

use glam::DVec3;
use rayon::prelude::*;

use super::f32_kernel::{LANES, Packed};
use super::{Particles, Theta};

/// Cells per particle at most (the grid's index costs 5 bytes a cell): a sparse scene gets
/// wider cells rather than a grid larger than its particles.
const CELLS_PER_PARTICLE: usize = 4;

/// A step's field for the f32 kernel.
#[derive(Clone, Debug)]
pub struct F32Field {
    /// Local coordinates are data coordinates minus this (the reference's origin).
    origin: DVec3,
    /// The grid's corner, in local coordinates; cell (i, j, k) spans `corner + [i, i+1) h`...
    corner: DVec3,
    cell: f64,
    inv_cell: f64,
    dims: [usize; 3],
    /// Particles of cell c are `start[c] .. start[c + 1]` (cells x fastest, then y, then z).
    start: Vec<u32>,
    /// Whether any particle may reach into the cell (it or a neighbour holds one).
    reached: Vec<bool>,
    /// The particles, cell by cell (in Hilbert order within a cell).
    particles: Packed,
}

impl F32Field {
    /// Packs `p` (with its field applied) into cells. Particles of radius 0 reach nothing and
    /// are left out, as in the reference.
    pub fn new(p: &Particles) -> F32Field {
        let live: Vec<u32> = (0..p.len() as u32)
            .into_par_iter()
            .filter(|&i| p.radii[i as usize] > 0.0)
            .collect();
        let r_max = live
            .par_iter()
            .map(|&i| p.radii[i as usize])
            .reduce(|| 0.0, f64::max);
        let (lo, hi) = live
            .par_iter()
            .map(|&i| (p.centers[i as usize], p.centers[i as usize]))
            .reduce(
                || (DVec3::INFINITY, DVec3::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let (corner, cell, dims) = if live.is_empty() {
            (DVec3::ZERO, 1.0, [1, 1, 1])
        } else {
            grid_over(lo, hi, r_max, live.len())
        };
        let inv = 1.0 / cell;
        let cell_of = |c: DVec3| -> usize {
            let g = ((c - corner) * inv).floor();
            cell_index(
                dims,
                [0, 1, 2].map(|a| (g[a].max(0.0) as usize).min(dims[a] - 1)),
            )
        };
        let mut keyed: Vec<(u32, u32)> = live
            .par_iter()
            .map(|&i| (cell_of(p.centers[i as usize]) as u32, i))
            .collect();
        // Stable: particles of a cell keep their Hilbert order.
        keyed.par_sort_by_key(|&(c, _)| c);
        let cells = dims[0] * dims[1] * dims[2];
        let mut start = vec![0u32; cells + 1];
        for &(c, _) in &keyed {
            start[c as usize + 1] += 1;
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        let reached: Vec<bool> = (0..cells)
            .into_par_iter()
            .map(|c| {
                let ijk = cell_coords(dims, c);
                let mut any = false;
                for_rows_around(dims, ijk, ijk, |a, b| any |= start[b + 1] > start[a]);
                any
            })
            .collect();
        tracing::debug!(
            "f32 field: {} particles in {}x{}x{} cells of {cell:.3e} (largest radius {r_max:.3e}), {} cells reached",
            keyed.len(),
            dims[0],
            dims[1],
            dims[2],
            reached.iter().filter(|&&r| r).count()
        );
        let order: Vec<usize> = keyed.iter().map(|&(_, i)| i as usize).collect();
        let f32s = |f: &(dyn Fn(usize) -> f32 + Sync)| -> Vec<f32> {
            order.par_iter().map(|&i| f(i)).collect()
        };
        let (theta, channels) = match &p.theta {
            Theta::None => ([Vec::new(), Vec::new(), Vec::new()], 0),
            Theta::Scalar(t) => ([f32s(&|i| t[i] as f32), Vec::new(), Vec::new()], 1),
            Theta::Rgb(c) => ([0, 1, 2].map(|ch| f32s(&|i| c[i][ch] as f32)), 3),
        };
        let mut particles = Packed {
            x: f32s(&|i| p.centers[i].x as f32),
            y: f32s(&|i| p.centers[i].y as f32),
            z: f32s(&|i| p.centers[i].z as f32),
            r2: f32s(&|i| (p.radii[i] * p.radii[i]) as f32),
            k: f32s(&|i| (4.5 / (p.radii[i] * p.radii[i])) as f32),
            w: f32s(&|i| p.weights[i] as f32),
            theta,
            channels,
        };
        particles.pad();
        F32Field {
            origin: p.origin,
            corner,
            cell,
            inv_cell: inv,
            dims,
            start,
            reached,
            particles,
        }
    }

    /// Bytes of the packed particles.
    pub fn particle_bytes(&self) -> usize {
        self.particles.bytes()
    }

    /// Bytes of the grid (the cells' starts and whether each is reached).
    pub fn grid_bytes(&self) -> usize {
        4 * self.start.len() + self.reached.len()
    }

    /// The cell holding local point `l` (its index and coordinates), if it is in the grid.
    #[inline]
    fn cell_at(&self, l: DVec3) -> Option<(usize, [usize; 3])> {
        let g = (l - self.corner) * self.inv_cell;
        let mut idx = [0usize; 3];
        for a in 0..3 {
            // NaN fails the test too.
            if !(g[a] >= 0.0 && g[a] < self.dims[a] as f64) {
                return None;
            }
            // Through u32 (a cell count fits): baseline x86-64 converts f64 to u64 in a
            // sequence of instructions, to u32 in one.
            idx[a] = g[a] as u32 as usize;
        }
        Some((cell_index(self.dims, idx), idx))
    }

    /// The particles of the cells around the block `lo..=hi` (one cell beyond it on every
    /// side: the 27 neighbours of a cell), as runs of particle indices, one per row of cells.
    fn runs(&self, lo: [usize; 3], hi: [usize; 3], out: &mut Vec<(u32, u32)>) {
        out.clear();
        for_rows_around(self.dims, lo, hi, |a, b| {
            let run = (self.start[a], self.start[b + 1]);
            if run.1 > run.0 {
                out.push(run);
            }
        });
    }

    /// Phi and the Theta numerator at `x` (data coordinates). `scratch` keeps the last
    /// cell's runs: a query in the same cell looks nothing up.
    pub fn eval_sums(&self, x: DVec3, scratch: &mut F32Ray) -> (f64, [f64; 3]) {
        let l = x - self.origin;
        let Some((c, ijk)) = self.cell_at(l) else {
            return (0.0, [0.0; 3]);
        };
        if !self.reached[c] {
            return (0.0, [0.0; 3]);
        }
        if scratch.cell != Some(c) {
            self.runs(ijk, ijk, &mut scratch.runs);
            scratch.cell = Some(c);
        }
        self.particles
            .sums(&scratch.runs, [l.x as f32, l.y as f32, l.z as f32])
    }

    /// [`F32Field::eval_sums`] at each of `points` (`None`: no sample; its value is left as
    /// it is), close together (a packet of neighbouring rays' samples): where they lie within
    /// two cells a side, their candidates are found once and evaluated a point per lane
    /// ([`Packed::packet_sums`]); otherwise, or for a lone point, each is evaluated alone with
    /// its ray's `rays[i]`. Returns how many points were evaluated together (0: each alone).
    pub fn eval_sums_packet(
        &self,
        points: &[Option<DVec3>; LANES],
        packet: &mut F32Packet,
        rays: &mut [F32Ray; LANES],
        out: &mut [(f64, [f64; 3]); LANES],
    ) -> usize {
        let mut q = [[0f32; 3]; LANES];
        let mut live = [0u32; LANES];
        let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
        let mut count = 0;
        for (i, point) in points.iter().enumerate() {
            let Some(x) = point else { continue };
            let l = *x - self.origin;
            match self.cell_at(l) {
                Some((c, ijk)) if self.reached[c] => {
                    q[i] = [l.x as f32, l.y as f32, l.z as f32];
                    live[i] = u32::MAX;
                    count += 1;
                    for a in 0..3 {
                        lo[a] = lo[a].min(ijk[a]);
                        hi[a] = hi[a].max(ijk[a]);
                    }
                }
                _ => out[i] = (0.0, [0.0; 3]),
            }
        }
        if count == 0 {
            return 0;
        }
        if count == 1 || (0..3).any(|a| hi[a] - lo[a] > 1) {
            for (i, x) in points.iter().enumerate() {
                if let (Some(x), true) = (x, live[i] != 0) {
                    out[i] = self.eval_sums(*x, &mut rays[i]);
                }
            }
            return 0;
        }
        if packet.cells != Some((lo, hi)) {
            self.runs(lo, hi, &mut packet.runs);
            packet.cells = Some((lo, hi));
        }
        let sums = self
            .particles
            .packet_sums(&packet.runs, &q, live, &mut packet.candidates);
        for (i, s) in sums.into_iter().enumerate() {
            if live[i] != 0 {
                out[i] = s;
            }
        }
        count
    }

    /// Appends the disjoint, ordered sub-intervals of `[t0, t1]` along `origin + t dir` (data
    /// coordinates) that cross a cell some particle may reach: outside them the field is 0.
    /// A 3D DDA over the cells (Amanatides and Woo).
    pub fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        // Grid coordinates: cell (i, j, k) is [i, i+1) x [j, j+1) x [k, k+1).
        let o = (origin - self.origin - self.corner) / self.cell;
        let d = dir / self.cell;
        let size = DVec3::new(
            self.dims[0] as f64,
            self.dims[1] as f64,
            self.dims[2] as f64,
        );
        let inv = d.recip();
        let a = (DVec3::ZERO - o) * inv;
        let b = (size - o) * inv;
        let enter = a.min(b).max_element().max(t0);
        let exit = a.max(b).min_element().min(t1);
        if enter.is_nan() || exit.is_nan() || enter >= exit {
            return;
        }
        let p = o + d * enter;
        let mut cell = [0i64; 3];
        let mut next = [f64::INFINITY; 3];
        let mut delta = [f64::INFINITY; 3];
        let mut step = [0i64; 3];
        for ax in 0..3 {
            // Truncation, not floor: they differ only below 0, which the clamp maps to 0.
            cell[ax] = (p[ax] as i64).clamp(0, self.dims[ax] as i64 - 1);
            if d[ax] > 0.0 {
                step[ax] = 1;
                delta[ax] = inv[ax];
                next[ax] = enter + ((cell[ax] + 1) as f64 - p[ax]) * inv[ax];
            } else if d[ax] < 0.0 {
                step[ax] = -1;
                delta[ax] = -inv[ax];
                next[ax] = enter + (cell[ax] as f64 - p[ax]) * inv[ax];
            }
        }
        let mut t = enter;
        // The cell's index, stepped along with its coordinates.
        let stride = [1, self.dims[0] as i64, (self.dims[0] * self.dims[1]) as i64];
        let mut c = cell_index(self.dims, cell.map(|v| v as usize)) as i64;
        loop {
            // The axis whose boundary comes first (the lowest on ties), as index arithmetic
            // rather than branches: which one it is changes unpredictably along a ray.
            let first_of_two = usize::from(next[1] < next[0]);
            let ax = if next[2] < next[first_of_two] {
                2
            } else {
                first_of_two
            };
            let leave = next[ax].min(exit);
            if self.reached[c as usize] && leave > t {
                match out.last_mut() {
                    Some(last) if last.1 >= t => last.1 = leave,
                    _ => out.push((t, leave)),
                }
            }
            if leave >= exit {
                return;
            }
            t = leave;
            cell[ax] += step[ax];
            if cell[ax] < 0 || cell[ax] >= self.dims[ax] as i64 {
                return;
            }
            c += step[ax] * stride[ax];
            next[ax] += delta[ax];
        }
    }
}

/// The grid over particle centres in `[lo, hi]` with radii up to `r_max`: its corner, cell
/// width and cells per axis, with a margin of one cell on every side (a particle reaches into
/// it, none lies in it). Cells are `r_max` wide unless that makes more than
/// [`CELLS_PER_PARTICLE`] a particle; then wider.
fn grid_over(lo: DVec3, hi: DVec3, r_max: f64, particles: usize) -> (DVec3, f64, [usize; 3]) {
    let extent = (hi - lo).max(DVec3::ZERO);
    let budget = (CELLS_PER_PARTICLE * particles + 4096) as f64;
    let dims_for =
        |cell: f64| -> [usize; 3] { [0, 1, 2].map(|a| (extent[a] / cell).floor() as usize + 3) };
    let mut cell = r_max
        .max(extent.max_element() * 1e-9)
        .max(f64::MIN_POSITIVE);
    loop {
        let d = dims_for(cell);
        let cells = d.iter().map(|&n| n as f64).product::<f64>();
        if cells <= budget {
            return (lo - DVec3::splat(cell), cell, d);
        }
        cell *= (cells / budget).cbrt().max(1.01);
    }
}

/// Calls `row(first, last)` with the first and last cell index of each x-row of cells around
/// the block `lo..=hi` (one cell beyond it on every side, clipped to the grid: for one cell,
/// its 27 neighbours in nine rows). Plain loops: an iterator chain of inclusive ranges cost
/// 4% of a frame.
#[inline]
fn for_rows_around(
    dims: [usize; 3],
    lo: [usize; 3],
    hi: [usize; 3],
    mut row: impl FnMut(usize, usize),
) {
    let below = |a: usize| lo[a].saturating_sub(1);
    let above = |a: usize| (hi[a] + 1).min(dims[a] - 1);
    let (i0, i1) = (below(0), above(0));
    for k in below(2)..above(2) + 1 {
        for j in below(1)..above(1) + 1 {
            let first = cell_index(dims, [i0, j, k]);
            row(first, first + (i1 - i0));
        }
    }
}

/// The index of cell `ijk` (x fastest, then y, then z).
#[inline]
fn cell_index(dims: [usize; 3], ijk: [usize; 3]) -> usize {
    ijk[0] + dims[0] * (ijk[1] + dims[1] * ijk[2])
}

/// The cell coordinates of index `c` ([`cell_index`]'s inverse).
#[inline]
fn cell_coords(dims: [usize; 3], c: usize) -> [usize; 3] {
    [
        c % dims[0],
        (c / dims[0]) % dims[1],
        c / (dims[0] * dims[1]),
    ]
}

/// Sampling a packet of rays together: the runs of candidates of the last block of cells its
/// samples fell in, and the candidates gathered for the last packet. Made once per thread.
#[derive(Debug, Default)]
pub struct F32Packet {
    cells: Option<([usize; 3], [usize; 3])>,
    runs: Vec<(u32, u32)>,
    candidates: Vec<u32>,
}

/// Sampling along rays (and point queries): the runs of candidates of the last cell visited,
/// kept for the next sample in it. Made once per thread and reused.
#[derive(Debug, Default)]
pub struct F32Ray {
    runs: Vec<(u32, u32)>,
    cell: Option<usize>,
}
