//! Running the ash backend's kernels: specialisation constants, pipelines and binding tables,
//! push constants, and one timed launch of the RT pipeline or a compute kernel.

use std::time::Duration;

use ash::vk;

use super::context::NAME;
use super::context::RtProgram;
use super::pipelines::{self, BindingTable, Push};
use super::resources::{TRANSFER_WRITE, barrier};
use super::{AshBackend, HitReports, QUERY_WIDTH, TS_END, TS_START, Traversal};
use crate::backend::BackendError;
use crate::backend::shaders::SpecConstants;
use crate::backend::shaders::{Entry, on_ash};
use crate::field::Classification;
use crate::values::ColourMode;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Launch {
    Query,
    Render,
    /// A frame of Knoll et al.'s splatter.
    Splat,
    /// A frame over the voxel baseline's grid (a compute kernel whatever the traversal).
    Voxels,
    /// A brick's share or optical depth (`owned.rgen`; `lbvh_owned.comp` with the LBVH).
    Owned,
}

impl AshBackend {
    /// The specialisation constants for the uploaded step and the given frame settings.
    pub(super) fn spec(
        &self,
        integrator: u32,
        colour: u32,
        noise: u32,
    ) -> Result<SpecConstants, BackendError> {
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let d = &up.data;
        Ok(SpecConstants {
            integrator,
            colour_mode: colour,
            noise_kind: noise,
            cluster_size: d.cluster.get() as u32,
            radius_map_varies: u32::from(d.radius_map_varies),
            density_map_varies: u32::from(d.density_map_varies),
            has_radius_attribute: u32::from(d.has_radius_attribute),
            position_ds: u32::from(d.double_single()),
            rt_hit_per_particle: u32::from(self.hit_reports == HitReports::PerParticle),
            compensated_sum: u32::from(d.compensated()),
            kernel: d.kernel.id(),
        })
    }

    /// The colour mode a query uses: what Theta's numerator sums for this field.
    pub(super) fn query_colour(&self) -> u32 {
        let field = self.uploaded.as_ref().map(|u| &u.field);
        SpecConstants::colour_id(match field {
            Some(f) if f.attribute.is_none() => ColourMode::Density,
            Some(f) if f.classification == Classification::Pre => ColourMode::Pre,
            _ => ColourMode::Post,
        })
    }

    /// The RT pipeline and binding table of `program` for `spec`.
    pub(super) fn rt(
        &mut self,
        spec: SpecConstants,
        program: RtProgram,
    ) -> Result<(vk::Pipeline, &BindingTable), BackendError> {
        let pipeline = pipelines::rt_pipeline(&self.ctx, spec, program)?;
        let key = (spec, program);
        if !self.binding_tables.contains_key(&key) {
            let table = BindingTable::new(&self.ctx, pipeline, program)?;
            self.binding_tables.insert(key, table);
        }
        Ok((pipeline, &self.binding_tables[&key]))
    }

    pub(super) fn bind(
        &self,
        cb: vk::CommandBuffer,
        point: vk::PipelineBindPoint,
        pipeline: vk::Pipeline,
        push: Push,
    ) {
        let push = Push {
            particle_address: self.buffers.points.address,
            radius_address: self.buffers.radius.address,
            boxes_address: self.buffers.boxes.address,
            accum_address: self.buffers.accum.address,
            particle_lo_address: self.buffers.points_lo.address,
            voxel_address: self.voxels.as_ref().map_or(0, |v| v.address()),
            ..push
        };
        let device = &self.ctx.device;
        // SAFETY: recording; the set matches the pipeline layout.
        unsafe {
            device.cmd_bind_pipeline(cb, point, pipeline);
            device.cmd_bind_descriptor_sets(
                cb,
                point,
                self.ctx.layouts.pipeline,
                0,
                &[self.set],
                &[],
            );
            device.cmd_push_constants(
                cb,
                self.ctx.layouts.pipeline,
                vk::ShaderStageFlags::ALL,
                0,
                bytemuck::bytes_of(&push),
            );
        }
    }

