//! The spatiotemporal void-and-cluster generator (Ulichney 1993, with the separable energy of
//! Wolfe et al. 2022).
//!
//! The mask is a W x H x D volume of pixels p = (x, y, z), z the frame. A set of "on" pixels S
//! defines the energy of every pixel
//!
//! ```text
//! E(p) = Σ_{q ∈ S} g(p, q)
//! g(p, q) = exp(-|p_xy - q_xy|² / 2σ²)   if p_z = q_z          (spatial, within the slice)
//!         = exp(-|p_z - q_z|² / 2σ²)      if p_xy = q_xy, p_z ≠ q_z  (temporal, per pixel)
//!         = 0                             otherwise
//! ```
//!
//! with toroidal distances in all three axes. g is truncated where it falls below
//! [`CUTOFF`] (a radius of 8 pixels / frames at σ = 1.9) and quantised to integers (2^24 per
//! unit, or less if a large σ needs it), so the incremental updates are exact: adding and then
//! removing a point restores every energy bit for bit, and the result does not depend on the
//! order of floating-point sums.
//!
//! The phases are Ulichney's, with one addition, *column balance* (below):
//!
//! 0. the initial binary pattern, ~10 % of all pixels placed by a seeded hash, relaxed by
//!    moving the tightest cluster (the set pixel of highest energy) to the largest void (the
//!    unset pixel of lowest energy) until the void found is the cluster just removed;
//! 1. ranks `count-1 .. 0`: remove the tightest cluster from a copy of the initial pattern;
//! 2. ranks `count .. N-1`: add the largest void to the initial pattern.
//!
//! Ulichney's phase 3 (past half the pixels, add the tightest cluster of the *unset* pixels,
//! with their own energy) is phase 2 continued: with a translation-invariant kernel the energy
//! of the unset pixels is E₀(p) = K − E(p), K the kernel's total weight, so the unset pixel of
//! highest E₀ is the unset pixel of lowest E, and the integer energies make the two choices
//! identical, ties included (the lowest index wins every tie).
//!
//! **Column balance.** With the energy alone, each pixel's D values are blue *in time* (few
//! low temporal frequencies) but not evenly spread *in value*: at 128 x 128 x 64 the largest
//! gap between a pixel's sorted values averaged 4.0/D, barely better than white noise's 4.75/D.
//! So the ranks are cut into D bands of W·H consecutive ranks, and every band gives each pixel
//! column (x, y) exactly one point: in the band of ranks [b·W·H, (b+1)·W·H) phase 2 only
//! considers voids in columns holding b points, phase 1 only clusters in columns holding b + 1,
//! and the initial pattern holds `full` points in every column plus one more in `extra` of them
//! (its relaxation moves points only from those columns to the others). Each pixel's values
//! then fall one per 1/D stratum (up to the per-slice renormalisation below): the mean largest
//! gap drops to 1.8/D, the energy minimisation is otherwise unchanged, and the spatial and
//! temporal spectra stay far below white noise's (the tests measure and log all three).
//!
//! The arg-max / arg-min searches use two 16-ary tournament trees over the energy array, updated
//! only along the paths above the pixels a point touches, so each step costs a few thousand
//! operations instead of a scan of all W·H·D pixels (the trees are rebuilt, in parallel, when a
//! band changes which columns are eligible); rayon builds the trees, the initial pattern and
//! the final per-slice values.
//!
//! Ranks become values slice by slice (see [`mask_from_ranks`]): each slice's pixels, sorted by
//! global rank, get `value = floor((rank_in_slice + 0.5) / (W·H) · 65536)`, so every slice's
//! histogram is exactly uniform, while the order within the slice (its blue-noise thresholds)
//! and, up to that per-slice renormalisation, each pixel's spread over time are those of the
//! 3D ranking.

use rayon::prelude::*;

use super::mask::{BlueNoiseMask, MAX_DIM};
use super::white::lowbias32;

