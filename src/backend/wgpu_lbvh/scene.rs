//! The uploaded step and its buffers: particles (and their lo parts) split over bindings as
//! they need, the radius attribute, the maps and field constants, and what each kernel binds
//! of them.

use super::context::{GpuContext, Layout, device_error};
use super::prepare::Targets;
use super::tree::GpuTree;
use super::util::{PARTS, SplitBuffer, parts_needed, storage, uniform, write};
use super::{CLUSTER_BYTES, PARTICLE_BYTES, WORD_BYTES};
use crate::accel::ClusterSize;
use crate::accel::lbvh::KeyGrid;
use crate::backend::gpu_data::{GpuStepData, StepStaging, factor_layout};
use crate::backend::shaders::{GpuField, SpecConstants, pack_map_tables};
use crate::backend::{BackendError, StepInput};
use crate::field::{Classification, FieldSettings};
use crate::values::shader_constants::{SPEC_CONSTANTS, TABLE_FLOATS};
use crate::values::{ColourMode, Integrator, NoiseKind, Step};

/// The uploaded step and its buffers.
pub(super) struct Scene {
    pub(super) step: std::sync::Arc<Step>,
    pub(super) field: FieldSettings,
    pub(super) cluster: ClusterSize,
    pub(super) series_range: Option<(f64, f64)>,
    pub(super) data: GpuStepData,
    pub(super) grid: KeyGrid,
    pub(super) particles: SplitBuffer,
    /// The lo parts of double-single positions, split like the particles (when the step has
    /// them; kernels without them bind `particles` in their place, unread).
    pub(super) particles_lo: Option<SplitBuffer>,
    pub(super) particle_capacity: usize,
    pub(super) radius_attribute: Option<wgpu::Buffer>,
    pub(super) maps: wgpu::Buffer,
    pub(super) field_uniform: wgpu::Buffer,
    /// What `maps` and `field_uniform` hold (carried with them from step to step).
    pub(super) maps_written: MapsWritten,
}

/// The bytes last written to a scene's map tables and field constants: a frame or a step
/// whose maps did not change writes nothing (a `write_buffer` is a staging allocation and a
/// copy, which a step change paid for both: docs/notes/2026-12-03-playback.md).
#[derive(Default)]
pub(super) struct MapsWritten(std::sync::Mutex<(Vec<f32>, Vec<u8>)>);

impl Scene {
    pub(super) fn clusters(&self) -> u32 {
        self.data.field.counts[1]
    }

    pub(super) fn colour_mode(&self) -> ColourMode {
        match (&self.field.attribute, self.field.classification) {
            (None, _) => ColourMode::Density,
            (Some(_), Classification::Post) => ColourMode::Post,
            (Some(_), Classification::Pre) => ColourMode::Pre,
        }
    }

    /// The GLSL kernels' specialisation constants.
    pub(super) fn variant(
        &self,
        integrator: Integrator,
        colour: ColourMode,
        noise: NoiseKind,
    ) -> [u32; SPEC_CONSTANTS.len()] {
        SpecConstants {
            integrator: SpecConstants::integrator_id(integrator),
            colour_mode: SpecConstants::colour_id(colour),
            noise_kind: SpecConstants::noise_id(noise),
            cluster_size: self.cluster.get() as u32,
            radius_map_varies: u32::from(self.data.radius_map_varies),
            density_map_varies: u32::from(self.data.density_map_varies),
            has_radius_attribute: u32::from(self.data.has_radius_attribute),
            position_ds: u32::from(self.data.double_single()),
            rt_hit_per_particle: 0,
            compensated_sum: u32::from(self.data.compensated()),
            kernel: self.data.kernel.id(),
        }
        .values()
    }