    /// Records and runs one query or render launch over `size` (queries: a count laid out in
    /// rows of `QUERY_WIDTH`; frames: pixels) with the current traversal, after filling
    /// `poison` (buffer, bytes; 0 for none) with NaN. Returns the launch's GPU time.
    pub(super) fn launch(
        &mut self,
        launch: Launch,
        spec: SpecConstants,
        push: Push,
        poison: (vk::Buffer, u64),
        size: (u32, u32),
    ) -> Result<Duration, BackendError> {
        let (w, h) = match launch {
            Launch::Query => (size.0.min(QUERY_WIDTH), size.0.div_ceil(QUERY_WIDTH)),
            Launch::Render | Launch::Splat | Launch::Voxels | Launch::Owned => size,
        };
        enum Work {
            Rays(vk::Pipeline, [vk::StridedDeviceAddressRegionKHR; 3]),
            Compute(vk::Pipeline, [u32; 2]),
        }
        let work = match self.traversal {
            _ if launch == Launch::Voxels => {
                let kind = on_ash::VOXEL_RENDER;
                let pipeline = pipelines::compute_pipeline(&self.ctx, kind, spec)?;
                Work::Compute(pipeline, groups(kind, w, h))
            }
            Traversal::RtPipeline => {
                let program = match launch {
                    Launch::Splat => RtProgram::Splat,
                    Launch::Owned => RtProgram::Owned,
                    Launch::Query | Launch::Render | Launch::Voxels => RtProgram::Field,
                };
                let (pipeline, table) = self.rt(spec, program)?;
                // The field pipeline's raygens: render, then query.
                let raygen = match launch {
                    Launch::Query => table.raygens[1],
                    Launch::Render | Launch::Splat | Launch::Voxels | Launch::Owned => {
                        table.raygens[0]
                    }
                };
                Work::Rays(pipeline, [raygen, table.miss, table.hit])
            }
            Traversal::Lbvh => {
                self.ensure_lbvh()?;
                let kind = match launch {
                    Launch::Query => on_ash::LBVH_QUERY,
                    Launch::Render => on_ash::LBVH_RENDER,
                    Launch::Splat => on_ash::LBVH_SPLAT,
                    Launch::Voxels => on_ash::VOXEL_RENDER,
                    Launch::Owned => on_ash::LBVH_OWNED,
                };
                let pipeline = pipelines::compute_pipeline(&self.ctx, kind, spec)?;
                Work::Compute(pipeline, groups(kind, w, h))
            }
        };
        let (stage, point) = match work {
            Work::Rays(..) => (
                vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR,
                vk::PipelineBindPoint::RAY_TRACING_KHR,
            ),
            Work::Compute(..) => (
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::PipelineBindPoint::COMPUTE,
            ),
        };
        let cb = self.commands.begin()?;
        if poison.1 > 0 {
            // SAFETY: recording; the buffer is alive and at least that large.
            unsafe {
                self.ctx
                    .device
                    .cmd_fill_buffer(cb, poison.0, 0, poison.1, f32::NAN.to_bits())
            };
            barrier(
                &self.ctx,
                cb,
                TRANSFER_WRITE,
                (
                    stage,
                    vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE,
                ),
            );
        }
        self.commands.timestamp(TS_START);
        match work {
            Work::Rays(pipeline, [raygen, miss, hit]) => {
                self.bind(cb, point, pipeline, push);
                // SAFETY: recording with the pipeline, set and push constants bound.
                unsafe {
                    self.ctx.rt.cmd_trace_rays(
                        cb,
                        &raygen,
                        &miss,
                        &hit,
                        &vk::StridedDeviceAddressRegionKHR::default(),
                        w,
                        h,
                        1,
                    )
                };
            }
            Work::Compute(pipeline, groups) => {
                self.bind(cb, point, pipeline, push);
                // SAFETY: as above.
                unsafe { self.ctx.device.cmd_dispatch(cb, groups[0], groups[1], 1) };
            }
        }
        self.commands.timestamp(TS_END);
        barrier(
            &self.ctx,
            cb,
            (stage, vk::AccessFlags::SHADER_WRITE),
            (
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::HOST,
                vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::HOST_READ,
            ),
        );
        self.commands.submit_and_wait()?;
        Ok(self.commands.elapsed(TS_START, TS_END).unwrap_or_default())
    }
}

/// Workgroups of `kernel` covering a `w` x `h` launch.
fn groups(kernel: Entry, w: u32, h: u32) -> [u32; 2] {
    let [x, y, _] = kernel.point().workgroup_size;
    [w.div_ceil(x), h.div_ceil(y)]
}