/// The Gaussian's standard deviation used by the shipped mask and by Wolfe et al.
pub const DEFAULT_SIGMA: f64 = 1.9;
/// The fraction of all pixels in the initial binary pattern.
pub const INITIAL_FRACTION: f64 = 0.1;
/// Kernel weights below this are dropped.
pub const CUTOFF: f64 = 1e-4;

/// Generates a W x H x D spatiotemporal blue-noise mask; deterministic for a seed.
///
/// # Panics
///
/// If a dimension is outside 1..=4096, W·H·D ≥ 2^32, or `sigma` is not a positive finite
/// number.
pub fn generate(width: u32, height: u32, depth: u32, sigma: f64, seed: u64) -> BlueNoiseMask {
    generate_with_progress(width, height, depth, sigma, seed, |_, _| {})
}

/// [`generate`], calling `progress(done, total)` as ranks are assigned (`total` = W·H·D; about
/// a thousand calls, the last with `done == total`). An indicatif bar fits:
/// `let bar = crate::progress::bar(n, "stbn"); generate_with_progress(.., |d, _| bar.set_position(d as u64))`.
pub fn generate_with_progress(
    width: u32,
    height: u32,
    depth: u32,
    sigma: f64,
    seed: u64,
    progress: impl FnMut(usize, usize),
) -> BlueNoiseMask {
    let ranks = ranks(width, height, depth, sigma, seed, progress);
    mask_from_ranks(width, height, depth, &ranks)
}

/// The void-and-cluster ranks: a permutation of 0..W·H·D, slice-major then row-major.
pub fn ranks(
    width: u32,
    height: u32,
    depth: u32,
    sigma: f64,
    seed: u64,
    progress: impl FnMut(usize, usize),
) -> Vec<u32> {
    ranks_with(width, height, depth, sigma, seed, BALANCED, progress)
}

/// Whether ranks are column-balanced (see the module docs).
const BALANCED: bool = true;

/// [`ranks`], with or without column balance (without: plain Wolfe et al.).
fn ranks_with(
    width: u32,
    height: u32,
    depth: u32,
    sigma: f64,
    seed: u64,
    balanced: bool,
    mut progress: impl FnMut(usize, usize),
) -> Vec<u32> {
    let n = checked_size(width, height, depth, sigma);
    let (w, h, d) = (width as usize, height as usize, depth as usize);
    let wh = w * h;
    let mut state = State::new(w, h, d, sigma, balanced);
    let report_every = (n / 1000).max(1);
    progress(0, n);

    // Phase 0: the initial pattern, relaxed.
    let mut count = ((n as f64 * INITIAL_FRACTION).round() as usize).clamp(1, n);
    if balanced && count < n {
        // Relaxation moves points only out of the `extra` fuller columns: keep enough of them.
        count = count / wh * wh + (count % wh).max(wh / 10);
    }
    for &i in &initial_pattern(n, wh, d, count, seed, balanced) {
        state.splat(i as usize, true);
    }
    if balanced {
        // Move points only from the fuller columns to the emptier ones.
        let cap = count.div_ceil(wh) as u32;
        state.cluster_above = cap - 1;
        state.void_max = cap - 1;
    }
    let (mut voids, mut clusters) = relax(&mut state, n);
    let initial_energy = state.energy.clone();
    let initial_set = state.set.clone();
    let initial_counts = state.column_count.clone();

    // Phase 1: ranks count-1 .. 0, removing the tightest cluster.
    let mut ranks = vec![u32::MAX; n];
    for (done, rank) in (0..count).rev().enumerate() {
        let cluster = state.place(&mut clusters, rank, false);
        ranks[cluster] = rank as u32;
        if (done + 1).is_multiple_of(report_every) {
            progress(done + 1, n);
        }
    }
    drop(clusters);

    // Phases 2 and 3: ranks count .. n-1, filling the largest void of the initial pattern.
    state.energy = initial_energy;
    state.set = initial_set;
    state.column_count = initial_counts;
    for rank in count..n {
        let void = state.place(&mut voids, rank, true);
        ranks[void] = rank as u32;
        if (rank + 1).is_multiple_of(report_every) {
            progress(rank + 1, n);
        }
    }
    if !n.is_multiple_of(report_every) {
        progress(n, n);
    }
    debug_assert!(ranks.iter().all(|&r| r != u32::MAX));
    ranks
}

