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
//!
//! Radii that vary (SPH smoothing lengths: small in dense regions, large in sparse ones)
//! would make cells as wide as the largest radius hold whole dense regions, so particles are
//! sorted into levels by radius, each a factor of two below the last, each with its own grid
//! as wide as its largest radius: a point's candidates are the 27 cells around it on every
//! level. Radii within a factor of two of the largest make one level (the common case: nothing
//! changes); a dense clump of small particles in a halo of large ones (100K of radius 0.002 in
//! a cube of 0.05, 100K of radius 0.06 in the unit cube) no longer hands every query in the
//! clump the whole clump.

use glam::DVec3;
use rayon::prelude::*;

/// Cells per particle at most (the grid's index costs 5 bytes a cell): a sparse scene gets
/// wider cells rather than a grid larger than its particles.
const CELLS_PER_PARTICLE: usize = 4;

/// Levels of radii at most (the last holds every radius below its bound).
const MAX_LEVELS: usize = 12;

/// The grids, one per level of radii, largest radii first.
#[derive(Clone, Debug)]
pub struct CellGrid {
    levels: Vec<Level>,
}

/// One level's grid: which particles each cell holds (as a range of the cell-sorted order) and
/// whether any particle of the level may reach into it. Coordinates are the particles' (local)
/// coordinates.
#[derive(Clone, Debug)]
struct Level {
    /// Cell (i, j, k) spans `corner + [i, i+1) h` on x, and so on.
    corner: DVec3,
    cell: f64,
    inv_cell: f64,
    dims: [usize; 3],
    /// Particles of cell c are `start[c] .. start[c + 1]` of the cell-sorted order (cells x
    /// fastest, then y, then z; the level's particles after the levels before it).
    start: Vec<u32>,
    /// Whether any particle may reach into the cell (it or a neighbour holds one), a bit a
    /// cell: a point query tests it for every point, and as bits it stays in L1 (as bytes it
    /// did not, and its loads were the most of a group's lookup).
    reached: Vec<u64>,
}

/// A block of cells on a level, as the coordinates of its first and last cell (what its runs
/// are made from; an index's coordinates would cost three divisions).
type Block = ([u32; 3], [u32; 3]);

/// No block of cells on a level (the point lies outside its grid or where none of its
/// particles reaches).
const NO_BLOCK: Block = ([u32::MAX; 3], [0; 3]);

/// The runs of candidates of the last cells (or blocks of cells) a query fell in, kept for the
/// next query there. Made once per thread (or ray) and reused.
#[derive(Debug)]
pub struct CellRuns {
    runs: Vec<(u32, u32)>,
    /// The block of cells on each level the runs are of.
    blocks: [Block; MAX_LEVELS],
    /// Whether `runs` are `blocks`' (false before the first query).
    current: bool,
}

impl Default for CellRuns {
    fn default() -> Self {
        CellRuns {
            runs: Vec::new(),
            blocks: [NO_BLOCK; MAX_LEVELS],
            current: false,
        }
    }
}

impl CellRuns {
    /// Sets level `i`'s block, noting whether it changed.
    #[inline]
    fn set(&mut self, i: usize, block: Block) {
        if self.blocks[i] != block {
            self.blocks[i] = block;
            self.current = false;
        }
    }

    /// The runs of the blocks set, made again only when one changed.
    #[inline]
    fn runs_for(&mut self, grid: &CellGrid) -> &[(u32, u32)] {
        if !self.current {
            self.current = true;
            self.runs.clear();
            for (level, &block) in grid.levels.iter().zip(&self.blocks) {
                if block == NO_BLOCK {
                    continue;
                }
                let (lo, hi) = (block.0.map(|v| v as usize), block.1.map(|v| v as usize));
                for_rows_around(level.dims, lo, hi, |a, b| {
                    let run = (level.start[a], level.start[b + 1]);
                    if run.1 > run.0 {
                        self.runs.push(run);
                    }
                });
            }
        }
        &self.runs
    }
}

