//! The settings a user may leave to the renderer, as properties of the series and the field,
//! never of the step being rendered: a frame of a sequence equals the same step rendered alone,
//! a sequence rendered in chunks has no seams, and the values are printed and written into a
//! saved scene so a frame can be reproduced exactly.
//!
//! - **Radii**: the largest radius any particle of the series can have
//!   (`R · max m · max h`, h over the whole series), which sets the march box's margin, and
//!   the typical one (`R · max m · mean h`), which sets the default step and density scale.
//! - **Phi_ref**, the density that maps to 1 for colour and extinction: the 95th percentile of
//!   Phi at up to [`PHI_REF_SAMPLES`] particle centres of the series' first step, computed in
//!   f64 on the CPU from the field's own rules (the maps' tables, the radius rule), so it is
//!   the same number on every backend. Neighbours are found with a grid of cells as wide as
//!   the largest radius, built once per series and step 0 and kept while only the maps change.
//!
//! The pieces of both estimates at particle centres (the rules, [`Estimate`]; the grid; which
//! records are sampled; the percentile) are the crate's, so that the distributed estimates
//! ([`crate::dist::auto`]), where each rank holds only its part of the first step, apply the
//! same ones and find the same numbers.

use glam::DVec3;
use rayon::prelude::*;

use super::error::RenderError;
use crate::field::{FieldSettings, FieldTables, normalise, particle_radius};
use crate::scene::TimeSeries;
use crate::values::tables::{lookup, table_max};
use crate::values::{Attribute, Step};

/// Particle centres Phi_ref is estimated at, at most.
pub const PHI_REF_SAMPLES: usize = 4096;
/// The most particle-sample pairs the estimate visits: beyond it (radii spanning the data) it
/// uses fewer samples, at least [`PHI_REF_MIN_SAMPLES`].
const PHI_REF_WORK: usize = 50_000_000;
const PHI_REF_MIN_SAMPLES: usize = 64;

/// The values derived from the series and the field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AutoValues {
    /// The density that maps to 1 for colour and extinction: the 95th percentile of Phi at particle
    /// centres of the first step.
    pub phi_ref: f64,
    /// The typical particle radius `R · max m · mean h`, data units: sets the default step and
    /// density scale.
    pub typical_radius: f64,
    /// The largest radius any particle of the series can have, `R · max m · max h`, data units:
    /// sets the march box's margin.
    pub max_radius: f64,
}

impl AutoValues {
    /// Whether two fields have the same automatic values (a change of colour map or
    /// classification keeps them).
    pub fn same_for(a: &FieldSettings, b: &FieldSettings) -> bool {
        a.attribute == b.attribute
            && a.attribute_range == b.attribute_range
            && a.radius == b.radius
            && a.radius_attribute == b.radius_attribute
            && a.radius_map == b.radius_map
            && a.density_map == b.density_map
    }

    /// The values for `field` over `series`.
    pub fn of(series: &TimeSeries, field: &FieldSettings) -> Result<AutoValues, RenderError> {
        AutoValues::with_phi_ref(series, field, None)
    }

    /// The values for `field` over `series`, with `phi_ref` where it is given (`--phi-ref`, `given`):
    /// then the first step is not read (Phi_ref is the one value that needs the first step,
    /// read whole here; the others come from the series' statistics). A distributed render's
    /// ranks find the same values each reading only its part ([`crate::dist::auto`]).
    pub fn with_phi_ref(
        series: &TimeSeries,
        field: &FieldSettings,
        given: Option<f64>,
    ) -> Result<AutoValues, RenderError> {
        AutoValues::estimated(series, field, given, |estimate| {
            Ok(estimate.phi_ref(&*series.step(0)?))
        })
    }

