//! A step prepared for a GPU backend: Hilbert-sorted particles in local coordinates, packed
//! the way `shaders_glsl/shared/rbf.glsl` reads them. Both GPU backends upload exactly this.

use glam::DVec3;
use rayon::prelude::*;

use super::StepInput;
use super::shaders::GpuField;
use crate::accel::{ClusterSize, hilbert_order};
use crate::field::{FieldError, FieldInputs, FieldSettings, FieldTables, normalise};
use crate::values::Step;

/// One step, ready to upload.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuStepData {
    /// Local coordinates are data coordinates minus this (the series' bounding-box centre), so
    /// f32 keeps its digits for data far from the origin.
    pub origin: DVec3,
    /// Per particle, in Hilbert order: xyz local position, w the normalised attribute t (0
    /// without an attribute).
    pub points: Vec<[f32; 4]>,
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
            radius_attribute,
            order,
            cluster: input.cluster,
            field: GpuField::default(),
            radius_map_varies: false,
            density_map_varies: false,
            tables: FieldTables::of(settings),
        };
        data.set_maps(settings);
        Ok(data)
    }

    /// Applies field settings that keep the particles (the same attribute and range): checks
    /// them with the one check every backend makes ([`FieldInputs::check`]), gathers a new
    /// radius attribute if it changed, and updates the maps. Returns whether the radius
    /// attribute changed (a backend uploads it again).
    pub fn apply_field(
        &mut self,
        step: &Step,
        old: &FieldSettings,
        new: &FieldSettings,
        series_range: Option<(f64, f64)>,
    ) -> Result<bool, FieldError> {
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
        Ok(radius_changed)
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

    /// A query point in local coordinates.
    pub fn local(&self, x: DVec3) -> [f32; 3] {
        let l = x - self.origin;
        [l.x as f32, l.y as f32, l.z as f32]
    }

    /// Bytes of particle data a GPU holds (positions with attribute, and radii when used).
    pub fn particle_bytes(&self) -> usize {
        self.points.len() * 16 + self.radius_attribute.as_ref().map_or(0, |h| h.len() * 4)
    }
}