/// The pixels of a W x H x D mask, after checking its dimensions and `sigma`.
///
/// # Panics
///
/// As [`generate`].
fn checked_size(width: u32, height: u32, depth: u32, sigma: f64) -> usize {
    for (name, dim) in [("width", width), ("height", height), ("depth", depth)] {
        assert!(
            (1..=MAX_DIM).contains(&dim),
            "mask {name} {dim} is outside 1..={MAX_DIM}"
        );
    }
    assert!(
        sigma.is_finite() && sigma > 0.0,
        "sigma must be a positive finite number, got {sigma}"
    );
    let n64 = u64::from(width) * u64::from(height) * u64::from(depth);
    assert!(
        n64 < 1 << 32,
        "a mask of {n64} pixels is too large (the limit is 2^32 - 1)"
    );
    n64 as usize
}

/// The `count` pixels of the initial pattern (of `n`, in slices of `wh` pixels, `d` deep),
/// chosen by a seeded hash.
fn initial_pattern(
    n: usize,
    wh: usize,
    d: usize,
    count: usize,
    seed: u64,
    balanced: bool,
) -> Vec<u32> {
    let seed_hash = lowbias32(lowbias32(seed as u32) ^ (seed >> 32) as u32);
    if balanced {
        // `full` whole bands (one point per pixel column each) plus one more point in each of
        // `extra` columns: every column holds `full` or `full + 1` points.
        let (full, extra) = (count / wh, count % wh);
        let column_seed = lowbias32(seed_hash);
        let mut columns: Vec<u32> = (0..wh as u32).collect();
        if extra > 0 && extra < wh {
            columns.select_nth_unstable_by_key(extra, |&c| (lowbias32(column_seed ^ c), c));
        }
        let mut points_in = vec![full; wh];
        for &c in &columns[..extra] {
            points_in[c as usize] += 1;
        }
        (0..wh)
            .into_par_iter()
            .flat_map_iter(|c| {
                let mut frames: Vec<u32> = (0..d).map(|z| (z * wh + c) as u32).collect();
                frames.sort_unstable_by_key(|&i| (lowbias32(seed_hash ^ i), i));
                frames.truncate(points_in[c]);
                frames
            })
            .collect()
    } else {
        // The `count` pixels of smallest seeded hash.
        let mut order: Vec<u32> = (0..n as u32).collect();
        if count < n {
            order.select_nth_unstable_by_key(count, |&i| (lowbias32(seed_hash ^ i), i));
        }
        order.truncate(count);
        order
    }
}

/// Relaxes the initial pattern of `state` (of `n` pixels): the tightest cluster moves to the
/// largest void until they are the same pixel. Returns the voids and clusters trees, up to date.
fn relax(state: &mut State, n: usize) -> (MinTree, MinTree) {
    let mut voids = MinTree::build(n, |i| state.void_key(i));
    let mut clusters = MinTree::build(n, |i| state.cluster_key(i));
    // A swap never raises the pattern's total energy (it lowers it unless energies tie), so
    // this settles; the cap only guards against a cycle among ties.
    let mut removed = Vec::new();
    for _ in 0..n {
        let cluster = MinTree::index(clusters.best());
        state.splat(cluster, false);
        voids.update(&state.dirty, |i| state.void_key(i));
        let void = MinTree::index(voids.best());
        if void == cluster {
            // Stable. Putting the point back restores every energy exactly, so the cluster
            // tree, not yet told about the removal, is still right.
            state.splat(cluster, true);
            voids.update(&state.dirty, |i| state.void_key(i));
            break;
        }
        removed.clear();
        removed.extend_from_slice(&state.dirty);
        state.splat(void, true);
        voids.update(&state.dirty, |i| state.void_key(i));
        clusters.update(&removed, |i| state.cluster_key(i));
        clusters.update(&state.dirty, |i| state.cluster_key(i));
    }
    (voids, clusters)
}

