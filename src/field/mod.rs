//! The f64 reference field (method.md §2): density Phi and attribute field Theta at query
//! points, by brute force over all particles and through a BVH over cluster boxes. This is the
//! oracle every GPU stage is tested against.
//!
//! For particle i with centre c_i, attribute s_i, normalised t_i = (s_i - s_min) / (s_max -
//! s_min), radius r_i = R · m(t_i) · h_i (h_i the per-particle radius when the data has one):
//!
//! ```text
//! phi_i(x) = w(t_i) · exp(-0.5 · (3 d / r_i)^2)   for d = |x - c_i| <= r_i, else 0
//! Phi(x)   = Σ phi_i(x)
//! Theta(x) = Σ theta_i · phi_i(x) / Phi(x)       (0 where Phi is 0 or denormal)
//! ```
//! with theta_i = s_i (post-classification; reported in the attribute's own units) or the
//! linear-light colour C(t_i) (pre-classification).

use glam::DVec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::accel::{ClusterBoxes, ClusterBvh, ClusterSize, hilbert_order};
use crate::scene::maps::{ColorMap, DensityMap, RadiusMap};
use crate::values::{Bounds, Step};

/// How attribute values become colour (method.md §2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Classification {
    /// Average the attribute, then colour-map the average.
    #[default]
    Post,
    /// Colour-map each particle, then average the colours.
    Pre,
}

/// Everything that defines the field of one step.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldSettings {
    /// The attribute the field carries; `None` for density only (maps must then be constant).
    pub attribute: Option<String>,
    /// Overrides the attribute's range over the series for normalisation.
    pub attribute_range: Option<(f64, f64)>,
    /// Global radius R, in data units.
    pub radius: f64,
    /// Per-particle radius attribute h (scaled by R).
    pub radius_attribute: Option<String>,
    pub radius_map: RadiusMap,
    pub density_map: DensityMap,
    pub color_map: ColorMap,
    pub classification: Classification,
}

impl FieldSettings {
    /// A field over `attribute` with radius `radius` and default maps (w = 1, m = 1).
    pub fn new(attribute: Option<&str>, radius: f64) -> FieldSettings {
        FieldSettings {
            attribute: attribute.map(str::to_owned),
            attribute_range: None,
            radius,
            radius_attribute: None,
            radius_map: RadiusMap::default(),
            density_map: DensityMap::default(),
            color_map: ColorMap::default(),
            classification: Classification::Post,
        }
    }
}

/// Why a field cannot be set up.
#[derive(Debug, thiserror::Error)]
pub enum FieldError {
    #[error("step '{step}' has no attribute '{name}'; it has: {available}")]
    MissingAttribute {
        step: String,
        name: String,
        available: String,
    },
    #[error("the global radius must be a positive finite number, got {0}")]
    BadRadius(f64),
    #[error("the {0} varies with the attribute, but no attribute was chosen")]
    MapNeedsAttribute(&'static str),
    #[error("the attribute range {0}..{1} is not a finite ascending pair")]
    BadRange(f64, f64),
    #[error(
        "step '{step}': radius attribute '{name}' holds {value} for particle {index}; radii must be >= 0"
    )]
    NegativeRadius {
        step: String,
        name: String,
        value: f32,
        index: usize,
    },
}

/// Per-particle values theta_i.
#[derive(Clone, Debug, PartialEq)]
pub enum Theta {
    /// Density only: no attribute is carried.
    None,
    /// Post-classification: t_i (normalised attribute).
    Scalar(Vec<f64>),
    /// Pre-classification: linear-light C(t_i).
    Rgb(Vec<[f64; 3]>),
}

/// The arrays a field reads from a step, checked against its settings: what every backend
/// needs before it prepares anything.
pub struct FieldInputs<'a> {
    /// The attribute the field carries, if any.
    pub attribute: Option<&'a crate::values::Attribute>,
    /// The per-particle radius attribute, if any.
    pub radius: Option<&'a crate::values::Attribute>,
    /// The range t is normalised over.
    pub range: (f64, f64),
}