impl CellGrid {
    /// Sorts the particles of radius > 0 (the others reach nothing) into cells, on levels by
    /// radius. Returns the grid and the particles' indices level by level and cell by cell:
    /// position `p` of the cell-sorted order is particle `order[p]`, and within a cell the
    /// input order is kept.
    pub fn build(centers: &[DVec3], radii: &[f64]) -> (CellGrid, Vec<u32>) {
        let r_max = radii
            .par_iter()
            .copied()
            .filter(|&r| r > 0.0)
            .reduce(|| 0.0, f64::max);
        // Level l holds radii in (r_max / 2^(l+1), r_max / 2^l]; the last, everything below.
        let level_of = |r: f64| -> usize {
            let l = (r_max / r).log2().floor();
            if l >= (MAX_LEVELS - 1) as f64 {
                MAX_LEVELS - 1
            } else {
                l.max(0.0) as usize
            }
        };
        let live: Vec<(u32, u32)> = (0..centers.len() as u32)
            .into_par_iter()
            .filter(|&i| radii[i as usize] > 0.0)
            .map(|i| (level_of(radii[i as usize]) as u32, i))
            .collect();
        let mut levels = Vec::new();
        let mut order = Vec::with_capacity(live.len());
        // A pass per level up to the last one used (one, where radii are within 2x).
        let deepest = live.par_iter().map(|&(l, _)| l).max().unwrap_or(0);
        for level in 0..=deepest {
            let members: Vec<u32> = live
                .par_iter()
                .filter(|&&(l, _)| l == level)
                .map(|&(_, i)| i)
                .collect();
            if members.is_empty() {
                continue;
            }
            levels.push(Level::build(
                centers,
                radii,
                &members,
                order.len() as u32,
                &mut order,
            ));
        }
        tracing::debug!(
            "cells: {} particles on {} levels of radii ({})",
            order.len(),
            levels.len(),
            levels
                .iter()
                .map(|l| format!(
                    "{}x{}x{} cells of {:.3e}",
                    l.dims[0], l.dims[1], l.dims[2], l.cell
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        (CellGrid { levels }, order)
    }

    /// Bytes of the grids (the cells' starts and whether each is reached).
    pub fn bytes(&self) -> usize {
        self.levels
            .iter()
            .map(|l| 4 * l.start.len() + 8 * l.reached.len())
            .sum()
    }

    /// The candidates of point `l`: the particles of the 27 cells around its cell on every
    /// level, as runs of the cell-sorted order (none where no particle reaches). Kept in
    /// `scratch`: a point in the same cells again looks nothing up.
    #[inline]
    pub fn runs_at<'s>(&self, l: DVec3, scratch: &'s mut CellRuns) -> &'s [(u32, u32)] {
        for (i, level) in self.levels.iter().enumerate() {
            match level.cell_at(l) {
                Some((c, ijk)) if level.reached(c) => {
                    let ijk = ijk.map(|v| v as u32);
                    scratch.set(i, (ijk, ijk));
                }
                _ => scratch.set(i, NO_BLOCK),
            }
        }
        scratch.runs_for(self)
    }

    /// Which of `points` (local coordinates; `None`: no point) lie in a cell some particle may
    /// reach on some level (bit i of the returned mask), and, where two or more do, their
    /// candidates together: the particles of the cells around the block of cells those points
    /// fall in, on every level. The runs are `None` for fewer than two such points, and where
    /// they spread over more than two cells a side on some level (evaluating them together
    /// would then cost more than one at a time). Each point's cells are found once.
    pub fn runs_around_packet<'s, const N: usize>(
        &self,
        points: &[Option<DVec3>; N],
        scratch: &'s mut CellRuns,
    ) -> (u32, Option<&'s [(u32, u32)]>) {
        const NONE: [u32; 3] = [u32::MAX; 3];
        // Each point's cell on each level (NONE: outside that level's grid).
        let mut cells = [[NONE; N]; MAX_LEVELS];
        let mut reached = 0u32;
        for (level, cells) in self.levels.iter().zip(&mut cells) {
            for (i, point) in points.iter().enumerate() {
                let Some(l) = point else { continue };
                if let Some((c, ijk)) = level.cell_at(*l) {
                    cells[i] = ijk.map(|v| v as u32);
                    reached |= u32::from(level.reached(c)) << i;
                }
            }
        }
        if reached.count_ones() < 2 {
            return (reached, None);
        }
        for (i, cells) in cells.iter().take(self.levels.len()).enumerate() {
            let (mut lo, mut hi) = ([u32::MAX; 3], [0; 3]);
            for (p, ijk) in cells.iter().enumerate() {
                if (reached >> p) & 1 == 1 && *ijk != NONE {
                    for a in 0..3 {
                        lo[a] = lo[a].min(ijk[a]);
                        hi[a] = hi[a].max(ijk[a]);
                    }
                }
            }
            if lo[0] == u32::MAX {
                scratch.set(i, NO_BLOCK);
            } else if (0..3).any(|a| hi[a] - lo[a] > 1) {
                return (reached, None);
            } else {
                scratch.set(i, (lo, hi));
            }
        }
        (reached, Some(scratch.runs_for(self)))
    }

