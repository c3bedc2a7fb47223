//! The field in f32 on the CPU: a step's particles (the reference's, already evaluated:
//! radius, weight and theta) packed as f32 structure-of-arrays in local coordinates, sorted
//! into grids of cells (one per level of radii, each at least as wide as its largest radius),
//! and evaluated eight at a time by [`f32_kernel`](super::f32_kernel). What it costs in error
//! is bounded by one model of every source (`backend::precision`: positions, kernel, terms,
//! and sums of at most eight terms a lane in f32, added in f64); the CPU backend uses it where
//! that bound meets the tolerance asked for, and the f64 reference everywhere else.
//!
//! The particles lie in the order of a [`CellGrid`] (why cells: `accel::cells`); the cells
//! hand the kernel about 6.4 times the particles within reach, and eight lanes at a time pay
//! for it several times over (`benches/cpu_roofline`). A packet of neighbouring rays' samples
//! ([`F32Field::eval_sums_packet`]) shares one lookup and one narrowing of its candidates to
//! those within reach of all of them, and evaluates them a sample per lane: samples along rays
//! lie much closer together than a radius.

use glam::DVec3;
use rayon::prelude::*;

use super::f32_kernel::{GroupScratch, LANES, Packed, simd_in_use};
use super::{Particles, Theta};
use crate::accel::{CellGrid, CellRuns};

/// A step's field for the f32 kernel.
#[derive(Clone, Debug)]
pub struct F32Field {
    /// Local coordinates are data coordinates minus this (the reference's origin).
    origin: DVec3,
    cells: CellGrid,
    /// The particles, cell by cell (in Hilbert order within a cell).
    particles: Packed,
}

impl F32Field {
    /// Packs `p` (with its field applied) into cells. Particles of radius 0 reach nothing and
    /// are left out, as in the reference.
    pub fn new(p: &Particles) -> F32Field {
        let (cells, order) = CellGrid::build(&p.centers, &p.radii);
        let f32s = |f: &(dyn Fn(usize) -> f32 + Sync)| -> Vec<f32> {
            order.par_iter().map(|&i| f(i as usize)).collect()
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
            // one_radius and same_w: set by `pad`.
            ..Packed::default()
        };
        particles.pad();
        F32Field {
            origin: p.origin,
            cells,
            particles,
        }
    }

    /// Bytes of the packed particles.
    pub fn particle_bytes(&self) -> usize {
        self.particles.bytes()
    }

    /// Bytes of the grid (the cells' starts and whether each is reached).
    pub fn grid_bytes(&self) -> usize {
        self.cells.bytes()
    }

    /// Phi and the Theta numerator at `x` (data coordinates). `scratch` keeps the last
    /// cell's runs: a query in the same cell looks nothing up.
    pub fn eval_sums(&self, x: DVec3, scratch: &mut F32Ray) -> (f64, [f64; 3]) {
        let l = x - self.origin;
        let runs = self.cells.runs_at(l, scratch);
        if runs.is_empty() {
            return (0.0, [0.0; 3]);
        }
        self.particles
            .sums(runs, [l.x as f32, l.y as f32, l.z as f32])
    }

