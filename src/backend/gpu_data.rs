//! A step prepared for a GPU backend: Hilbert-sorted particles in local coordinates, packed
//! the way `shaders_glsl/shared/rbf.glsl` reads them. Both GPU backends upload exactly this.
//!
//! # Precision of positions
//! Local coordinates are the data's minus the series' centre, subtracted in f64, so offsets
//! from the origin cost nothing. Rounded to f32 they still carry an absolute error of up to
//! 2^-24 of the largest local coordinate, which a particle's radius may not tolerate: a
//! radius of 1e-6 of the domain makes it a 6% error of the distance. [`f32_phi_error`] bounds
//! the relative Phi error f32 positions can cause for a scene; where it exceeds the
//! tolerance asked for (see [`Precision`]), positions go to the GPU as double-single pairs, hi
//! the f32 rounding and lo the f32 remainder (about 48 bits), and the shaders compute
//! distances from both (`POSITION_DS`, `shaders_glsl/shared/rbf.glsl`). A scene that does not
//! need it uploads no lo parts and runs kernels without the extra arithmetic.

use glam::DVec3;
use rayon::prelude::*;

use super::shaders::GpuField;
use super::{Precision, StepInput};
use crate::accel::{ClusterSize, hilbert_order};
use crate::field::{
    FieldError, FieldInputs, FieldSettings, FieldTables, normalise, particle_radius,
};
use crate::values::Step;
use crate::values::tables::lookup;

/// One step, ready to upload.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuStepData {
    /// Local coordinates are data coordinates minus this (the series' bounding-box centre), so
    /// f32 keeps its digits for data far from the origin.
    pub origin: DVec3,
    /// Per particle, in Hilbert order: xyz local position (the hi part with double-single
    /// positions), w the normalised attribute t (0 without an attribute).
    pub points: Vec<[f32; 4]>,
    /// With double-single positions, per particle: xyz the lo part (local position minus hi),
    /// w 0.
    pub points_lo: Option<Vec<[f32; 4]>>,
    /// The precision asked for, and the bound on the relative Phi error f32 positions would
    /// cause in this scene (what decided `points_lo`).
    pub precision: Precision,
    pub f32_error_bound: f64,
    /// Per particle (Hilbert order): the radius attribute h, only when the scene uses one.
    pub radius_attribute: Option<Vec<f32>>,
    /// `order[k]` is the step's index of sorted particle k.
    pub order: Vec<u32>,
    pub cluster: ClusterSize,
    pub field: GpuField,
    pub radius_map_varies: bool,
    pub density_map_varies: bool,
    /// The density, radius and colour maps' tables.
    pub tables: FieldTables,
}

impl GpuStepData {
    pub fn prepare(input: &StepInput<'_>) -> Result<GpuStepData, FieldError> {
        let step = input.step;
        let settings = input.field;
        // The same checks and range as the CPU reference, so every backend refuses the same input.
        let inputs = FieldInputs::check(step, settings, input.series_range)?;
        let origin = input.series_bounds.center();
        let order = hilbert_order(&step.positions, input.series_bounds);
        let points = order
            .par_iter()
            .map(|&i| {
                let p = step.positions[i as usize] - origin;
                let t = inputs
                    .attribute
                    .map_or(0.0, |a| normalise(a.values[i as usize], inputs.range));
                [p.x as f32, p.y as f32, p.z as f32, t as f32]
            })
            .collect();
        let radius_attribute = inputs.radius.map(|h| {
            order
                .par_iter()
                .map(|&i| h.values[i as usize] as f32)
                .collect()
        });
        let mut data = GpuStepData {
            origin,
            points,
            points_lo: None,
            precision: input.precision,
            f32_error_bound: 0.0,
            radius_attribute,
            order,
            cluster: input.cluster,
            field: GpuField::default(),
            radius_map_varies: false,
            density_map_varies: false,
            tables: FieldTables::of(settings),
        };
        data.set_maps(settings);
        data.choose_precision(step, settings);
        Ok(data)
    }