    /// The values for `field` over `series`, Phi_ref (unless `given`, or the series has no
    /// step) by `estimate_phi_ref` under the series' rules: from the whole first step
    /// ([`AutoValues::with_phi_ref`]) or from each rank's part of it ([`crate::dist::auto`]).
    pub(crate) fn estimated<E>(
        series: &TimeSeries,
        field: &FieldSettings,
        given: Option<f64>,
        estimate_phi_ref: impl FnOnce(&Estimate) -> Result<f64, E>,
    ) -> Result<AutoValues, E> {
        let estimate = Estimate::new(series, field);
        let phi_ref = match given {
            Some(given) => given,
            None if series.is_empty() => 1.0,
            None => estimate_phi_ref(&estimate)?,
        };
        Ok(AutoValues {
            phi_ref,
            typical_radius: estimate.typical_radius,
            max_radius: estimate.max_radius,
        })
    }
}

/// The typical radius (`R · max m · mean h`) and the largest (`R · max m · max h`, h over the
/// whole series).
fn radii(series: &TimeSeries, field: &FieldSettings, tables: &FieldTables) -> (f64, f64) {
    let m_max = table_max(&tables.radius);
    let h = field
        .radius_attribute
        .as_deref()
        .and_then(|a| series.attribute(a));
    let (mean_h, max_h) = h.map_or((1.0, 1.0), |h| (h.mean, h.max));
    (field.radius * m_max * mean_h, field.radius * m_max * max_h)
}

/// The range the field's attribute is normalised over: the field's, else the series'.
fn attribute_range(series: &TimeSeries, field: &FieldSettings) -> (f64, f64) {
    field
        .attribute_range
        .or_else(|| {
            let a = series.attribute(field.attribute.as_deref()?)?;
            Some((a.min, a.max))
        })
        .unwrap_or((0.0, 0.0))
}

/// Particle centres [`mean_overlap`] counts at, at most.
const OVERLAP_SAMPLES: usize = 1024;

/// How many particles reach a particle centre of the series' first step, on average (each
/// particle's own radius, as the field's): the overlap that decides how many particles a
/// cluster box should hold ([`crate::accel::ClusterSize::for_overlap`]). A property of the
/// series and the field, like Phi_ref.
pub fn mean_overlap(series: &TimeSeries, field: &FieldSettings) -> Result<f64, RenderError> {
    if series.is_empty() {
        return Ok(0.0);
    }
    Ok(Estimate::new(series, field).mean_overlap(&*series.step(0)?))
}

/// The field's rules over a series as the estimates at particle centres of its first step
/// apply them, in f64 on the CPU: the maps' tables, the range the attribute is normalised over
/// and the radii, all from the field and the series' statistics (never from the step), so a
/// rank holding part of the step has them whole.
pub(crate) struct Estimate<'a> {
    field: &'a FieldSettings,
    tables: FieldTables,
    range: (f64, f64),
    typical_radius: f64,
    max_radius: f64,
}

