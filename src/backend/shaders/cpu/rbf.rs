//! The CPU twin of `shaders_glsl/shared/rbf.glsl`: the particle radius rule in f32.

use crate::backend::shaders::GpuField;
use crate::values::tables::lookup;

/// How particle radii are computed: `rbf.glsl`'s `particle_radius` in f32.
#[derive(Clone, Copy, Debug)]
pub struct RadiusRule<'a> {
    pub field: GpuField,
    /// The radius-map table when the map varies (`RADIUS_MAP_VARIES`), else the constant
    /// `field.radius[1]` applies.
    pub radius_table: Option<&'a [f32]>,
    /// Per-particle radius factors (`HAS_RADIUS_ATTRIBUTE`).
    pub radius_attribute: Option<&'a [f32]>,
}

impl RadiusRule<'_> {
    pub fn radius(&self, p: [f32; 4], index: usize) -> f32 {
        let m = match self.radius_table {
            Some(t) => lookup(t, p[3]),
            None => self.field.radius[1],
        };
        let mut r = self.field.radius[0] * m;
        if let Some(h) = self.radius_attribute {
            r *= h[index];
        }
        r
    }
}
