//! Synthetic data sets, deterministic from a seed: the paper's `uniform` and `random` sets,
//! a `clusters` stress case, and an animated `dambreak-demo` time series.

use std::borrow::Cow;
use std::fmt;
use std::ops::Range;
use std::str::FromStr;

use glam::DVec3;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;

use crate::io;
use crate::values::{Attribute, Step};

/// The generators.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Generator {
    /// Poisson-disk samples in the unit cube (the paper's Fig. 10 "Uniform", 60K by default).
    Uniform,
    /// `uniform` with every sample displaced by the Poisson radius in a random direction.
    Random,
    /// Gaussian blobs whose densities differ by 1000x (a stress case for trees and grids).
    Clusters,
    /// A column of fluid-like particles collapsing under gravity in a tank (a time series).
    #[value(name = "dambreak-demo")]
    DambreakDemo,
}

impl Generator {
    /// Particles it generates unless asked for another count.
    pub fn default_count(self) -> usize {
        match self {
            Generator::Uniform | Generator::Random => 60_000,
            Generator::Clusters => 100_000,
            Generator::DambreakDemo => 20_000,
        }
    }

    /// Time steps it generates unless asked (1 for the static generators).
    pub fn default_steps(self) -> usize {
        match self {
            Generator::DambreakDemo => 48,
            _ => 1,
        }
    }

    /// The attribute a scene colours this data by.
    pub fn main_attribute(self) -> &'static str {
        match self {
            Generator::Uniform | Generator::Random => "distance",
            Generator::Clusters => "blob",
            Generator::DambreakDemo => "velocity",
        }
    }

    /// Generates `steps` steps of about `count` particles (exactly `count` except where noted).
    pub fn generate(self, count: usize, steps: usize, seed: u64) -> Vec<Step> {
        self.series(count, steps, seed).into_steps()
    }

    /// The series [`Generator::generate`] makes, held so that a step can be written a run of
    /// particles at a time ([`io::write_series_from`]): a dam break above
    /// [`DAMBREAK_SIMULATED`] particles keeps only its simulated steps and makes any run of the
    /// riding particles from them on demand, so a step is never whole in memory.
    pub fn series(self, count: usize, steps: usize, seed: u64) -> GeneratedSeries {
        let (steps, riders) = match self {
            Generator::DambreakDemo if count > DAMBREAK_SIMULATED => (
                dambreak(DAMBREAK_SIMULATED, steps.max(1), seed),
                Some(Riders { count, seed }),
            ),
            _ => (self.whole_steps(count, steps, seed), None),
        };
        GeneratedSeries {
            steps,
            riders,
            chunk_len: GENERATED_CHUNK_LEN,
        }
    }

    /// The steps of every generator that makes them whole.
    fn whole_steps(self, count: usize, steps: usize, seed: u64) -> Vec<Step> {
        match self {
            Generator::Uniform | Generator::Random => {
                let (points, radius) = poisson_disk_unit_cube(count, seed);
                let mut rng = Pcg64::seed_from_u64(seed ^ 0x5eed);
                let points: Vec<DVec3> = if self == Generator::Random {
                    points
                        .into_iter()
                        .map(|p| p + random_unit_vector(&mut rng) * radius)
                        .collect()
                } else {
                    points
                };
                let step = static_step(&points, DVec3::splat(0.5));
                vec![step; steps.max(1)]
                    .into_iter()
                    .enumerate()
                    .map(|(i, mut s)| {
                        s.name = format!("{i:04}");
                        s
                    })
                    .collect()
            }
            Generator::Clusters => {
                let step = gaussian_blobs(count, seed);
                (0..steps.max(1))
                    .map(|i| Step {
                        name: format!("{i:04}"),
                        ..step.clone()
                    })
                    .collect()
            }
            Generator::DambreakDemo => dambreak(count, steps.max(1), seed),
        }
    }
}

/// The particles a run of a generated step holds when it is written a run at a time: 4M
/// particles are 160 MB as a step (positions and two attributes in f64) and 64 MB as
/// `.particles` records, small beside the 1.6 GB of a 100M-particle step.
pub const GENERATED_CHUNK_LEN: usize = 4_000_000;