impl<'a> Estimate<'a> {
    pub(crate) fn new(series: &TimeSeries, field: &'a FieldSettings) -> Estimate<'a> {
        let tables = FieldTables::of(field);
        let (typical_radius, max_radius) = radii(series, field, &tables);
        Estimate {
            field,
            range: attribute_range(series, field),
            tables,
            typical_radius,
            max_radius,
        }
    }

    /// Whether any particle has a positive radius (without, Phi is 0 everywhere, Phi_ref is 1
    /// and no particle reaches a centre).
    pub(crate) fn reaches(&self) -> bool {
        self.max_radius > 0.0
    }

    /// A grid of `positions` in cells as wide as the largest radius, laid over `bounds` (the
    /// whole step's least and greatest corner: a rank's part is laid in the whole step's grid).
    pub(crate) fn grid(&self, positions: &[DVec3], bounds: (DVec3, DVec3)) -> Grid {
        Grid::over(positions, bounds, self.max_radius)
    }

    /// `step`'s particles (a whole step, or a rank's part of one) under the rules.
    pub(crate) fn particles<'s>(&'s self, step: &'s Step) -> ParticleRule<'s> {
        ParticleRule {
            estimate: self,
            positions: &step.positions,
            attribute: self
                .field
                .attribute
                .as_deref()
                .and_then(|a| step.attribute(a)),
            h: self
                .field
                .radius_attribute
                .as_deref()
                .and_then(|a| step.attribute(a)),
        }
    }

    /// The 95th percentile of Phi (positive values) at every k-th particle centre of `step`.
    fn phi_ref(&self, step: &Step) -> f64 {
        let n = step.len();
        if n == 0 || !self.reaches() {
            return 1.0;
        }
        let grid = self.grid(&step.positions, bounds_of(&step.positions));
        let particles = self.particles(step);
        let stride = phi_ref_stride(n, grid.mean_candidates());
        let phi = (0..n)
            .into_par_iter()
            .step_by(stride)
            .map(|j| particles.phi_at(step.positions[j], &grid))
            .collect();
        phi_percentile(phi)
    }

    /// How many particles reach every k-th particle centre of `step`, on average.
    fn mean_overlap(&self, step: &Step) -> f64 {
        let n = step.len();
        if n == 0 || !self.reaches() {
            return 0.0;
        }
        let grid = self.grid(&step.positions, bounds_of(&step.positions));
        let particles = self.particles(step);
        let counts: Vec<u64> = (0..n)
            .into_par_iter()
            .step_by(overlap_stride(n))
            .map(|j| particles.reaching(step.positions[j], &grid))
            .collect();
        mean_count(&counts)
    }
}

/// Every how many records of a step of `n` Phi_ref is sampled at (records 0, k, 2k, ...):
/// [`PHI_REF_SAMPLES`] centres, fewer where each sample would visit many particles
/// (`per_sample`, [`Grid::mean_candidates`]: radii spanning the data).
pub(crate) fn phi_ref_stride(n: usize, per_sample: f64) -> usize {
    let samples = ((PHI_REF_WORK as f64 / per_sample.max(1.0)) as usize)
        .clamp(PHI_REF_MIN_SAMPLES, PHI_REF_SAMPLES)
        .min(n);
    n.div_ceil(samples.max(1)).max(1)
}

/// Every how many records of a step of `n` the mean overlap is counted at.
pub(crate) fn overlap_stride(n: usize) -> usize {
    n.div_ceil(n.clamp(1, OVERLAP_SAMPLES)).max(1)
}

/// Phi_ref from Phi at the sampled centres: the 95th percentile of the positive values (1
/// where none is).
pub(crate) fn phi_percentile(mut phi: Vec<f64>) -> f64 {
    phi.retain(|p| *p > 0.0);
    phi.sort_by(f64::total_cmp);
    phi.get(phi.len() * 95 / 100).copied().unwrap_or(1.0)
}

/// The mean of the particle counts at the sampled centres.
pub(crate) fn mean_count(counts: &[u64]) -> f64 {
    counts.iter().sum::<u64>() as f64 / counts.len().max(1) as f64
}

/// The least and the greatest corner of `positions` (infinite, inverted, for none).
pub(crate) fn bounds_of(positions: &[DVec3]) -> (DVec3, DVec3) {
    positions
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        })
}

/// About how many particles the 27 cells around a particle hold, on average (what one sample of
/// Phi costs), from `squares`, the sum over occupied cells of their particle counts squared, and
/// `n` particles: a particle's own cell holds Σ n² / N particles on average, its neighbourhood
/// about 27 cells' worth at that density. The sum is an exact integer, so that a step's cells
/// counted by parts give the whole step's number.
pub(crate) fn mean_candidates(squares: u128, n: usize) -> f64 {
    27.0 * squares as f64 / n.max(1) as f64
}