/// Turns global ranks (a permutation of 0..W·H·D) into mask values: within each slice, the
/// pixel of k-th smallest rank gets `floor((k + 0.5) / (W·H) · 65536)`. Each slice is then
/// exactly uniform (with W·H a multiple of B, each of B equal bins holds W·H/B values) and
/// every value is in [0, 65535].
pub fn mask_from_ranks(width: u32, height: u32, depth: u32, ranks: &[u32]) -> BlueNoiseMask {
    let wh = width as usize * height as usize;
    assert_eq!(ranks.len(), wh * depth as usize, "one rank per pixel");
    let mut values = vec![0u16; ranks.len()];
    values
        .par_chunks_mut(wh)
        .zip(ranks.par_chunks(wh))
        .for_each(|(values, ranks)| {
            let mut order: Vec<u32> = (0..wh as u32).collect();
            order.sort_unstable_by_key(|&i| ranks[i as usize]);
            for (k, &i) in order.iter().enumerate() {
                values[i as usize] = ((2 * k as u64 + 1) * 65536 / (2 * wh as u64)) as u16;
            }
        });
    BlueNoiseMask {
        width,
        height,
        depth,
        values,
    }
}

/// The truncated, quantised kernel as wrapped offsets.
#[derive(Clone, Debug)]
struct Kernel {
    /// (x offset in 0..W, y offset in 0..H, weight), ordered by signed (dy, dx) so that the
    /// pixels a point touches come row by row, left to right (up to the wrap).
    spatial: Vec<(usize, usize, u32)>,
    /// (z offset in 1..D, weight), ordered by signed dz.
    temporal: Vec<(usize, u32)>,
}

impl Kernel {
    fn new(w: usize, h: usize, d: usize, sigma: f64) -> Kernel {
        let gauss = |dist2: f64| (-dist2 / (2.0 * sigma * sigma)).exp();
        // Signed toroidal offset: o in 0..len as the nearest of o and o - len.
        let signed = |o: usize, len: usize| {
            if 2 * o <= len {
                o as i64
            } else {
                o as i64 - len as i64
            }
        };
        let mut spatial = Vec::new();
        for oy in 0..h {
            for ox in 0..w {
                let (dx, dy) = (signed(ox, w), signed(oy, h));
                let g = gauss((dx * dx + dy * dy) as f64);
                if g >= CUTOFF {
                    spatial.push((dy, dx, ox, oy, g));
                }
            }
        }
        spatial.sort_by_key(|&(dy, dx, ..)| (dy, dx));
        let mut temporal = Vec::new();
        for oz in 1..d {
            let dz = signed(oz, d);
            let g = gauss((dz * dz) as f64);
            if g >= CUTOFF {
                temporal.push((dz, oz, g));
            }
        }
        temporal.sort_by_key(|&(dz, ..)| dz);
        // The largest scale (at most 2^24 per unit) at which no energy can overflow a u32.
        let total: f64 =
            spatial.iter().map(|s| s.4).sum::<f64>() + temporal.iter().map(|t| t.2).sum::<f64>();
        let mut scale = f64::from(1u32 << 24);
        while total * scale + (spatial.len() + temporal.len()) as f64 > f64::from(u32::MAX) {
            scale /= 2.0;
        }
        let quantise = |g: f64| (g * scale).round() as u32;
        Kernel {
            spatial: spatial
                .into_iter()
                .map(|(_, _, ox, oy, g)| (ox, oy, quantise(g)))
                .filter(|s| s.2 > 0)
                .collect(),
            temporal: temporal
                .into_iter()
                .map(|(_, oz, g)| (oz, quantise(g)))
                .filter(|t| t.1 > 0)
                .collect(),
        }
    }
}