    /// Applies field settings that keep the particles (the same attribute and range): checks
    /// them with the one check every backend makes ([`FieldInputs::check`]), gathers a new
    /// radius attribute if it changed, updates the maps, and chooses the positions' precision
    /// again (new radii may need double-single positions, or no longer need them). Says what
    /// a backend must upload again.
    pub fn apply_field(
        &mut self,
        step: &Step,
        old: &FieldSettings,
        new: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<Changed, FieldError> {
        let inputs = FieldInputs::check(step, new, series_range)?;
        let radius_changed = new.radius_attribute != old.radius_attribute;
        if radius_changed {
            self.radius_attribute = inputs.radius.map(|h| {
                self.order
                    .par_iter()
                    .map(|&i| h.values[i as usize] as f32)
                    .collect()
            });
        }
        self.set_maps(new);
        let had_lo = self.points_lo.is_some();
        self.choose_precision(step, new);
        Ok(Changed {
            radius_attribute: radius_changed,
            positions_lo: self.points_lo.is_some() != had_lo,
        })
    }

    /// Bounds the Phi error of f32 positions for the current radii ([`f32_phi_error`]) and
    /// makes the lo parts of double-single positions when the precision asked for needs them
    /// (dropping them when it does not).
    fn choose_precision(&mut self, step: &Step, settings: &FieldSettings) {
        let (largest, r_min, r_max) = self
            .points
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                let m = lookup(&self.tables.radius, f64::from(p[3]));
                let h = self.radius_attribute.as_ref().map(|h| f64::from(h[k]));
                let r = particle_radius(settings.radius, m, h);
                let coordinate = p[..3]
                    .iter()
                    .fold(0.0f64, |a, &c| a.max(f64::from(c).abs()));
                let positive = r > 0.0;
                (
                    coordinate,
                    if positive { r } else { f64::INFINITY },
                    if positive { r } else { 0.0 },
                )
            })
            .reduce(
                || (0.0, f64::INFINITY, 0.0),
                |a, b| (a.0.max(b.0), a.1.min(b.1), a.2.max(b.2)),
            );
        self.f32_error_bound = f32_phi_error(largest, r_min, r_max);
        let double_single = match self.precision {
            Precision::F32 => false,
            Precision::DoubleSingle => true,
            Precision::Auto { tolerance } => self.f32_error_bound > tolerance,
        };
        if !double_single {
            self.points_lo = None;
        } else if self.points_lo.is_none() {
            let origin = self.origin;
            self.points_lo = Some(
                self.order
                    .par_iter()
                    .zip(&self.points)
                    .map(|(&i, hi)| {
                        let local = step.positions[i as usize] - origin;
                        [
                            (local.x - f64::from(hi[0])) as f32,
                            (local.y - f64::from(hi[1])) as f32,
                            (local.z - f64::from(hi[2])) as f32,
                            0.0,
                        ]
                    })
                    .collect(),
            );
        }
    }

    /// Whether positions are double-single pairs (`POSITION_DS`).
    pub fn double_single(&self) -> bool {
        self.points_lo.is_some()
    }

    /// How the positions are held, for [`super::Backend::positions`].
    pub fn positions(&self) -> super::Positions {
        if self.double_single() {
            super::Positions::DoubleSingle {
                f32_error_bound: self.f32_error_bound,
            }
        } else {
            super::Positions::F32 {
                error_bound: self.f32_error_bound,
            }
        }
    }

    /// A query point as the query kernels read it: one vec4 (local coordinates, f32), or with
    /// double-single positions two (hi, then lo).
    pub fn push_query(&self, x: DVec3, out: &mut Vec<[f32; 4]>) {
        let l = x - self.origin;
        let hi = [l.x as f32, l.y as f32, l.z as f32, 0.0];
        out.push(hi);
        if self.double_single() {
            out.push([
                (l.x - f64::from(hi[0])) as f32,
                (l.y - f64::from(hi[1])) as f32,
                (l.z - f64::from(hi[2])) as f32,
                0.0,
            ]);
        }
    }

    /// Updates everything that depends on the maps and the global radius (not the particles).
    pub fn set_maps(&mut self, settings: &FieldSettings) {
        let n = self.points.len();
        self.tables = FieldTables::of(settings);
        self.radius_map_varies = !settings.radius_map.0.is_constant();
        self.density_map_varies = !settings.density_map.0.is_constant();
        self.field = GpuField {
            radius: [
                settings.radius as f32,
                self.tables.radius[0],
                self.tables.density[0],
                0.0,
            ],
            counts: [n as u32, self.cluster.clusters_for(n) as u32, 0, 0],
        };
    }

    /// Bytes of particle data a GPU holds (positions with attribute, their lo parts and radii
    /// when used).
    pub fn particle_bytes(&self) -> usize {
        self.points.len() * 16
            + self.points_lo.as_ref().map_or(0, |lo| lo.len() * 16)
            + self.radius_attribute.as_ref().map_or(0, |h| h.len() * 4)
    }
}

/// What [`GpuStepData::apply_field`] changed that a backend must upload again.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Changed {
    pub radius_attribute: bool,
    /// The lo parts of the positions appeared or went (the precision changed).
    pub positions_lo: bool,
}