/// A step's particles under the field's rules, evaluated in f64 on the CPU: each one's
/// normalised attribute and radius.
pub(crate) struct ParticleRule<'a> {
    estimate: &'a Estimate<'a>,
    positions: &'a [DVec3],
    attribute: Option<&'a Attribute>,
    h: Option<&'a Attribute>,
}

impl ParticleRule<'_> {
    /// Particle `i`'s attribute, normalised (0.5 without one).
    fn t(&self, i: usize) -> f64 {
        self.attribute
            .map_or(0.5, |a| normalise(a.values[i], self.estimate.range))
    }

    /// Particle `i`'s radius, `t` being its [`ParticleRule::t`].
    fn radius(&self, t: f64, i: usize) -> f64 {
        particle_radius(
            self.estimate.field.radius,
            lookup(&self.estimate.tables.radius, t),
            self.h.map(|h| h.values[i]),
        )
    }

    /// Phi at `x` of these particles (`grid` holds them): each one within its radius adds
    /// its density map's value times `exp(-4.5 d² / r²)`.
    pub(crate) fn phi_at(&self, x: DVec3, grid: &Grid) -> f64 {
        let mut sum = 0.0;
        grid.for_each_near(x, |i| {
            let t = self.t(i);
            let r = self.radius(t, i);
            let d2 = (x - self.positions[i]).length_squared();
            if r > 0.0 && d2 <= r * r {
                sum += lookup(&self.estimate.tables.density, t) * (-4.5 * d2 / (r * r)).exp();
            }
        });
        sum
    }

    /// How many of these particles (`grid` holds them) reach `x` with their own radius.
    pub(crate) fn reaching(&self, x: DVec3, grid: &Grid) -> u64 {
        let mut count = 0;
        grid.for_each_near(x, |i| {
            let r = self.radius(self.t(i), i);
            count += u64::from(r > 0.0 && (x - self.positions[i]).length_squared() <= r * r);
        });
        count
    }
}

/// Particles bucketed in cubic cells of side `cell` (sorted by cell key), for finding every
/// particle within `cell` of a point in the 27 cells around it.
pub(crate) struct Grid {
    origin: DVec3,
    cell: f64,
    /// (cell key, particle index), sorted.
    entries: Vec<(u64, u32)>,
}

impl Grid {
    /// `positions` in cells of side `cell` at least, laid from `bounds.0` so that `bounds`
    /// spans at most 2^20 cells per axis (keys of 60 bits; larger radii need fewer). The
    /// positions lie in `bounds`.
    fn over(positions: &[DVec3], bounds: (DVec3, DVec3), cell: f64) -> Grid {
        let (origin, greatest) = bounds;
        let extent = greatest - origin;
        let cell = cell
            .max(extent.max_element() / f64::from(1u32 << 20))
            .max(1e-300);
        let grid = Grid {
            origin,
            cell,
            entries: Vec::new(),
        };
        let mut entries: Vec<(u64, u32)> = positions
            .par_iter()
            .enumerate()
            .map(|(i, p)| (grid.key(grid.cell_of(*p)), i as u32))
            .collect();
        entries.par_sort_unstable();
        Grid { entries, ..grid }
    }