/// The pattern and its energy field.
struct State {
    w: usize,
    h: usize,
    d: usize,
    kernel: Kernel,
    energy: Vec<u32>,
    set: Vec<bool>,
    /// Set points per pixel column (x, y), over all slices.
    column_count: Vec<u32>,
    /// Column-balanced: the trees' keys depend on `column_count`, so a change to a column
    /// dirties all of it.
    balanced: bool,
    /// W·H - 1 when W·H is a power of two (then `column` needs no division), else 0.
    column_mask: usize,
    /// Only unset pixels in columns holding at most this many points are voids.
    void_max: u32,
    /// Only set pixels in columns holding more than this many points are clusters.
    cluster_above: u32,
    /// The pixels whose key the last [`splat`](Self::splat) may have changed.
    dirty: Vec<u32>,
}

impl State {
    /// Gives `rank` to the best pixel of `tree` and updates it: with `fill`, the largest void
    /// of the voids tree gets a point; without, the tightest cluster of the clusters tree
    /// loses one. With column balance, a new band of W·H ranks first rebuilds the tree, since
    /// which columns may give (more than `band` points left) or take (at most `band` points)
    /// changes with the band.
    fn place(&mut self, tree: &mut MinTree, rank: usize, fill: bool) -> usize {
        let key = |s: &State, i: usize| {
            if fill {
                s.void_key(i)
            } else {
                s.cluster_key(i)
            }
        };
        let band = (rank / (self.w * self.h)) as u32;
        let current = if fill {
            self.void_max
        } else {
            self.cluster_above
        };
        if self.balanced && band != current {
            if fill {
                self.void_max = band;
            } else {
                self.cluster_above = band;
            }
            *tree = MinTree::build(self.set.len(), |i| key(self, i));
        }
        let best = MinTree::index(tree.best());
        self.splat(best, fill);
        tree.update(&self.dirty, |i| key(self, i));
        best
    }

    fn new(w: usize, h: usize, d: usize, sigma: f64, balanced: bool) -> State {
        let kernel = Kernel::new(w, h, d, sigma);
        let n = w * h * d;
        State {
            w,
            h,
            d,
            dirty: Vec::with_capacity(kernel.spatial.len() + kernel.temporal.len() + d),
            kernel,
            energy: vec![0; n],
            set: vec![false; n],
            column_count: vec![0; w * h],
            column_mask: if (w * h).is_power_of_two() {
                w * h - 1
            } else {
                0
            },
            balanced,
            void_max: u32::MAX,
            cluster_above: 0,
        }
    }

    /// Adds (`on`) or removes the point at pixel index `i`, updating the energy of its slice's
    /// footprint and of its pixel column across slices; records in `dirty` the pixels whose
    /// tree keys may have changed (with column balance, the whole column: its count changed).
    fn splat(&mut self, i: usize, on: bool) {
        debug_assert_ne!(self.set[i], on);
        self.set[i] = on;
        let (w, h, d) = (self.w, self.h, self.d);
        let wh = w * h;
        let (z, r) = (i / wh, i % wh);
        let (y, x) = (r / w, r % w);
        let slice = z * wh;
        let (energy, dirty) = (&mut self.energy, &mut self.dirty);
        dirty.clear();
        for &(ox, oy, weight) in &self.kernel.spatial {
            let nx = if x + ox >= w { x + ox - w } else { x + ox };
            let ny = if y + oy >= h { y + oy - h } else { y + oy };
            let j = slice + ny * w + nx;
            if on {
                energy[j] += weight;
            } else {
                energy[j] -= weight;
            }
            dirty.push(j as u32);
        }
        for &(oz, weight) in &self.kernel.temporal {
            let nz = if z + oz >= d { z + oz - d } else { z + oz };
            let j = nz * wh + r;
            if on {
                energy[j] += weight;
            } else {
                energy[j] -= weight;
            }
            if !self.balanced {
                dirty.push(j as u32);
            }
        }
        if on {
            self.column_count[r] += 1;
        } else {
            self.column_count[r] -= 1;
        }
        if self.balanced {
            dirty.extend((0..d).map(|z| (z * wh + r) as u32));
        }
    }