    /// The bind-group entries every kernel that traverses the tree shares: the field uniform
    /// (1), the maps (3), the radius attribute (4, `dummy` without one), the particles (10..),
    /// the tree's nodes (14..) and boxes (18..), and the particles' lo parts (26..: the
    /// particles themselves in their place, unread, without double-single positions).
    pub(super) fn traversal_entries<'a>(
        &'a self,
        tree: &'a GpuTree,
        dummy: &'a wgpu::Buffer,
        layout: Layout,
    ) -> Vec<(u32, wgpu::BindingResource<'a>)> {
        let mut entries = vec![
            (1, self.field_uniform.as_entire_binding()),
            (3, self.maps.as_entire_binding()),
            (
                4,
                self.radius_attribute
                    .as_ref()
                    .unwrap_or(dummy)
                    .as_entire_binding(),
            ),
        ];
        entries.extend(self.particles.entries(10, layout));
        entries.extend(tree.nodes.entries(14, layout));
        entries.extend(tree.boxes.entries(18, layout));
        entries.extend(
            self.particles_lo
                .as_ref()
                .unwrap_or(&self.particles)
                .entries(26, layout),
        );
        entries
    }

    /// Makes the buffer of the lo parts of double-single positions (split like the particles)
    /// the first time a step needs them (the preparation gathers into it).
    pub(super) fn ensure_points_lo(
        &mut self,
        ctx: &GpuContext,
        max_binding: u64,
    ) -> Result<(), BackendError> {
        if !self.data.double_single
            || self
                .particles_lo
                .as_ref()
                .is_some_and(|b| b.size() >= self.particles.size())
        {
            return Ok(());
        }
        let capacity = self.particle_capacity as u64;
        self.particles_lo = Some(
            ctx.scoped("particle lo parts", || {
                SplitBuffer::new(
                    ctx,
                    "particle lo parts",
                    capacity,
                    PARTICLE_BYTES,
                    max_binding,
                )
            })?
            .ok_or_else(|| device_error("the particles' lo parts do not fit their parts"))?,
        );
        Ok(())
    }

    /// Makes the radius-attribute buffer when the scene has one and it is missing or small, and
    /// drops it when the scene has none.
    pub(super) fn ensure_radius_attribute(&mut self, ctx: &GpuContext) -> Result<(), BackendError> {
        if !self.data.has_factors() {
            self.radius_attribute = None;
            return Ok(());
        }
        // Room for the radius attribute and an SPH kernel's volumes at the capacity.
        let words = crate::backend::gpu_data::factor_layout(
            self.particle_capacity.max(self.data.count),
            self.data.has_radius_attribute,
            self.data.kernel.is_sph(),
        )
        .1;
        let needed = (words.max(1) * 4) as u64;
        if self
            .radius_attribute
            .as_ref()
            .is_none_or(|b| b.size() < needed)
        {
            self.radius_attribute = Some(ctx.scoped("radius attribute buffer", || {
                storage(ctx, "radius attribute", needed)
            })?);
        }
        Ok(())
    }

    /// The preparation's targets: the particles, and the lo parts and radius attribute when
    /// the scene has them.
    pub(super) fn targets(&self) -> Targets<'_> {
        Targets {
            particles: &self.particles,
            particles_lo: self
                .particles_lo
                .as_ref()
                .filter(|_| self.data.double_single),
            radius_attribute: self
                .radius_attribute
                .as_ref()
                .filter(|_| self.data.has_factors()),
        }
    }
}

/// Whether a step of `n` particles in `clusters` clusters fits bindings of `max_binding`
/// bytes: the particles, nodes and boxes in at most [`PARTS`] parts each, the 4-byte arrays in
/// one. Err names what does not fit and what it needs.
pub(super) fn check_fits(
    n: usize,
    clusters: usize,
    factor_words: usize,
    max_binding: u64,
) -> Result<(), String> {
    let (n, c) = (n as u64, clusters as u64);
    let split = [
        ("the particles", n, PARTICLE_BYTES),
        ("the LBVH nodes", c, CLUSTER_BYTES),
        ("the cluster boxes", c, CLUSTER_BYTES),
    ];
    for (what, count, bytes) in split {
        if parts_needed(count, bytes, max_binding) > PARTS {
            return Err(format!(
                "{what} need {} bytes, more than {PARTS} x {max_binding}",
                count * bytes
            ));
        }
    }
    // The preparation sorts per particle, the build per cluster.
    let mut single = vec![
        ("the per-particle sort keys", n),
        ("the per-cluster sort keys", c),
    ];
    if factor_words > 0 {
        single.push(("the radius attribute and SPH volumes", factor_words as u64));
    }
    for (what, count) in single {
        if count * WORD_BYTES > max_binding {
            return Err(format!(
                "{what} need {} bytes in one binding, more than {max_binding}",
                count * WORD_BYTES
            ));
        }
    }
    Ok(())
}