    /// The longest run of `points` from the first (local coordinates; at most 32) whose cells
    /// on every level lie within a block of two cells a side, counting only the points in a
    /// cell some particle may reach on some level: how many points it holds, which of them lie
    /// in such a cell (bit i), and, where two or more do, their candidates together (the
    /// particles of the cells around their block, on every level). The run ends before the
    /// first point that would widen a block past two cells; it holds at least one point.
    /// Each point's cells are found once (what halving a group and looking up its points again
    /// cost: a seventh of the queries' time).
    pub fn runs_around_prefix<'s>(
        &self,
        points: &[DVec3],
        scratch: &'s mut CellRuns,
    ) -> (usize, u32, Option<&'s [(u32, u32)]>) {
        let levels = self.levels.len();
        let mut lo = [[u32::MAX; 3]; MAX_LEVELS];
        let mut hi = [[0u32; 3]; MAX_LEVELS];
        let mut reached = 0u32;
        let mut count = 0;
        for (i, l) in points.iter().take(32).enumerate() {
            let mut cells = [[u32::MAX; 3]; MAX_LEVELS];
            let (mut any, mut fits) = (false, true);
            for ((level, cell), (lo, hi)) in
                self.levels.iter().zip(&mut cells).zip(lo.iter().zip(&hi))
            {
                if let Some((c, ijk)) = level.cell_at(*l) {
                    *cell = ijk.map(|v| v as u32);
                    any |= level.reached(c);
                    for a in 0..3 {
                        fits &= cell[a].max(hi[a]) - cell[a].min(lo[a]) <= 1;
                    }
                }
            }
            if any {
                if !fits {
                    // It would widen a block past two cells.
                    break;
                }
                for (cell, (lo, hi)) in cells.iter().zip(lo.iter_mut().zip(&mut hi)).take(levels) {
                    if cell[0] != u32::MAX {
                        for a in 0..3 {
                            lo[a] = lo[a].min(cell[a]);
                            hi[a] = hi[a].max(cell[a]);
                        }
                    }
                }
                reached |= 1 << i;
            }
            count = i + 1;
        }
        // At least one point (the first widens nothing), unless there are none.
        if reached.count_ones() < 2 {
            return (count, reached, None);
        }
        for i in 0..levels {
            if lo[i][0] == u32::MAX {
                scratch.set(i, NO_BLOCK);
            } else {
                scratch.set(i, (lo[i], hi[i]));
            }
        }
        (count, reached, Some(scratch.runs_for(self)))
    }

    /// Appends the disjoint, ordered sub-intervals of `[t0, t1]` along `origin + t dir` (the
    /// grid's coordinates) that cross a cell some particle may reach: outside them the field is
    /// 0. A 3D DDA over each level's cells (Amanatides and Woo), the levels' intervals merged.
    pub fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        let from = out.len();
        for level in &self.levels {
            level.occupied(origin, dir, t0, t1, out);
        }
        if self.levels.len() > 1 {
            let merged = &mut out[from..];
            merged.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut kept = from;
            for i in from..out.len() {
                let (a, b) = out[i];
                if kept > from && a <= out[kept - 1].1 {
                    out[kept - 1].1 = out[kept - 1].1.max(b);
                } else {
                    out[kept] = (a, b);
                    kept += 1;
                }
            }
            out.truncate(kept);
        }
    }
}