/// A generated series (see [`Generator::series`]): its steps whole, or the simulated steps
/// that the rest of the particles ride with.
pub struct GeneratedSeries {
    steps: Vec<Step>,
    riders: Option<Riders>,
    chunk_len: usize,
}

impl GeneratedSeries {
    /// The same series, handed to writers `chunk_len` particles at a time (at least 1).
    pub fn with_chunk_len(mut self, chunk_len: usize) -> GeneratedSeries {
        self.chunk_len = chunk_len.max(1);
        self
    }

    /// Every step whole.
    pub fn into_steps(self) -> Vec<Step> {
        match self.riders {
            None => self.steps,
            Some(riders) => self
                .steps
                .iter()
                .map(|simulated| riders.ride(simulated, 0..riders.count))
                .collect(),
        }
    }
}

impl io::SeriesSource for GeneratedSeries {
    fn step_count(&self) -> usize {
        self.steps.len()
    }

    fn step_len(&self, step: usize) -> usize {
        match self.riders {
            None => self.steps[step].len(),
            Some(riders) => riders.count,
        }
    }

    fn for_each_chunk(
        &self,
        step: usize,
        write: &mut dyn FnMut(&Step) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        let Some(riders) = self.riders else {
            return write(&self.steps[step]);
        };
        for start in (0..riders.count).step_by(self.chunk_len) {
            let end = (start + self.chunk_len).min(riders.count);
            write(&riders.ride(&self.steps[step], start..end))?;
        }
        Ok(())
    }

    fn whole_step(&self, step: usize) -> Cow<'_, Step> {
        match self.riders {
            None => Cow::Borrowed(&self.steps[step]),
            Some(riders) => Cow::Owned(riders.ride(&self.steps[step], 0..riders.count)),
        }
    }
}

impl fmt::Display for Generator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Generator::Uniform => "uniform",
            Generator::Random => "random",
            Generator::Clusters => "clusters",
            Generator::DambreakDemo => "dambreak-demo",
        })
    }
}

impl FromStr for Generator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        <Generator as clap::ValueEnum>::from_str(s, true).map_err(|_| {
            format!("unknown generator '{s}' (uniform, random, clusters, dambreak-demo)")
        })
    }
}

/// A step of static points with their distance to `centre` as the attribute.
fn static_step(points: &[DVec3], centre: DVec3) -> Step {
    Step {
        name: String::new(),
        positions: points.to_vec(),
        attributes: vec![Attribute {
            name: "distance".into(),
            values: points.iter().map(|p| p.distance(centre)).collect(),
        }],
    }
}