impl<'a> FieldInputs<'a> {
    /// Checks `settings` against `step`: a positive finite radius, the attributes present, no
    /// negative per-particle radius, constant maps when no attribute is carried, a valid range.
    pub fn check(
        step: &'a Step,
        settings: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<FieldInputs<'a>, FieldError> {
        if !(settings.radius.is_finite() && settings.radius > 0.0) {
            return Err(FieldError::BadRadius(settings.radius));
        }
        let lookup = |name: &str| {
            step.attribute(name)
                .ok_or_else(|| FieldError::MissingAttribute {
                    step: step.name.clone(),
                    name: name.to_owned(),
                    available: step.attribute_names().join(", "),
                })
        };
        let attribute = settings.attribute.as_deref().map(lookup).transpose()?;
        let per_particle_radius = settings
            .radius_attribute
            .as_deref()
            .map(lookup)
            .transpose()?;
        if let Some(h) = per_particle_radius
            && let Some((index, &value)) = h.values.iter().enumerate().find(|(_, v)| **v < 0.0)
        {
            return Err(FieldError::NegativeRadius {
                step: step.name.clone(),
                name: h.name.clone(),
                value,
                index,
            });
        }
        if attribute.is_none() {
            if !settings.radius_map.0.is_constant() {
                return Err(FieldError::MapNeedsAttribute("radius map"));
            }
            if !settings.density_map.0.is_constant() {
                return Err(FieldError::MapNeedsAttribute("density map"));
            }
        }
        let range = match (settings.attribute_range, attribute) {
            (Some((lo, hi)), _) => {
                if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                    return Err(FieldError::BadRange(lo, hi));
                }
                (lo, hi)
            }
            (None, Some(a)) => series_range.unwrap_or_else(|| {
                crate::values::value_range(&a.values)
                    .map_or((0.0, 0.0), |(lo, hi)| (f64::from(lo), f64::from(hi)))
            }),
            (None, None) => (0.0, 0.0),
        };

        let inputs = FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
        };
        inputs.warn_if_meaningless(step, settings);
        Ok(inputs)
    }

    /// Warns (once per preparation, on every backend) when the settings leave this step no
    /// density anywhere, so the image is empty for a reason the user can fix.
    fn warn_if_meaningless(&self, step: &Step, settings: &FieldSettings) {
        if step.is_empty() {
            return;
        }
        let t_of = |i: usize| {
            self.attribute
                .map_or(0.5, |a| normalise(f64::from(a.values[i]), self.range))
        };
        let no_radius = (0..step.len()).into_par_iter().all(|i| {
            let h = self.radius.map_or(1.0, |h| f64::from(h.values[i]));
            settings.radius_map.0.eval(t_of(i)) * h <= 0.0
        });
        if no_radius {
            tracing::warn!(
                "step '{}': every particle has radius 0 under the radius map{}, so the field is 0 everywhere",
                step.name,
                self.radius
                    .map(|h| format!(" and radius attribute '{}'", h.name))
                    .unwrap_or_default()
            );
        } else if (0..step.len())
            .into_par_iter()
            .all(|i| settings.density_map.0.eval(t_of(i)) <= 0.0)
        {
            tracing::warn!(
                "step '{}': the density map gives every particle weight 0, so the field is 0 everywhere",
                step.name
            );
        }
    }
}

/// The particles of one step, prepared for the field: Hilbert-sorted, with radius, weight and
/// theta evaluated once per particle.
#[derive(Clone, Debug)]
pub struct Particles {
    pub centers: Vec<DVec3>,
    pub radii: Vec<f64>,
    pub weights: Vec<f64>,
    pub theta: Theta,
    /// The attribute range t is normalised over (`lo == hi` for a constant attribute, where
    /// every t is 0.5).
    pub range: (f64, f64),
    /// `order[k]` is the step's index of sorted particle k.
    pub order: Vec<u32>,
}

/// Normalises s into t over `range`; a zero-width range maps everything to 0.5.
pub fn normalise(s: f64, range: (f64, f64)) -> f64 {
    let width = range.1 - range.0;
    if width > 0.0 {
        (s - range.0) / width
    } else {
        0.5
    }
}