impl Level {
    /// Sorts `members` into cells as wide as their largest radius; appends them, cell by cell,
    /// to `order`, whose first `base` entries are the levels before.
    fn build(
        centers: &[DVec3],
        radii: &[f64],
        members: &[u32],
        base: u32,
        order: &mut Vec<u32>,
    ) -> Level {
        let r_max = members
            .par_iter()
            .map(|&i| radii[i as usize])
            .reduce(|| 0.0, f64::max);
        let (lo, hi) = members
            .par_iter()
            .map(|&i| (centers[i as usize], centers[i as usize]))
            .reduce(
                || (DVec3::INFINITY, DVec3::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let (corner, cell, dims) = grid_over(lo, hi, r_max, members.len());
        let inv = 1.0 / cell;
        let cell_of = |c: DVec3| -> usize {
            let g = ((c - corner) * inv).floor();
            cell_index(
                dims,
                [0, 1, 2].map(|a| (g[a].max(0.0) as usize).min(dims[a] - 1)),
            )
        };
        let mut keyed: Vec<(u32, u32)> = members
            .par_iter()
            .map(|&i| (cell_of(centers[i as usize]) as u32, i))
            .collect();
        // Stable: particles of a cell keep their input (Hilbert) order.
        keyed.par_sort_by_key(|&(c, _)| c);
        let cells = dims[0] * dims[1] * dims[2];
        let mut start = vec![0u32; cells + 1];
        start[0] = base;
        for &(c, _) in &keyed {
            start[c as usize + 1] += 1;
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        let reached: Vec<u64> = (0..cells.div_ceil(64))
            .into_par_iter()
            .map(|word| {
                let mut bits = 0;
                for c in word * 64..(word * 64 + 64).min(cells) {
                    let ijk = cell_coords(dims, c);
                    let mut any = false;
                    for_rows_around(dims, ijk, ijk, |a, b| any |= start[b + 1] > start[a]);
                    bits |= u64::from(any) << (c % 64);
                }
                bits
            })
            .collect();
        order.extend(keyed.into_iter().map(|(_, i)| i));
        Level {
            corner,
            cell,
            inv_cell: inv,
            dims,
            start,
            reached,
        }
    }

    /// Whether any particle may reach into cell `c`.
    #[inline]
    fn reached(&self, c: usize) -> bool {
        (self.reached[c / 64] >> (c % 64)) & 1 == 1
    }

    /// The cell holding point `l` (its index and coordinates), if it is in the grid.
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

    /// [`CellGrid::occupied`] on this level alone.
    fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        let from = out.len();
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
        // Cell index steps along each axis, and the steps left on it before the grid's face.
        let stride = [1, self.dims[0] as i64, (self.dims[0] * self.dims[1]) as i64];
        let mut step = [0i64; 3];
        let mut left = [i64::MAX; 3];
        for ax in 0..3 {
            // Truncation, not floor: they differ only below 0, which the clamp maps to 0.
            cell[ax] = (p[ax] as i64).clamp(0, self.dims[ax] as i64 - 1);
            if d[ax] > 0.0 {
                step[ax] = stride[ax];
                left[ax] = self.dims[ax] as i64 - 1 - cell[ax];
                delta[ax] = inv[ax];
                next[ax] = enter + ((cell[ax] + 1) as f64 - p[ax]) * inv[ax];
            } else if d[ax] < 0.0 {
                step[ax] = -stride[ax];
                left[ax] = cell[ax];
                delta[ax] = -inv[ax];
                next[ax] = enter + (cell[ax] as f64 - p[ax]) * inv[ax];
            }
        }
        let mut t = enter;
        let mut c = cell_index(self.dims, cell.map(|v| v as usize)) as i64;
        // The walk's state in registers (arrays indexed by the axis went through memory, a
        // store and a dependent load each step), the axis chosen by selects rather than
        // branches: which one it is changes unpredictably along a ray.
        let [mut nx, mut ny, mut nz] = next;
        let [mut lx, mut ly, mut lz] = left;
        loop {
            // The axis whose boundary comes first, the lowest on ties.
            let y_first = ny < nx;
            let first_of_two = if y_first { ny } else { nx };
            let z_first = nz < first_of_two;
            let boundary = if z_first { nz } else { first_of_two };
            let leave = if boundary < exit { boundary } else { exit };
            if self.reached(c as usize) && leave > t {
                // Merged only with this level's own intervals.
                match out[from..].last_mut() {
                    Some(last) if last.1 >= t => last.1 = leave,
                    _ => out.push((t, leave)),
                }
            }
            if leave >= exit {
                return;
            }
            t = leave;
            let (on_x, on_y) = (!y_first && !z_first, y_first && !z_first);
            if on_x {
                nx += delta[0];
            }
            if on_y {
                ny += delta[1];
            }
            if z_first {
                nz += delta[2];
            }
            lx -= i64::from(on_x);
            ly -= i64::from(on_y);
            lz -= i64::from(z_first);
            if (lx | ly | lz) < 0 {
                return;
            }
            c += if z_first {
                step[2]
            } else if y_first {
                step[1]
            } else {
                step[0]
            };
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
/// its 27 neighbours in nine rows). Plain loops: an iterator chain of inclusive ranges showed
/// in a frame's profile (docs/notes/2026-12-03-cpu-backend.md).
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

#[cfg(test)]
mod tests;