fn random_unit_vector(rng: &mut Pcg64) -> DVec3 {
    loop {
        let v = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        let l = v.length_squared();
        if l > 1e-6 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

fn gaussian(rng: &mut Pcg64) -> f64 {
    // Box–Muller.
    let u1: f64 = rng.random_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Exactly `n` Poisson-disk samples in the unit cube (Bridson, "Fast Poisson disk sampling in
/// arbitrary dimensions", 2007): sampling runs with a radius small enough to give at least `n`
/// points, then a random subset of `n` is kept. Returns the points and the radius.
pub fn poisson_disk_unit_cube(n: usize, seed: u64) -> (Vec<DVec3>, f64) {
    if n == 0 {
        return (Vec::new(), 0.0);
    }
    let mut c = 0.5;
    loop {
        let radius = (c / n as f64).cbrt();
        let mut rng = Pcg64::seed_from_u64(seed);
        let mut points = bridson(radius, &mut rng);
        if points.len() >= n {
            points.shuffle(&mut rng);
            points.truncate(n);
            return (points, radius);
        }
        c *= 0.8;
    }
}

fn bridson(radius: f64, rng: &mut Pcg64) -> Vec<DVec3> {
    let cell = radius / 3f64.sqrt();
    let side = (1.0 / cell).ceil() as usize;
    let mut grid = vec![u32::MAX; side * side * side];
    let index = |p: DVec3| {
        let c = (p / cell)
            .as_uvec3()
            .min(glam::UVec3::splat(side as u32 - 1));
        (c.x as usize, c.y as usize, c.z as usize)
    };
    let mut points: Vec<DVec3> = Vec::new();
    let mut active: Vec<u32> = Vec::new();
    let first = DVec3::new(rng.random(), rng.random(), rng.random());
    let (x, y, z) = index(first);
    grid[(z * side + y) * side + x] = 0;
    points.push(first);
    active.push(0);
    const ATTEMPTS: usize = 30;
    while !active.is_empty() {
        let k = rng.random_range(0..active.len());
        let centre = points[active[k] as usize];
        let mut found = false;
        for _ in 0..ATTEMPTS {
            // Uniform in the spherical shell [r, 2r].
            let dir = random_unit_vector(rng);
            let u: f64 = rng.random();
            let dist = (radius.powi(3) + u * (8.0 * radius.powi(3) - radius.powi(3))).cbrt();
            let p = centre + dir * dist;
            if p.min_element() < 0.0 || p.max_element() >= 1.0 {
                continue;
            }
            let (x, y, z) = index(p);
            let mut ok = true;
            'search: for zz in z.saturating_sub(2)..(z + 3).min(side) {
                for yy in y.saturating_sub(2)..(y + 3).min(side) {
                    for xx in x.saturating_sub(2)..(x + 3).min(side) {
                        let q = grid[(zz * side + yy) * side + xx];
                        if q != u32::MAX && points[q as usize].distance_squared(p) < radius * radius
                        {
                            ok = false;
                            break 'search;
                        }
                    }
                }
            }
            if ok {
                grid[(z * side + y) * side + x] = points.len() as u32;
                active.push(points.len() as u32);
                points.push(p);
                found = true;
                break;
            }
        }
        if !found {
            active.swap_remove(k);
        }
    }
    points
}

/// Eight Gaussian blobs with equal counts and standard deviations from 0.01 to 0.1, so their
/// peak densities differ by 1000x. Attributes: `blob` (0..7) and `sigma_distance` (distance
/// to the blob's centre in standard deviations).
fn gaussian_blobs(n: usize, seed: u64) -> Step {
    const BLOBS: usize = 8;
    let mut rng = Pcg64::seed_from_u64(seed);
    let centres: Vec<DVec3> = (0..BLOBS)
        .map(|_| DVec3::new(rng.random(), rng.random(), rng.random()) * 0.6 + 0.2)
        .collect();
    let sigma = |b: usize| 0.01 * 10f64.powf(b as f64 / (BLOBS - 1) as f64);
    let mut positions = Vec::with_capacity(n);
    let mut blob = Vec::with_capacity(n);
    let mut distance = Vec::with_capacity(n);
    for i in 0..n {
        let b = i % BLOBS;
        let offset = DVec3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng));
        positions.push(centres[b] + offset * sigma(b));
        blob.push(b as f64);
        distance.push(offset.length());
    }
    Step {
        name: String::new(),
        positions,
        attributes: vec![
            Attribute {
                name: "blob".into(),
                values: blob,
            },
            Attribute {
                name: "sigma_distance".into(),
                values: distance,
            },
        ],
    }
}

/// A uniform grid of particle indices for neighbour searches.
struct NeighbourGrid {
    cell: f64,
    dims: [usize; 3],
    starts: Vec<u32>,
    indices: Vec<u32>,
}

impl NeighbourGrid {
    fn new(points: &[DVec3], cell: f64, extent: DVec3) -> NeighbourGrid {
        let dims = [0, 1, 2].map(|a| ((extent[a] / cell).ceil() as usize).max(1));
        let cell_of = |p: DVec3| -> usize {
            let c = [0, 1, 2].map(|a| ((p[a] / cell).max(0.0) as usize).min(dims[a] - 1));
            (c[2] * dims[1] + c[1]) * dims[0] + c[0]
        };
        let cells: Vec<usize> = points.iter().map(|&p| cell_of(p)).collect();
        let mut starts = vec![0u32; dims[0] * dims[1] * dims[2] + 1];
        for &c in &cells {
            starts[c + 1] += 1;
        }
        for i in 1..starts.len() {
            starts[i] += starts[i - 1];
        }
        let mut fill = starts.clone();
        let mut indices = vec![0u32; points.len()];
        for (i, &c) in cells.iter().enumerate() {
            indices[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        NeighbourGrid {
            cell,
            dims,
            starts,
            indices,
        }
    }

    /// Calls `f(j)` for every particle in the 27 cells around `p`, in a fixed order.
    fn for_each_near(&self, p: DVec3, mut f: impl FnMut(usize)) {
        let c = [0, 1, 2].map(|a| ((p[a] / self.cell).max(0.0) as usize).min(self.dims[a] - 1));
        for z in c[2].saturating_sub(1)..(c[2] + 2).min(self.dims[2]) {
            for y in c[1].saturating_sub(1)..(c[1] + 2).min(self.dims[1]) {
                for x in c[0].saturating_sub(1)..(c[0] + 2).min(self.dims[0]) {
                    let cell = (z * self.dims[1] + y) * self.dims[0] + x;
                    for k in self.starts[cell]..self.starts[cell + 1] {
                        f(self.indices[k as usize] as usize);
                    }
                }
            }
        }
    }
}

/// The dam break's tank, and the column of fluid it starts as (in its corner).
const DAMBREAK_TANK: DVec3 = DVec3::new(1.2, 0.8, 0.3);
const DAMBREAK_COLUMN: DVec3 = DVec3::new(0.35, 0.7, 0.3);

/// The particle spacing of a dam break of `n` particles: the column's volume shared out.
fn dambreak_spacing(n: usize) -> f64 {
    (DAMBREAK_COLUMN.x * DAMBREAK_COLUMN.y * DAMBREAK_COLUMN.z / n.max(1) as f64).cbrt()
}

/// The most particles the dam break simulates. Its fixed time step resolves the collapse at
/// up to about this resolution; finer, particles cross several spacings per substep, crowd,
/// and the projection's cost grows faster than the count (1M simulated particles did not
/// finish 20 steps in 25 CPU-minutes). Larger counts ride with the simulated particles (see
/// [`Riders`]).
pub const DAMBREAK_SIMULATED: usize = 100_000;

/// The particles of a dam break that ride with its simulation: `count` a step, their offsets
/// drawn from `seed`.
#[derive(Clone, Copy, Debug)]
struct Riders {
    count: usize,
    seed: u64,
}

impl Riders {
    /// Particles `range` of the `count` that follow the simulated step `simulated`: particle k
    /// rides with simulated particle `k mod n` at a fixed offset within its spacing (the same
    /// in every step, so each keeps its identity and moves smoothly), carrying its velocity;
    /// the neighbour count scales with the density. Positions stay within the tank. Any range
    /// gives the values the whole step has there, bit for bit.
    fn ride(&self, simulated: &Step, range: Range<usize>) -> Step {
        let n = simulated.len();
        let tank = DAMBREAK_TANK;
        let spacing = dambreak_spacing(n);
        let stream = Pcg64::seed_from_u64(self.seed ^ 0x00fe_11e5);
        // Particle k's offset is draws 3k, 3k + 1 and 3k + 2 of one stream (a draw of an f64
        // is one u64, one step of the generator), so a block of particles starting at k jumps
        // the stream 3k steps ahead instead of drawing every earlier particle's offset.
        const BLOCK: usize = 4096;
        let positions: Vec<DVec3> = range
            .clone()
            .into_par_iter()
            .step_by(BLOCK)
            .flat_map_iter(|start| {
                let mut rng = stream.clone();
                rng.advance(3 * start as u128);
                (start..(start + BLOCK).min(range.end)).map(move |k| {
                    let offset =
                        (DVec3::new(rng.random(), rng.random(), rng.random()) - 0.5) * spacing;
                    (simulated.positions[k % n] + offset).clamp(DVec3::ZERO, tank)
                })
            })
            .collect();
        let scale = self.count as f64 / n as f64;
        Step {
            name: simulated.name.clone(),
            positions,
            attributes: simulated
                .attributes
                .iter()
                .map(|a| Attribute {
                    name: a.name.clone(),
                    values: range
                        .clone()
                        .into_par_iter()
                        .map(|k| {
                            let v = a.values[k % n];
                            if a.name == "neighbours" { v * scale } else { v }
                        })
                        .collect(),
                })
                .collect(),
        }
    }
}

/// A dam break: a column of particles in the corner of a 1.2 x 0.8 x 0.3 tank collapses under
/// gravity. Position-based dynamics (positions projected apart to the particle spacing, walls
/// as constraints, velocities from positions, XSPH-style viscosity): not physically exact, but
/// it moves plausibly, splashes, and its density varies. Attributes: `velocity` (magnitude,
/// m/s) and `neighbours` (particles within two spacings, a density estimate).
fn dambreak(n: usize, steps: usize, seed: u64) -> Vec<Step> {
    let spacing = dambreak_spacing(n);
    let mut x = dambreak_column(n, spacing, seed);
    let mut v = vec![DVec3::ZERO; n];
    let substeps = 8;
    let radius = 0.5 * spacing;
    let sim = Dambreak {
        tank: DAMBREAK_TANK,
        spacing,
        h: (1.0 / 30.0) / substeps as f64,
        lo: DVec3::splat(radius),
        hi: DAMBREAK_TANK - radius,
    };
    let mut out = Vec::with_capacity(steps);
    let bar = crate::progress::bar(steps as u64, "simulating");
    for step in 0..steps {
        bar.inc(1);
        if step > 0 {
            for _ in 0..substeps {
                sim.substep(&mut x, &mut v);
            }
        }
        out.push(Step {
            name: format!("{step:04}"),
            positions: x.clone(),
            attributes: vec![
                Attribute {
                    name: "velocity".into(),
                    values: v.iter().map(|v| v.length()).collect(),
                },
                Attribute {
                    name: "neighbours".into(),
                    values: sim.neighbours(&x),
                },
            ],
        });
    }
    bar.finish_and_clear();
    out
}

/// The dam break's column: `n` particles `spacing` apart, jittered, filled bottom-up layer by
/// layer, so the last layer is the partial one.
fn dambreak_column(n: usize, spacing: f64, seed: u64) -> Vec<DVec3> {
    let per_axis = (DAMBREAK_COLUMN / spacing)
        .ceil()
        .as_uvec3()
        .max(glam::UVec3::ONE);
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut x: Vec<DVec3> = Vec::with_capacity(n);
    'fill: for j in 0..u32::MAX {
        for i in 0..per_axis.x {
            for k in 0..per_axis.z {
                let p = (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * spacing;
                let jitter = DVec3::new(rng.random(), rng.random(), rng.random()) - 0.5;
                x.push(p + jitter * 0.1 * spacing);
                if x.len() == n {
                    break 'fill;
                }
            }
        }
    }
    x
}

/// The dam break's dynamics: the tank, the particle spacing, the substep's length and the
/// box the particles' centres keep to.
struct Dambreak {
    tank: DVec3,
    spacing: f64,
    h: f64,
    lo: DVec3,
    hi: DVec3,
}

impl Dambreak {
    /// One substep: gravity, three passes of pushing particles apart, the velocities the
    /// moves imply, then viscosity.
    fn substep(&self, x: &mut Vec<DVec3>, v: &mut Vec<DVec3>) {
        let (h, lo, hi) = (self.h, self.lo, self.hi);
        let gravity = DVec3::new(0.0, -9.81, 0.0);
        let mut p: Vec<DVec3> = x
            .par_iter()
            .zip(&mut *v)
            .map(|(x, v)| {
                *v += gravity * h;
                (*x + *v * h).clamp(lo, hi)
            })
            .collect();
        for _ in 0..3 {
            p = self.separate(&p);
        }
        let n = p.len();
        let new_v: Vec<DVec3> = (0..n).into_par_iter().map(|i| (p[i] - x[i]) / h).collect();
        *v = self.viscous(&p, &new_v);
        *x = p;
    }

    /// Each particle moved half way out of its overlaps with those nearer than the spacing.
    fn separate(&self, p: &[DVec3]) -> Vec<DVec3> {
        let spacing = self.spacing;
        let grid = NeighbourGrid::new(p, spacing, self.tank);
        (0..p.len())
            .into_par_iter()
            .map(|i| {
                let mut correction = DVec3::ZERO;
                grid.for_each_near(p[i], |j| {
                    if j == i {
                        return;
                    }
                    let d = p[i] - p[j];
                    let len = d.length();
                    if len < spacing {
                        // Co-located particles separate along a fixed, index-derived axis.
                        let dir = if len > 1e-12 * spacing {
                            d / len
                        } else {
                            let a = (i.wrapping_mul(2654435761) ^ j) as f64;
                            DVec3::new(a.sin(), a.cos(), (a * 0.5).sin()).normalize()
                                * if i < j { 1.0 } else { -1.0 }
                        };
                        correction += dir * 0.5 * (spacing - len);
                    }
                });
                (p[i] + correction * 0.5).clamp(self.lo, self.hi)
            })
            .collect()
    }

    /// XSPH-style viscosity: each velocity blended towards its neighbours' mean.
    fn viscous(&self, p: &[DVec3], new_v: &[DVec3]) -> Vec<DVec3> {
        let spacing = self.spacing;
        let grid = NeighbourGrid::new(p, 2.0 * spacing, self.tank);
        (0..p.len())
            .into_par_iter()
            .map(|i| {
                let (mut sum, mut weight) = (DVec3::ZERO, 0.0);
                grid.for_each_near(p[i], |j| {
                    let d = p[i].distance(p[j]);
                    if d < 2.0 * spacing {
                        let w = 1.0 - d / (2.0 * spacing);
                        sum += new_v[j] * w;
                        weight += w;
                    }
                });
                let mean = if weight > 0.0 { sum / weight } else { new_v[i] };
                new_v[i] + (mean - new_v[i]) * 0.05
            })
            .collect()
    }

    /// Each particle's neighbours within two spacings.
    fn neighbours(&self, x: &[DVec3]) -> Vec<f64> {
        let spacing = self.spacing;
        let grid = NeighbourGrid::new(x, 2.0 * spacing, self.tank);
        (0..x.len())
            .into_par_iter()
            .map(|i| {
                let mut count = 0u32;
                grid.for_each_near(x[i], |j| {
                    count += u32::from(j != i && x[i].distance(x[j]) < 2.0 * spacing);
                });
                f64::from(count)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Refined particles keep their count and their identity: each moves exactly as the
    /// simulated particle it rides with (inside the tank), with its velocity.
    #[test]
    fn a_refined_dam_break_moves_with_the_simulation() {
        let simulated = dambreak(2000, 3, 5);
        let riders = Riders {
            count: 7001,
            seed: 5,
        };
        let fine: Vec<Step> = simulated.iter().map(|s| riders.ride(s, 0..7001)).collect();
        assert_eq!(fine.len(), 3);
        let inside =
            |p: DVec3| p.cmpgt(DVec3::splat(1e-9)).all() && p.cmplt(DAMBREAK_TANK - 1e-9).all();
        let mut checked = 0;
        for k in (0..7001).step_by(7) {
            let parent = k % 2000;
            let (a, b) = (fine[1].positions[k], fine[2].positions[k]);
            if inside(a) && inside(b) {
                let moved = simulated[2].positions[parent] - simulated[1].positions[parent];
                assert!((b - a - moved).length() < 1e-12, "particle {k}");
                checked += 1;
            }
            assert_eq!(
                fine[2].attributes[0].values[k],
                simulated[2].attributes[0].values[parent]
            );
            assert!(fine[2].positions[k].cmpge(DVec3::ZERO).all());
            assert!(fine[2].positions[k].cmple(DAMBREAK_TANK).all());
        }
        assert!(checked > 500, "{checked}");
        assert_eq!(fine[0].attributes[0].name, "velocity");
        assert_eq!(fine[2].positions.len(), 7001);
    }

    /// A count above the simulated one that is no multiple of the run, the runs small.
    const RIDING: usize = 250_001;
    const RUN: usize = 100_000;

    /// Every format that is written a run at a time gives the same bytes as the step written
    /// whole, and the runs are the sizes asked for.
    #[test]
    fn a_step_written_in_runs_is_the_step_written_whole() {
        use io::{Format, SeriesSource};
        let (steps, seed) = (2, 3);
        let whole = Generator::DambreakDemo.generate(RIDING, steps, seed);
        let series = Generator::DambreakDemo
            .series(RIDING, steps, seed)
            .with_chunk_len(RUN);
        let mut runs = Vec::new();
        series
            .for_each_chunk(1, &mut |run| {
                runs.push(run.len());
                Ok(())
            })
            .unwrap();
        assert_eq!(runs, [RUN, RUN, RIDING - 2 * RUN]);
        for format in [Format::Particles, Format::Raw, Format::Npy] {
            let dir = tempfile::tempdir().unwrap();
            let (at_once, in_runs) = (dir.path().join("whole"), dir.path().join("runs"));
            io::write_series(&at_once, "db", &whole, format, "velocity").unwrap();
            io::write_series_from(&in_runs, "db", &series, format, "velocity").unwrap();
            let files = |d: &std::path::Path| {
                let mut names: Vec<_> = std::fs::read_dir(d)
                    .unwrap()
                    .map(|e| e.unwrap().file_name())
                    .collect();
                names.sort();
                names
            };
            let names = files(&at_once);
            assert_eq!(names, files(&in_runs), "{format}");
            // The .particles header and a file a step.
            assert_eq!(
                names.len(),
                steps + usize::from(format == Format::Particles),
                "{format}"
            );
            for name in names {
                let a = std::fs::read(at_once.join(&name)).unwrap();
                let b = std::fs::read(in_runs.join(&name)).unwrap();
                assert!(a == b, "{format}: {name:?} differs");
            }
        }
    }

    /// A step written in runs reads back through the ordinary readers as the generated step
    /// (rounded to f32 where the format holds f32).
    #[test]
    fn a_step_written_in_runs_reads_back_as_generated() {
        use io::{AttributeSelection, Format};
        let whole = Generator::DambreakDemo.generate(RIDING, 1, 9);
        let series = Generator::DambreakDemo
            .series(RIDING, 1, 9)
            .with_chunk_len(RUN);
        let expected = &whole[0];
        for format in [Format::Particles, Format::Raw, Format::Npy] {
            let dir = tempfile::tempdir().unwrap();
            let path =
                io::write_series_from(dir.path(), "db", &series, format, "velocity").unwrap();
            let refs = io::list_steps(&path, None).unwrap();
            assert_eq!(refs.len(), 1, "{format}");
            let back = io::read_step(&refs[0], &AttributeSelection::All).unwrap();
            let f32_format = format != Format::Npy;
            let stored = |v: f64| if f32_format { f64::from(v as f32) } else { v };
            let positions: Vec<DVec3> = expected
                .positions
                .iter()
                .map(|p| DVec3::from_array(p.to_array().map(stored)))
                .collect();
            assert_eq!(back.len(), RIDING, "{format}");
            assert!(back.positions == positions, "{format}: positions differ");
            // .particles and .raw carry the velocity alone; .npy every attribute, as columns.
            let names: &[&str] = match format {
                Format::Particles => &["attribute"],
                Format::Raw => &["w"],
                _ => &["col3", "col4"],
            };
            assert_eq!(back.attributes.len(), names.len(), "{format}");
            for (a, name) in expected.attributes.iter().zip(names) {
                let values: Vec<f64> = a.values.iter().map(|&v| stored(v)).collect();
                assert!(
                    back.attribute(name).unwrap().values == values,
                    "{format}: {name} differs from {}",
                    a.name
                );
            }
        }
    }
}