impl Particles {
    /// Prepares `step` under `settings`. `series_bounds` fixes the Hilbert grid and
    /// `series_range` the attribute's range (both over the whole series).
    pub fn prepare(
        step: &Step,
        settings: &FieldSettings,
        series_bounds: Bounds,
        series_range: Option<(f64, f64)>,
    ) -> Result<Particles, FieldError> {
        let FieldInputs {
            attribute,
            radius: per_particle_radius,
            range,
        } = FieldInputs::check(step, settings, series_range)?;
        let order = hilbert_order(&step.positions, series_bounds);
        let t_of = |i: usize| attribute.map_or(0.5, |a| normalise(f64::from(a.values[i]), range));
        let centers = order
            .par_iter()
            .map(|&i| step.positions[i as usize].as_dvec3())
            .collect();
        let radii: Vec<f64> = order
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                let h = per_particle_radius.map_or(1.0, |h| f64::from(h.values[i]));
                settings.radius * settings.radius_map.0.eval(t_of(i)) * h
            })
            .collect();
        let weights = order
            .par_iter()
            .map(|&i| settings.density_map.0.eval(t_of(i as usize)))
            .collect();
        let theta = match (attribute, settings.classification) {
            (None, _) => Theta::None,
            (Some(_), Classification::Post) => {
                Theta::Scalar(order.par_iter().map(|&i| t_of(i as usize)).collect())
            }
            (Some(_), Classification::Pre) => Theta::Rgb(
                order
                    .par_iter()
                    .map(|&i| settings.color_map.linear_rgb(t_of(i as usize)))
                    .collect(),
            ),
        };
        Ok(Particles {
            centers,
            radii,
            weights,
            theta,
            range,
            order,
        })
    }

    pub fn len(&self) -> usize {
        self.centers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.centers.is_empty()
    }

    /// Adds particle `i`'s contribution at `x` to `acc` if `x` lies within its radius.
    #[inline]
    fn accumulate(&self, i: usize, x: DVec3, acc: &mut Accumulator) {
        let r = self.radii[i];
        if r <= 0.0 {
            return;
        }
        let d2 = (x - self.centers[i]).length_squared();
        if d2 > r * r {
            return;
        }
        let phi = self.weights[i] * (-4.5 * d2 / (r * r)).exp();
        acc.phi += phi;
        match &self.theta {
            Theta::None => {}
            Theta::Scalar(t) => acc.theta[0] += t[i] * phi,
            Theta::Rgb(c) => {
                for (a, c) in acc.theta.iter_mut().zip(c[i]) {
                    *a += c * phi;
                }
            }
        }
    }
}

#[derive(Default)]
struct Accumulator {
    phi: f64,
    theta: [f64; 3],
}

/// The field at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Density Phi.
    pub phi: f64,
    /// Theta: the attribute in its own units in `theta[0]` (post-classification), or linear
    /// RGB (pre-classification); zeros where Phi is 0.
    pub theta: [f64; 3],
}

/// Phi and Theta from the sums Σ phi_i and Σ theta_i phi_i (what every backend's query
/// returns): Theta = numerator / Phi, in the attribute's units for post-classification
/// (`range` undoes the normalisation), linear RGB for pre-classification.
pub fn finish_sums(phi: f64, num: [f64; 3], post: bool, range: (f64, f64)) -> Sample {
    // Theta is undefined where Phi vanishes; a denormal Phi would make the ratio meaningless
    // (or infinite in f32 on a GPU), so both count as "no density here".
    if phi.is_nan() || phi < f64::MIN_POSITIVE {
        return Sample {
            phi: if phi.is_finite() { phi } else { 0.0 },
            theta: [0.0; 3],
        };
    }
    let mut theta = num.map(|v| v / phi);
    if post {
        let (lo, hi) = range;
        theta[0] = if hi > lo {
            lo + theta[0] * (hi - lo)
        } else {
            lo
        };
    }
    Sample { phi, theta }
}

/// The reference field of one step: prepared particles, cluster boxes and their BVH.
pub struct ReferenceField {
    pub particles: Particles,
    pub boxes: ClusterBoxes,
    bvh: ClusterBvh,
}

