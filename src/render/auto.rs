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
    /// then the first step is not read (Phi_ref is the one value that needs a whole step; the
    /// others come from the series' statistics).
    pub fn with_phi_ref(
        series: &TimeSeries,
        field: &FieldSettings,
        given: Option<f64>,
    ) -> Result<AutoValues, RenderError> {
        let tables = FieldTables::of(field);
        let (typical_radius, max_radius) = radii(series, field, &tables);
        let phi_ref = if let Some(given) = given {
            given
        } else if series.is_empty() {
            1.0
        } else {
            let step = series.step(0)?;
            let range = attribute_range(series, field);
            phi_ref(&step, field, &tables, range, max_radius)
        };
        Ok(AutoValues {
            phi_ref,
            typical_radius,
            max_radius,
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
    let step = series.step(0)?;
    let tables = FieldTables::of(field);
    let (_, max_radius) = radii(series, field, &tables);
    let n = step.len();
    if n == 0 || max_radius.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return Ok(0.0);
    }
    let rule = ParticleRule::new(&step, field, &tables, attribute_range(series, field));
    let grid = Grid::new(&step.positions, max_radius);
    let samples = n.min(OVERLAP_SAMPLES);
    let stride = n.div_ceil(samples).max(1);
    let counts: Vec<usize> = (0..n)
        .into_par_iter()
        .step_by(stride)
        .map(|j| {
            let x = step.positions[j];
            let mut count = 0;
            grid.for_each_near(x, |i| {
                let r = rule.radius(rule.t(i), i);
                count += usize::from(r > 0.0 && (x - step.positions[i]).length_squared() <= r * r);
            });
            count
        })
        .collect();
    Ok(counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64)
}

/// The 95th percentile of Phi (positive values) at every k-th particle centre of `step`.
fn phi_ref(
    step: &Step,
    field: &FieldSettings,
    tables: &FieldTables,
    range: (f64, f64),
    max_radius: f64,
) -> f64 {
    let n = step.len();
    if n == 0 || max_radius.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 1.0;
    }
    let grid = Grid::new(&step.positions, max_radius);
    let rule = ParticleRule::new(step, field, tables, range);
    // Fewer samples where every sample meets most of the step (radii spanning the data).
    let per_sample = grid.mean_candidates().max(1.0);
    let samples = ((PHI_REF_WORK as f64 / per_sample) as usize)
        .clamp(PHI_REF_MIN_SAMPLES, PHI_REF_SAMPLES)
        .min(n);
    let stride = n.div_ceil(samples).max(1);
    let centres: Vec<usize> = (0..n).step_by(stride).collect();
    let mut phi: Vec<f64> = centres
        .par_iter()
        .map(|&j| {
            let x = step.positions[j];
            let mut sum = 0.0;
            grid.for_each_near(x, |i| {
                let t = rule.t(i);
                let r = rule.radius(t, i);
                let d2 = (x - step.positions[i]).length_squared();
                if r > 0.0 && d2 <= r * r {
                    sum += lookup(&tables.density, t) * (-4.5 * d2 / (r * r)).exp();
                }
            });
            sum
        })
        .filter(|p| *p > 0.0)
        .collect();
    phi.sort_by(f64::total_cmp);
    phi.get(phi.len() * 95 / 100).copied().unwrap_or(1.0)
}

/// A step's particles under the field's rules, evaluated in f64 on the CPU: each one's
/// normalised attribute and radius.
struct ParticleRule<'a> {
    field: &'a FieldSettings,
    tables: &'a FieldTables,
    range: (f64, f64),
    attribute: Option<&'a Attribute>,
    h: Option<&'a Attribute>,
}

impl<'a> ParticleRule<'a> {
    fn new(
        step: &'a Step,
        field: &'a FieldSettings,
        tables: &'a FieldTables,
        range: (f64, f64),
    ) -> Self {
        ParticleRule {
            field,
            tables,
            range,
            attribute: field.attribute.as_deref().and_then(|a| step.attribute(a)),
            h: field
                .radius_attribute
                .as_deref()
                .and_then(|a| step.attribute(a)),
        }
    }

    /// Particle `i`'s attribute, normalised (0.5 without one).
    fn t(&self, i: usize) -> f64 {
        self.attribute
            .map_or(0.5, |a| normalise(a.values[i], self.range))
    }

    /// Particle `i`'s radius, `t` being its [`ParticleRule::t`].
    fn radius(&self, t: f64, i: usize) -> f64 {
        particle_radius(
            self.field.radius,
            lookup(&self.tables.radius, t),
            self.h.map(|h| h.values[i]),
        )
    }
}

/// Particles bucketed in cubic cells of side `cell` (sorted by cell key), for finding every
/// particle within `cell` of a point in the 27 cells around it.
struct Grid {
    origin: DVec3,
    cell: f64,
    /// (cell key, particle index), sorted.
    entries: Vec<(u64, u32)>,
}

impl Grid {
    fn new(positions: &[DVec3], cell: f64) -> Grid {
        let origin = positions.iter().fold(DVec3::INFINITY, |m, p| m.min(*p));
        let extent = positions.iter().fold(DVec3::NEG_INFINITY, |m, p| m.max(*p)) - origin;
        // At most 2^20 cells per axis (keys of 60 bits); larger radii need fewer.
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

    /// About how many particles the 27 cells around a particle hold, on average (what one
    /// sample of Phi costs): a particle's own cell holds Σ n² / N particles on average (n per
    /// occupied cell), its neighbourhood about 27 cells' worth at that density.
    fn mean_candidates(&self) -> f64 {
        let mut squares = 0f64;
        let mut run = 0usize;
        for (k, e) in self.entries.iter().enumerate() {
            run += 1;
            if self.entries.get(k + 1).is_none_or(|next| next.0 != e.0) {
                squares += (run * run) as f64;
                run = 0;
            }
        }
        27.0 * squares / self.entries.len().max(1) as f64
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