/// The particles a step's buffers are made for: the reserved count or the largest step seen
/// (`reserved`) when that fits the bindings, so a series allocates once, else the step's own;
/// an error when the step itself does not fit.
pub(super) fn capacity_for_step(
    input: &StepInput<'_>,
    staging: &StepStaging<'_>,
    reserved: usize,
    max_binding: u64,
    device: &str,
) -> Result<usize, BackendError> {
    let n = staging.len();
    let clusters = input.cluster.clusters_for(n);
    let has_radius = staging.has_radius_attribute();
    let sph = input.field.kernel.is_sph();
    let factor_words = |n| factor_layout(n, has_radius, sph).1;
    if let Err(what) = check_fits(n, clusters, factor_words(n), max_binding) {
        return Err(device_error(format!(
            "step '{}' ({n} particles in {clusters} clusters of {}): {what}; {device} binds at \
             most {max_binding} bytes per storage buffer, and this backend splits the \
             particles, nodes and boxes over at most {PARTS} (a larger cluster size needs \
             fewer clusters)",
            input.step.name, input.cluster,
        )));
    }
    let reserved = reserved.max(n);
    let fits = check_fits(
        reserved,
        input.cluster.clusters_for(reserved),
        factor_words(reserved),
        max_binding,
    )
    .is_ok();
    Ok(if fits { reserved } else { n })
}

/// The buffers a scene keeps from step to step: the particles (and lo parts), the maps and
/// field constants with what they hold, and the radius attribute.
pub(super) struct SceneBuffers {
    pub(super) particles: SplitBuffer,
    pub(super) particles_lo: Option<SplitBuffer>,
    pub(super) particle_capacity: usize,
    pub(super) maps: wgpu::Buffer,
    pub(super) field_uniform: wgpu::Buffer,
    pub(super) maps_written: MapsWritten,
    pub(super) radius_attribute: Option<wgpu::Buffer>,
}

impl SceneBuffers {
    /// The buffers of the scene in `old`, taken from it, when they hold `n` particles; else new
    /// ones for `capacity` (`step` names the step in an error).
    pub(super) fn reuse_or_make(
        ctx: &GpuContext,
        old: &mut Option<Scene>,
        step: &str,
        n: usize,
        capacity: usize,
        max_binding: u64,
    ) -> Result<SceneBuffers, BackendError> {
        if let Some(s) = old.take_if(|s| s.particle_capacity >= n) {
            return Ok(SceneBuffers {
                particles: s.particles,
                particles_lo: s.particles_lo,
                particle_capacity: s.particle_capacity,
                maps: s.maps,
                field_uniform: s.field_uniform,
                maps_written: s.maps_written,
                radius_attribute: s.radius_attribute,
            });
        }
        let need = capacity as u64 * PARTICLE_BYTES;
        let (particles, maps, field_uniform) = ctx.scoped(
            &format!("step '{step}': particle buffers ({need} bytes for {capacity} particles)"),
            || {
                (
                    SplitBuffer::new(
                        ctx,
                        "particles",
                        capacity as u64,
                        PARTICLE_BYTES,
                        max_binding,
                    ),
                    storage(ctx, "map tables", TABLE_FLOATS as u64 * 4),
                    uniform(ctx, "field", std::mem::size_of::<GpuField>() as u64),
                )
            },
        )?;
        let particles = particles.ok_or_else(|| {
            device_error(format!("{capacity} particles do not fit {PARTS} parts"))
        })?;
        Ok(SceneBuffers {
            particles,
            particles_lo: None,
            particle_capacity: capacity,
            maps,
            field_uniform,
            maps_written: MapsWritten::default(),
            radius_attribute: None,
        })
    }
}

impl Scene {
    /// Writes the map tables (with the last frame's optical-density table) and field constants
    /// (with the part lengths of the split arrays, `shaders_glsl/wgpu/split.glsl`).
    pub(super) fn write_maps(
        &self,
        ctx: &GpuContext,
        tree: Option<&GpuTree>,
        optical: &[f32],
        colour: &[[f32; 3]],
    ) {
        let tables = pack_map_tables(
            &self.data.tables.density,
            &self.data.tables.radius,
            optical,
            colour,
        );
        let mut field = self.data.field;
        field.counts[2] = self.particles.part_len(PARTICLE_BYTES);
        field.counts[3] = tree.map_or(u32::MAX, |t| t.boxes.part_len(16));
        let field = bytemuck::bytes_of(&field);
        let mut written = self
            .maps_written
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let (old_tables, old_field) = &mut *written;
        // Bitwise: a NaN never equals itself, -0.0 equals 0.0.
        if bytemuck::cast_slice::<f32, u8>(old_tables) != bytemuck::cast_slice::<f32, u8>(&tables) {
            write(ctx, &self.maps, bytemuck::cast_slice(&tables));
            *old_tables = tables;
        }
        if old_field.as_slice() != field {
            write(ctx, &self.field_uniform, field);
            *old_field = field.to_vec();
        }
    }
}