impl ReferenceField {
    pub fn new(particles: Particles, cluster: ClusterSize) -> ReferenceField {
        let boxes = ClusterBoxes::build(&particles.centers, &particles.radii, cluster);
        let bvh = ClusterBvh::build(&boxes);
        ReferenceField {
            particles,
            boxes,
            bvh,
        }
    }

    /// Builds the field of `step` in one call.
    pub fn of_step(
        step: &Step,
        settings: &FieldSettings,
        cluster: ClusterSize,
        series_bounds: Bounds,
        series_range: Option<(f64, f64)>,
    ) -> Result<ReferenceField, FieldError> {
        let particles = Particles::prepare(step, settings, series_bounds, series_range)?;
        Ok(ReferenceField::new(particles, cluster))
    }

    /// The field at `x` through the BVH.
    pub fn eval(&self, x: DVec3) -> Sample {
        let mut acc = Accumulator::default();
        let n = self.particles.len();
        self.bvh.for_each_cluster_at(x, |c| {
            for i in self.boxes.members(c, n) {
                self.particles.accumulate(i, x, &mut acc);
            }
        });
        self.finish(acc)
    }

    /// Phi and the Theta numerator at `x` as the renderer uses them: Σ phi_i and
    /// Σ theta_i phi_i with theta_i the normalised attribute t_i (post) or linear RGB (pre).
    pub fn eval_sums(&self, x: DVec3) -> (f64, [f64; 3]) {
        let mut acc = Accumulator::default();
        let n = self.particles.len();
        self.bvh.for_each_cluster_at(x, |c| {
            for i in self.boxes.members(c, n) {
                self.particles.accumulate(i, x, &mut acc);
            }
        });
        (acc.phi, acc.theta)
    }

    /// The disjoint, ordered sub-intervals of `[t0, t1]` along a ray that cross any cluster
    /// box: outside them the field is 0.
    pub fn occupied_intervals(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        out: &mut Vec<(f64, f64)>,
    ) {
        let mut hits = Vec::new();
        self.bvh.ray_boxes(origin, dir, t0, t1, &mut hits);
        hits.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        for (a, b, _) in hits {
            match out.last_mut() {
                Some(last) if a <= last.1 => last.1 = last.1.max(b),
                _ => out.push((a, b)),
            }
        }
    }

    /// Bytes of the cluster boxes and the BVH.
    pub fn structure_bytes(&self) -> usize {
        self.boxes.len() * std::mem::size_of::<Bounds>() + self.bvh.bytes()
    }

    /// The field at `x` by visiting every particle.
    pub fn eval_brute_force(&self, x: DVec3) -> Sample {
        let mut acc = Accumulator::default();
        for i in 0..self.particles.len() {
            self.particles.accumulate(i, x, &mut acc);
        }
        self.finish(acc)
    }

    /// The field at many points, in parallel, with a progress bar for long runs. Queries are
    /// visited in Hilbert order (neighbouring queries share tree nodes, about 2x faster) and
    /// the results returned in input order.
    pub fn eval_many(&self, queries: &[DVec3]) -> Vec<Sample> {
        let bounds = queries
            .iter()
            .fold(Bounds::EMPTY, |b, q| b.grown_by(q.as_vec3()));
        let as_f32: Vec<glam::Vec3> = queries.iter().map(|q| q.as_vec3()).collect();
        let order = hilbert_order(&as_f32, bounds);
        let bar = crate::progress::bar(queries.len() as u64, "evaluating");
        let chunk = 4096;
        let sorted: Vec<Sample> = order
            .par_chunks(chunk)
            .flat_map_iter(|c| {
                let r: Vec<Sample> = c.iter().map(|&i| self.eval(queries[i as usize])).collect();
                bar.inc(c.len() as u64);
                r
            })
            .collect();
        bar.finish_and_clear();
        let mut out = vec![Sample::default(); queries.len()];
        for (&i, s) in order.iter().zip(sorted) {
            out[i as usize] = s;
        }
        out
    }

    fn finish(&self, acc: Accumulator) -> Sample {
        let post = matches!(self.particles.theta, Theta::Scalar(_));
        finish_sums(acc.phi, acc.theta, post, self.particles.range)
    }
}
