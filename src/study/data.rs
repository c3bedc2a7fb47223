//! The data a study runs on: a synthetic set generated in memory (`uniform`, `random`,
//! `dambreak-demo`, `clusters`) or a series on disk, and the radius it is rendered at by default.

use std::path::PathBuf;
use std::sync::Arc;

use super::StudyError;
use crate::scene::synth::Generator;
use crate::scene::{OpenOptions, TimeSeries};
use crate::scene_file::RadiusSpec;
use crate::values::{Bounds, Step};

/// `--data`: a generator's name or a path.
#[derive(Clone, Debug, PartialEq)]
pub enum DataSpec {
    /// A generated data set.
    Generated(Generator),
    /// A particle file or directory.
    Path(PathBuf),
}

impl std::str::FromStr for DataSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<DataSpec, String> {
        if s.is_empty() {
            return Err("an empty data set name".into());
        }
        Ok(match s.parse::<Generator>() {
            Ok(g) => DataSpec::Generated(g),
            Err(_) => DataSpec::Path(PathBuf::from(s)),
        })
    }
}

impl std::fmt::Display for DataSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DataSpec::Generated(g) => write!(f, "{g}"),
            DataSpec::Path(p) => write!(f, "{}", p.display()),
        }
    }
}

/// One step of a data set, opened as a one-step-or-more series.
pub struct Dataset {
    /// The name in rows and tables.
    pub name: String,
    /// The data set's series.
    pub series: TimeSeries,
    /// The step measured, counted from 0.
    pub step: usize,
    /// The attribute to colour by (the generator's main one, or the data's first); `None` where the
    /// data has none.
    pub attribute: Option<String>,
    /// The particles of `step`.
    pub n: usize,
    /// `step`'s bounds (the benchmark orbit's centre and distance).
    pub bounds: Bounds,
    /// The radius the studies use unless swept (data units).
    pub radius: f64,
}

/// The dam break is generated with 15 steps and studied at step 14, as the other benchmarks
/// and the demo render it (the fluid has spread over the tank's floor).
const DAMBREAK_STEPS: usize = 15;

impl Dataset {
    /// Generates or opens `spec`: `count` particles for a generator (its default if `None`),
    /// step `step` (default: the last), coloured by `attribute` (default: the generator's, or
    /// the data's first attribute). `radius`, if given, is read as `aarbf render --radius`
    /// reads it (a length, or a percentage of the series' diagonal); otherwise
    /// [`default_radius`].
    pub fn load(
        spec: &DataSpec,
        count: Option<usize>,
        step: Option<usize>,
        attribute: Option<&str>,
        radius: Option<RadiusSpec>,
    ) -> Result<Dataset, StudyError> {
        let (series, generator) = match spec {
            DataSpec::Generated(g) => {
                let count = count.unwrap_or(g.default_count());
                if count == 0 {
                    return Err(StudyError::Invalid("--count must be at least 1".to_owned()));
                }
                let steps = if *g == Generator::DambreakDemo {
                    DAMBREAK_STEPS
                } else {
                    1
                };
                (
                    TimeSeries::from_steps(g.generate(count, steps, 1)),
                    Some(*g),
                )
            }
            DataSpec::Path(path) => (TimeSeries::open(path, &OpenOptions::default())?, None),
        };
        series.wait_for_scan()?;
        if series.is_empty() {
            return Err(StudyError::Invalid(format!("{spec}: no steps")));
        }
        let step = step.unwrap_or(series.len() - 1);
        if step >= series.len() {
            return Err(StudyError::Invalid(format!(
                "{spec}: step {step} does not exist (the series has {} steps)",
                series.len()
            )));
        }
        let attribute = match attribute {
            Some(a) => {
                if series.attribute(a).is_none() {
                    return Err(StudyError::Invalid(format!(
                        "{spec}: no attribute '{a}' (it has: {})",
                        series
                            .attributes()
                            .iter()
                            .map(|a| a.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )));
                }
                Some(a.to_owned())
            }
            None => generator
                .map(|g| g.main_attribute().to_owned())
                .or_else(|| series.attributes().first().map(|a| a.name.clone())),
        };
        let data: Arc<Step> = series.step(step)?;
        if data.is_empty() {
            return Err(StudyError::Invalid(format!(
                "{spec}: step {step} holds no particles"
            )));
        }
        let bounds = data.bounds();
        let radius = match radius {
            Some(r) => r.resolve(series.bounds().diagonal()),
            None => default_radius(generator, data.len(), series.bounds()),
        };
        Ok(Dataset {
            name: spec.to_string(),
            n: data.len(),
            series,
            step,
            attribute,
            bounds,
            radius,
        })
    }
}

impl Dataset {
    /// The step with the most particles (the first of equals): the largest this data holds.
    pub fn largest_step(&self) -> usize {
        (0..self.series.len())
            .max_by_key(|&i| {
                let count = self.series.step_info(i).map_or(0, |s| s.count);
                (count, std::cmp::Reverse(i))
            })
            .unwrap_or(self.step)
    }

    /// `n` particles of this data set's step drawn at random (seeded: the subsets of one seed
    /// are nested, each smaller one inside each larger one), kept in the file's order, as a
    /// one-step data set. With `keep_overlap` the radius grows by (N / n)^(1/3), so about as
    /// many particles reach a point as in the whole step.
    pub fn subset(&self, n: usize, seed: u64, keep_overlap: bool) -> Result<Dataset, StudyError> {
        use rand::SeedableRng;
        use rand::seq::SliceRandom;
        let step = self.series.step(self.step)?;
        let n = n.clamp(1, step.len());
        let mut chosen: Vec<usize> = (0..step.len()).collect();
        chosen.shuffle(&mut rand_pcg::Pcg64::seed_from_u64(seed));
        chosen.truncate(n);
        chosen.sort_unstable();
        let subset = Step {
            name: format!("{} ({n} of {})", step.name, step.len()),
            positions: chosen.iter().map(|&i| step.positions[i]).collect(),
            attributes: step
                .attributes
                .iter()
                .map(|a| crate::values::Attribute {
                    name: a.name.clone(),
                    values: chosen.iter().map(|&i| a.values[i]).collect(),
                })
                .collect(),
        };
        let bounds = subset.bounds();
        let radius = if keep_overlap {
            self.radius * (step.len() as f64 / n as f64).cbrt()
        } else {
            self.radius
        };
        Ok(Dataset {
            name: self.name.clone(),
            series: TimeSeries::from_steps(vec![subset]),
            step: 0,
            attribute: self.attribute.clone(),
            n,
            bounds,
            radius,
        })
    }
}

/// The radius a study renders a data set at: for the unit-cube sets (`uniform`, `random`) the
/// one at which about 30 particles reach a point, as the other benchmarks use; for every
/// other data set 1.5% of the series' diagonal (`series_bounds`), the demo's radius.
pub fn default_radius(generator: Option<Generator>, n: usize, series_bounds: Bounds) -> f64 {
    match generator {
        Some(Generator::Uniform | Generator::Random) => radius_for_overlap(30.0, n),
        _ => RadiusSpec::PercentOfDiagonal(1.5).resolve(series_bounds.diagonal()),
    }
}

/// The radius at which `overlap` of `n` uniformly spread particles in the unit cube reach a
/// point on average.
pub fn radius_for_overlap(overlap: f64, n: usize) -> f64 {
    (overlap * 3.0 / (4.0 * std::f64::consts::PI * n.max(1) as f64)).cbrt()
}