/// A bound on the relative error of Phi that rounding local positions to f32 causes, for
/// particles with local coordinates up to `largest` (in magnitude) and radii `r_min` ..
/// `r_max` (the positive ones). A query point within reach of a particle has coordinates up to
/// `largest + r_max`; each coordinate of it and of the particle is rounded by up to 2^-24 of
/// its magnitude, so their distance d by up to `δ = √3 · 2^-24 · (2 largest + r_max)`. Phi's
/// term `w exp(-4.5 d² / r²)` then changes by a factor of up to `exp(9 d δ / r²)`, at most
/// `9 δ / r_min` relative for d ≤ r. (The rest of the f32 arithmetic, the exponential and the
/// sum, adds about 1e-6 whatever the positions.)
pub fn f32_phi_error(largest: f64, r_min: f64, r_max: f64) -> f64 {
    if !(r_min.is_finite() && r_min > 0.0) {
        return 0.0;
    }
    let delta = 3f64.sqrt() * f64::from(f32::EPSILON) * 0.5 * (2.0 * largest + r_max);
    9.0 * delta / r_min
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::DVec3;
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::values::{Attribute, Bounds};

    /// `n` particles uniform in a cube of side `side` centred at `offset`, written as f64 the
    /// way a simulation would (no f32-exact coordinates).
    fn cube(n: usize, side: f64, offset: f64) -> Arc<Step> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let positions: Vec<DVec3> = (0..n)
            .map(|_| {
                DVec3::new(rng.random(), rng.random(), rng.random()) * side + DVec3::splat(offset)
            })
            .collect();
        let values = (0..n).map(|_| rng.random::<f64>()).collect();
        Arc::new(Step {
            name: "cube".into(),
            positions,
            attributes: vec![Attribute {
                name: "s".into(),
                values,
            }],
        })
    }

    fn prepared(step: &Arc<Step>, radius: f64, precision: Precision) -> GpuStepData {
        let field = FieldSettings::new(Some("s"), radius);
        GpuStepData::prepare(&StepInput {
            step,
            field: &field,
            cluster: ClusterSize::new(1).unwrap(),
            series_bounds: Bounds::of_points(&step.positions),
            series_range: Some((0.0, 1.0)),
            precision,
        })
        .unwrap()
    }

    /// A scene pays for double-single positions only when its radii and extent need them: an
    /// image of a unit-cube scene at a radius of 2% of the domain stays in f32 (16 B a
    /// particle), the same scene asked for field values at 1e-5 needs the pairs, and so does
    /// an image whose radii are 1e-6 of the domain, or whose domain lies at 1e6 with radii
    /// of 1e-4 (offsets alone cost nothing: local coordinates remove them).
    #[test]
    fn auto_precision_pays_for_pairs_only_where_the_scene_needs_them() {
        let unit = cube(2000, 1.0, 0.0);
        let image = prepared(&unit, 0.02, Precision::RENDER);
        assert!(!image.double_single(), "bound {}", image.f32_error_bound);
        assert_eq!(image.particle_bytes(), 2000 * 16);
        let field = prepared(&unit, 0.02, Precision::FIELD);
        assert!(field.double_single(), "bound {}", field.f32_error_bound);
        assert_eq!(field.particle_bytes(), 2000 * 32);
        assert!(prepared(&unit, 1e-6, Precision::RENDER).double_single());

        let far = cube(2000, 1.0, 1e6);
        let far_image = prepared(&far, 0.02, Precision::RENDER);
        assert!(!far_image.double_single(), "an offset alone needs no pairs");
        assert!(
            (far_image.f32_error_bound - image.f32_error_bound).abs()
                < 1e-3 * image.f32_error_bound,
            "the bound depends on the local extent, not the offset: {} vs {}",
            far_image.f32_error_bound,
            image.f32_error_bound
        );
        assert!(prepared(&far, 1e-4, Precision::RENDER).double_single());

        // The pairs hold what f32 loses: hi + lo equals the f64 local position to ~48 bits.
        let pairs = prepared(&far, 1e-4, Precision::RENDER);
        let lo = pairs.points_lo.as_ref().unwrap();
        for (k, &i) in pairs.order.iter().enumerate().step_by(97) {
            let local = far.positions[i as usize] - pairs.origin;
            for a in 0..3 {
                let sum = f64::from(pairs.points[k][a]) + f64::from(lo[k][a]);
                assert!((sum - local[a]).abs() <= 1e-13, "{sum} vs {}", local[a]);
            }
        }
        // Forced precisions are obeyed either way.
        assert!(!prepared(&unit, 1e-6, Precision::F32).double_single());
        assert!(prepared(&unit, 0.5, Precision::DoubleSingle).double_single());
    }
}
