//! A uniform grid of cells over particle centres, at least as wide as the largest radius: the
//! point-query structure of the CPU's field, in both precisions (`field::F32Field`, and the
//! f64 reference's point queries).
//!
//! Why cells and not the cluster BVH the GPUs traverse: a particle reaches at most one cell
//! beyond its own, so a point's candidates are the particles of its cell's 27 neighbours, nine
//! contiguous runs of the cell-sorted particles, found with arithmetic instead of a tree walk
//! and evaluated where they lie (no copy, several at a time). A query keeps its cell's runs, and
//! the next query in the same cell (consecutive samples of a ray, Hilbert-ordered query points)
//! looks nothing up. Empty space along a ray is skipped cell by cell (a 3D DDA over the cells
//! some particle may reach). The cost is overfetch: candidates fill the 3x3x3 cells around a
//! point, about 27 / (4/3 π) = 6.4 times the particles within the largest radius.

use glam::DVec3;
use rayon::prelude::*;

/// Cells per particle at most (the grid's index costs 5 bytes a cell): a sparse scene gets
/// wider cells rather than a grid larger than its particles.
const CELLS_PER_PARTICLE: usize = 4;

/// The grid: which particles each cell holds (as a range of the cell-sorted order) and whether
/// any particle may reach into it. Coordinates are the particles' (local) coordinates.
#[derive(Clone, Debug)]
pub struct CellGrid {
    /// Cell (i, j, k) spans `corner + [i, i+1) h` on x, and so on.
    corner: DVec3,
    cell: f64,
    inv_cell: f64,
    dims: [usize; 3],
    /// Particles of cell c are `start[c] .. start[c + 1]` of the cell-sorted order (cells x
    /// fastest, then y, then z).
    start: Vec<u32>,
    /// Whether any particle may reach into the cell (it or a neighbour holds one).
    reached: Vec<bool>,
}

/// The runs of candidates of the last cell (or block of cells) a query fell in, kept for the
/// next query there. Made once per thread (or ray) and reused.
#[derive(Debug, Default)]
pub struct CellRuns {
    runs: Vec<(u32, u32)>,
    cells: Option<([usize; 3], [usize; 3])>,
}

impl CellGrid {
    /// Sorts the particles of radius > 0 (the others reach nothing) into cells. Returns the
    /// grid and the particles' indices cell by cell: position `p` of the cell-sorted order is
    /// particle `order[p]`, and within a cell the input order is kept.
    pub fn build(centers: &[DVec3], radii: &[f64]) -> (CellGrid, Vec<u32>) {
        let live: Vec<u32> = (0..centers.len() as u32)
            .into_par_iter()
            .filter(|&i| radii[i as usize] > 0.0)
            .collect();
        let r_max = live
            .par_iter()
            .map(|&i| radii[i as usize])
            .reduce(|| 0.0, f64::max);
        let (lo, hi) = live
            .par_iter()
            .map(|&i| (centers[i as usize], centers[i as usize]))
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
            .map(|&i| (cell_of(centers[i as usize]) as u32, i))
            .collect();
        // Stable: particles of a cell keep their input (Hilbert) order.
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
            "cells: {} particles in {}x{}x{} cells of {cell:.3e} (largest radius {r_max:.3e}), {} cells reached",
            keyed.len(),
            dims[0],
            dims[1],
            dims[2],
            reached.iter().filter(|&&r| r).count()
        );
        let order = keyed.into_iter().map(|(_, i)| i).collect();
        let grid = CellGrid {
            corner,
            cell,
            inv_cell: inv,
            dims,
            start,
            reached,
        };
        (grid, order)
    }

    /// Bytes of the grid (the cells' starts and whether each is reached).
    pub fn bytes(&self) -> usize {
        4 * self.start.len() + self.reached.len()
    }

    /// The cell holding point `l` (its index and coordinates), if it is in the grid.
    #[inline]
    pub fn cell_at(&self, l: DVec3) -> Option<(usize, [usize; 3])> {
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

    /// Whether any particle may reach into cell `c`.
    #[inline]
    pub fn is_reached(&self, c: usize) -> bool {
        self.reached[c]
    }

    /// The candidates of the block of cells `lo..=hi`: the particles of the cells around it
    /// (one cell beyond it on every side: the 27 neighbours of a cell), as runs of the
    /// cell-sorted order, one per row of cells. Kept in `scratch`: the same block again looks
    /// nothing up.
    #[inline]
    pub fn runs_around<'s>(
        &self,
        lo: [usize; 3],
        hi: [usize; 3],
        scratch: &'s mut CellRuns,
    ) -> &'s [(u32, u32)] {
        if scratch.cells != Some((lo, hi)) {
            scratch.runs.clear();
            for_rows_around(self.dims, lo, hi, |a, b| {
                let run = (self.start[a], self.start[b + 1]);
                if run.1 > run.0 {
                    scratch.runs.push(run);
                }
            });
            scratch.cells = Some((lo, hi));
        }
        &scratch.runs
    }

    /// Appends the disjoint, ordered sub-intervals of `[t0, t1]` along `origin + t dir` (the
    /// grid's coordinates) that cross a cell some particle may reach: outside them the field is
    /// 0. A 3D DDA over the cells (Amanatides and Woo).
    pub fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        // Grid coordinates: cell (i, j, k) is [i, i+1) x [j, j+1) x [k, k+1).
        let o = (origin - self.corner) / self.cell;
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
/// it, none lies in it). Cells are `r_max` wide (a hair wider) unless that makes more than
/// [`CELLS_PER_PARTICLE`] a particle; then wider.
fn grid_over(lo: DVec3, hi: DVec3, r_max: f64, particles: usize) -> (DVec3, f64, [usize; 3]) {
    let extent = (hi - lo).max(DVec3::ZERO);
    let budget = (CELLS_PER_PARTICLE * particles + 4096) as f64;
    let dims_for =
        |cell: f64| -> [usize; 3] { [0, 1, 2].map(|a| (extent[a] / cell).floor() as usize + 3) };
    // A hair wider than the largest radius: a point at exactly r from a particle then lies
    // within the neighbour cell however the cell coordinates round.
    let mut cell = (r_max * (1.0 + 1e-9))
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