    /// The pixel column (index y·W + x) of pixel index `i`.
    #[inline]
    fn column(&self, i: usize) -> usize {
        if self.column_mask != 0 {
            i & self.column_mask
        } else {
            i % (self.w * self.h)
        }
    }

    /// The void tree's key: unset pixels by (energy, index); set pixels never win.
    #[inline]
    fn void_key(&self, i: usize) -> u64 {
        if self.set[i] || self.column_count[self.column(i)] > self.void_max {
            u64::MAX
        } else {
            (u64::from(self.energy[i]) << 32) | i as u64
        }
    }

    /// The cluster tree's key: set pixels by (highest energy, lowest index); unset never win.
    #[inline]
    fn cluster_key(&self, i: usize) -> u64 {
        if self.set[i] && self.column_count[self.column(i)] > self.cluster_above {
            (u64::from(!self.energy[i]) << 32) | i as u64
        } else {
            u64::MAX
        }
    }
}

const FANOUT: usize = 16;

/// A 16-ary tournament tree of minima over `n` leaf keys that live elsewhere (computed by a
/// closure). `levels[0]` holds the minima of blocks of 16 leaves, the last level the overall
/// minimum.
#[derive(Clone, Debug)]
struct MinTree {
    n: usize,
    levels: Vec<Vec<u64>>,
    scratch: [Vec<u32>; 2],
}

impl MinTree {
    fn build(n: usize, leaf: impl Fn(usize) -> u64 + Sync) -> MinTree {
        let first: Vec<u64> = (0..n.div_ceil(FANOUT))
            .into_par_iter()
            .map(|b| {
                (b * FANOUT..(b * FANOUT + FANOUT).min(n))
                    .map(&leaf)
                    .min()
                    .expect("a non-empty block")
            })
            .collect();
        let mut levels = vec![first];
        while levels.last().expect("one level").len() > 1 {
            let below = levels.last().expect("one level");
            let next = below
                .chunks(FANOUT)
                .map(|c| *c.iter().min().expect("a non-empty block"))
                .collect();
            levels.push(next);
        }
        MinTree {
            n,
            levels,
            scratch: [Vec::new(), Vec::new()],
        }
    }

    /// The smallest key.
    #[inline]
    fn best(&self) -> u64 {
        self.levels.last().expect("one level")[0]
    }

    /// The pixel index packed in a key's low half.
    #[inline]
    fn index(key: u64) -> usize {
        debug_assert_ne!(key, u64::MAX, "no eligible pixel left");
        (key & 0xffff_ffff) as usize
    }

    /// Recomputes the paths above the leaves in `dirty` (given mostly in ascending runs;
    /// consecutive duplicates are merged, others only cost time).
    fn update(&mut self, dirty: &[u32], leaf: impl Fn(usize) -> u64) {
        let [parents, next] = &mut self.scratch;
        parents.clear();
        for &i in dirty {
            let p = i / FANOUT as u32;
            if parents.last() != Some(&p) {
                parents.push(p);
            }
        }
        let n = self.n;
        for &p in parents.iter() {
            let start = p as usize * FANOUT;
            let mut best = u64::MAX;
            for i in start..(start + FANOUT).min(n) {
                best = best.min(leaf(i));
            }
            self.levels[0][p as usize] = best;
        }
        for level in 1..self.levels.len() {
            next.clear();
            for &p in parents.iter() {
                let q = p / FANOUT as u32;
                if next.last() != Some(&q) {
                    next.push(q);
                }
            }
            let (below, above) = self.levels.split_at_mut(level);
            let (below, above) = (&below[level - 1], &mut above[0]);
            for &q in next.iter() {
                let start = q as usize * FANOUT;
                let end = (start + FANOUT).min(below.len());
                above[q as usize] = *below[start..end].iter().min().expect("a non-empty block");
            }
            std::mem::swap(parents, next);
        }
    }
}

#[cfg(test)]
mod tests;