    /// [`F32Field::eval_sums`] at each of `points` (point queries, in Hilbert order), into
    /// `out` (as long). Up to [`GROUP`] consecutive points within two cells a side are
    /// evaluated together ([`Packed::group_sums`]: their candidates found and narrowed once),
    /// each to the bits it has alone (but for a particle on the very edge of a point's cells,
    /// which f32 may count from a group's wider block: what f32 cannot decide, as in a packet).
    /// A group takes consecutive points until one would widen its block of cells past two a
    /// side ([`CellGrid::runs_around_prefix`]); a group of fewer than two points in reach of
    /// some particle is evaluated one point at a time. Without the AVX2 build every point is
    /// evaluated alone. Returns how many points were evaluated in groups.
    pub fn eval_sums_many(
        &self,
        points: &[DVec3],
        scratch: &mut F32Batch,
        out: &mut [(f64, [f64; 3])],
    ) -> usize {
        assert_eq!(points.len(), out.len(), "a result per point");
        let mut together = 0;
        let grouped = simd_in_use();
        let mut i = 0;
        let mut local = [DVec3::ZERO; GROUP];
        while i < points.len() {
            let g = GROUP.min(points.len() - i);
            // Points evaluated alone from i: one, unless a lookup says how many.
            let mut alone = 1;
            if grouped && g >= 2 {
                for (l, &x) in local.iter_mut().zip(&points[i..i + g]) {
                    *l = x - self.origin;
                }
                let (count, reached, runs) = self
                    .cells
                    .runs_around_prefix(&local[..g], &mut scratch.runs);
                if let Some(runs) = runs {
                    let mut qs = [[0f32; 3]; GROUP];
                    let mut which = [0usize; GROUP];
                    let mut m = 0;
                    for (j, l) in local.iter().take(count).enumerate() {
                        if (reached >> j) & 1 == 1 {
                            qs[m] = [l.x as f32, l.y as f32, l.z as f32];
                            which[m] = j;
                            m += 1;
                        } else {
                            out[i + j] = (0.0, [0.0; 3]);
                        }
                    }
                    // Every point reached (the common case): straight into `out`.
                    let mut sums = [(0.0, [0.0; 3]); GROUP];
                    let every = m == count;
                    let to = if every {
                        &mut out[i..i + count]
                    } else {
                        &mut sums[..m]
                    };
                    self.particles
                        .group_sums(runs, &qs[..m], &mut scratch.group, to);
                    if !every {
                        for (s, &j) in sums.iter().zip(&which).take(m) {
                            out[i + j] = *s;
                        }
                    }
                    together += m;
                    i += count;
                    continue;
                }
                alone = count;
            }
            for (o, &x) in out[i..i + alone].iter_mut().zip(&points[i..i + alone]) {
                *o = self.eval_sums(x, &mut scratch.ray);
            }
            i += alone;
        }
        together
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
        let local = points.map(|x| x.map(|x| x - self.origin));
        let (reached, runs) = self.cells.runs_around_packet(&local, &mut packet.runs);
        let mut q = [[0f32; 3]; LANES];
        let mut live = [0u32; LANES];
        for (i, l) in local.iter().enumerate() {
            let Some(l) = l else { continue };
            if (reached >> i) & 1 == 1 {
                q[i] = [l.x as f32, l.y as f32, l.z as f32];
                live[i] = u32::MAX;
            } else {
                out[i] = (0.0, [0.0; 3]);
            }
        }
        let Some(runs) = runs else {
            for (i, x) in points.iter().enumerate() {
                if let (Some(x), true) = (x, live[i] != 0) {
                    out[i] = self.eval_sums(*x, &mut rays[i]);
                }
            }
            return 0;
        };
        let sums = self
            .particles
            .packet_sums(runs, &q, live, &mut packet.candidates);
        for (i, s) in sums.into_iter().enumerate() {
            if live[i] != 0 {
                out[i] = s;
            }
        }
        reached.count_ones() as usize
    }

    /// Appends the disjoint, ordered sub-intervals of `[t0, t1]` along `origin + t dir` (data
    /// coordinates) that cross a cell some particle may reach: outside them the field is 0.
    pub fn occupied(&self, origin: DVec3, dir: DVec3, t0: f64, t1: f64, out: &mut Vec<(f64, f64)>) {
        self.cells.occupied(origin - self.origin, dir, t0, t1, out);
    }
}

/// Sampling a packet of rays together: the runs of candidates of the last block of cells its
/// samples fell in, and the candidates gathered for the last packet. Made once per thread.
#[derive(Debug, Default)]
pub struct F32Packet {
    runs: CellRuns,
    candidates: Vec<u32>,
}

/// Point queries evaluated together: at most this many a group. Sixteen, not eight: groups
/// that grow until their block of cells would pass two a side hold 9.2 points on average
/// with sixteen (6.9 with eight), and a group's lookup and narrowing are shared by more.
pub const GROUP: usize = 16;

/// Point queries in groups ([`F32Field::eval_sums_many`]): the runs of a group's block of
/// cells, its narrowed candidates and reached ones, and a lone point's runs. Made once per
/// thread and reused.
#[derive(Debug, Default)]
pub struct F32Batch {
    runs: CellRuns,
    group: GroupScratch,
    ray: F32Ray,
}

/// Sampling along rays (and point queries): the runs of candidates of the last cell visited,
/// kept for the next sample in it. Made once per thread and reused.
pub type F32Ray = CellRuns;
