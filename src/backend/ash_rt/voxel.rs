//! The voxel-grid baseline on the ash backend ([`crate::backend::voxel`]): the grid is one
//! buffer of four f32 sums per cell reached by device address (only the allocation limit
//! applies, not a binding's, so no slabs), cleared and filled in one dispatch of
//! `voxel_splat.comp` (each particle's kernel from the shared `rbf.glsl` added to the cells it
//! reaches by compare-exchange loops), and marched by `voxel_render.comp` (the shared
//! integrators with `shared/voxel_sample.glsl` as the field) into the accumulation the other
//! frame kernels fill. Both timed by the device's timestamps where it has them.

use std::time::Instant;

use ash::vk;

use super::buffers::addressed;
use super::context::{NAME, device_error};
use super::pipelines::{self, Push};
use super::resources::{Buffer, COMPUTE_READ_WRITE, COMPUTE_WRITE, TRANSFER_WRITE, barrier};
use super::{AshBackend, QUERY_WIDTH, TS_END, TS_START};
use crate::backend::BackendError;
use crate::backend::shaders::on_ash;
use crate::backend::shaders::{GpuField, GpuFrame, GpuVoxels, SpecConstants};
use crate::backend::voxel::{VoxelGeometry, VoxelGrid};
use crate::values::FrameParams;

/// The grid the backend holds.
pub(super) struct Voxels {
    geometry: VoxelGeometry,
    buffer: Buffer,
}

impl Voxels {
    pub(super) fn address(&self) -> u64 {
        self.buffer.address
    }

    pub(super) fn bytes(&self) -> usize {
        self.buffer.size as usize
    }
}

/// Where the grid's constants (`Voxels` in bindings.glsl's `Params`) start in the parameter
/// block.
pub(super) const VOXELS_OFFSET: u64 =
    (std::mem::size_of::<GpuFrame>() + std::mem::size_of::<GpuField>()) as u64;

impl AshBackend {
    pub(super) fn run_voxelize(
        &mut self,
        frame: &FrameParams,
        n: usize,
    ) -> Result<(), BackendError> {
        let started = Instant::now();
        let geometry = VoxelGeometry::new(NAME, frame.box_min, frame.box_max, n)?;
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let (origin, count) = (up.data.origin, up.data.count);
        let bytes = geometry.bytes() as u64;
        let limit = self.ctx.info.max_allocation;
        if bytes > limit {
            return Err(device_error(
                "voxelising",
                format!(
                    "a voxel grid of {:?} cells needs {} MiB, more than this device's largest \
                     allocation (maxMemoryAllocationSize = {} MiB)",
                    geometry.dims,
                    bytes >> 20,
                    limit >> 20
                ),
            ));
        }
        // The kernels index the grid's words with u32.
        if bytes / 4 > u64::from(u32::MAX) {
            return Err(device_error(
                "voxelising",
                format!(
                    "a voxel grid of {:?} cells has more than 2^32 words, which the kernels \
                     index with 32 bits",
                    geometry.dims
                ),
            ));
        }
        if self.voxels.as_ref().is_none_or(|v| v.buffer.size < bytes) {
            self.voxels = None;
            let buffer = addressed(&self.ctx, "voxel grid", bytes)?;
            self.voxels = Some(Voxels { geometry, buffer });
        }
        self.voxels.as_mut().expect("made above").geometry = geometry;
        self.write_params(Some(frame))?;
        let constants = GpuVoxels::new(&geometry, origin, geometry.dims[0] as u32, frame.colour);
        self.buffers
            .params
            .write(VOXELS_OFFSET, bytemuck::bytes_of(&constants))?;
        let spec = self.spec(0, SpecConstants::colour_id(frame.colour), 0)?;
        let pipeline = pipelines::compute_pipeline(&self.ctx, on_ash::VOXEL_SPLAT, spec)?;
        let grid = self.voxels.as_ref().expect("made above").buffer.raw;
        let count = count as u32;
        let cb = self.commands.begin()?;
        // SAFETY: recording; the buffer is alive.
        unsafe {
            self.ctx
                .device
                .cmd_fill_buffer(cb, grid, 0, vk::WHOLE_SIZE, 0)
        };
        barrier(&self.ctx, cb, TRANSFER_WRITE, COMPUTE_READ_WRITE);
        self.commands.timestamp(TS_START);
        self.bind(
            cb,
            vk::PipelineBindPoint::COMPUTE,
            pipeline,
            Push {
                count,
                width: QUERY_WIDTH,
                ..Push::default()
            },
        );
        let groups = (
            count.min(QUERY_WIDTH).div_ceil(64),
            count.div_ceil(QUERY_WIDTH),
        );
        if count > 0 {
            // SAFETY: recording with the pipeline, set and push constants bound.
            unsafe { self.ctx.device.cmd_dispatch(cb, groups.0, groups.1, 1) };
        }
        self.commands.timestamp(TS_END);
        barrier(
            &self.ctx,
            cb,
            COMPUTE_WRITE,
            (
                vk::PipelineStageFlags::COMPUTE_SHADER
                    | vk::PipelineStageFlags::TRANSFER
                    | vk::PipelineStageFlags::HOST,
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::HOST_READ,
            ),
        );
        self.commands.submit_and_wait()?;
        self.timings.voxelize = self
            .commands
            .elapsed(TS_START, TS_END)
            .filter(|_| self.ctx.info.timestamp_period.is_some())
            .unwrap_or_else(|| started.elapsed());
        Ok(())
    }

    /// The grid's sums, read back.
    pub(super) fn read_voxels(&mut self) -> Result<VoxelGrid, BackendError> {
        let voxels = self
            .voxels
            .as_mut()
            .ok_or(BackendError::NoVoxelGrid(NAME))?;
        let geometry = voxels.geometry;
        let bytes = voxels.buffer.read(geometry.bytes() as u64)?;
        Ok(VoxelGrid::from_sums(
            geometry,
            bytemuck::pod_collect_to_vec(&bytes),
        ))
    }
}