    fn cell_of(&self, p: DVec3) -> [i64; 3] {
        let c = ((p - self.origin) / self.cell).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    fn key(&self, c: [i64; 3]) -> u64 {
        let k = |v: i64| (v.clamp(0, (1 << 20) - 1)) as u64;
        (k(c[0]) << 40) | (k(c[1]) << 20) | k(c[2])
    }

    /// Calls `visit(i)` for every particle in the 27 cells around `x` (every one within a
    /// cell's side of it, and some farther).
    fn for_each_near(&self, x: DVec3, mut visit: impl FnMut(usize)) {
        let c = self.cell_of(x);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let n = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if n.iter().any(|&v| !(0..1 << 20).contains(&v)) {
                        continue;
                    }
                    let key = self.key(n);
                    let start = self.entries.partition_point(|e| e.0 < key);
                    for e in self.entries[start..].iter().take_while(|e| e.0 == key) {
                        visit(e.1 as usize);
                    }
                }
            }
        }
    }

    /// Each occupied cell's key and particle count, in key order.
    pub(crate) fn cell_counts(&self) -> Vec<(u64, u64)> {
        self.entries
            .chunk_by(|a, b| a.0 == b.0)
            .map(|run| (run[0].0, run.len() as u64))
            .collect()
    }

    /// [`mean_candidates`] of the particles it holds.
    fn mean_candidates(&self) -> f64 {
        let squares = self
            .cell_counts()
            .iter()
            .map(|&(_, count)| u128::from(count) * u128::from(count))
            .sum();
        mean_candidates(squares, self.entries.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The mean overlap is the count of particles whose own radius reaches each sampled centre,
    /// itself included, found by brute force here; radii from an attribute (smoothing length)
    /// and off-origin f64 positions.
    #[test]
    fn mean_overlap_counts_the_particles_reaching_each_centre() {
        let mut state = 7u64;
        let mut random = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let n: usize = 1237;
        let positions: Vec<DVec3> = (0..n)
            .map(|_| DVec3::new(random(), random(), random()) * DVec3::new(3.0, 2.0, 1.0) - 5e4)
            .collect();
        let h: Vec<f64> = (0..n).map(|_| 0.5 + random()).collect();
        let step = Step {
            name: "overlap".into(),
            positions: positions.clone(),
            attributes: vec![Attribute {
                name: "h".into(),
                values: h.clone(),
            }],
        };
        let series = TimeSeries::from_steps(vec![step]);
        let mut field = FieldSettings::new(None, 0.2);
        field.radius_attribute = Some("h".into());
        let got = mean_overlap(&series, &field).unwrap();
        let stride = n.div_ceil(n.min(OVERLAP_SAMPLES));
        let counts: Vec<usize> = (0..n)
            .step_by(stride)
            .map(|j| {
                (0..n)
                    .filter(|&i| {
                        let r = 0.2 * h[i];
                        (positions[j] - positions[i]).length_squared() <= r * r
                    })
                    .count()
            })
            .collect();
        let want = counts.iter().sum::<usize>() as f64 / counts.len() as f64;
        assert_eq!(got, want);
        assert!(want > 3.0, "the particles overlap: {want}");
    }
    use crate::field::ReferenceField;
    use crate::scene::synth::Generator;

    #[test]
    fn phi_ref_is_the_reference_fields_95th_percentile_at_the_first_steps_centres() {
        let steps = Generator::DambreakDemo.generate(3000, 4, 2);
        let series = TimeSeries::from_steps(steps.clone());
        let mut field = FieldSettings::new(Some("velocity"), 0.02 * series.bounds().diagonal());
        field.density_map =
            crate::scene::maps::DensityMap::new("0:0.3,0.7:1,1:0.2".parse().unwrap()).unwrap();
        let auto = AutoValues::of(&series, &field).unwrap();
        let range = series.attribute("velocity").map(|a| (a.min, a.max));
        let reference = ReferenceField::of_step(
            &steps[0],
            &field,
            crate::accel::ClusterSize::new(4).unwrap(),
            series.bounds(),
            range,
        )
        .unwrap();
        let mut phi: Vec<f64> = steps[0]
            .positions
            .iter()
            .map(|&x| reference.eval(x).phi)
            .filter(|p| *p > 0.0)
            .collect();
        phi.sort_by(f64::total_cmp);
        let expected = phi[phi.len() * 95 / 100];
        assert!(
            (auto.phi_ref - expected).abs() <= 1e-9 * expected,
            "{} vs {expected}",
            auto.phi_ref
        );
        // A property of the series: the same whatever step is shown later.
        assert_eq!(AutoValues::of(&series, &field).unwrap(), auto);
    }
}
