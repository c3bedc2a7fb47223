//! Building the ash backend's structures: the box kernel, then the BLAS build or refit and
//! the TLAS (timed per stage), and the LBVH for the software traversal (built on the CPU by
//! [`crate::accel::lbvh`], whose stages the wgpu backend runs on the device, and uploaded).

use std::time::Instant;

use ash::vk;

use super::StructureTimings;
use super::buffers::storage;
use super::context::{NAME, device_error};
use super::pipelines::{self, Push};
use super::resources::{COMPUTE_WRITE, barrier};
use super::{AshBackend, BOX_ROW_GROUPS, TS_BLAS, TS_BOXES, TS_START, TS_TLAS};
use crate::accel::lbvh::{KeyGrid, LBVH_STACK_SIZE, Lbvh, cluster_boxes};
use crate::backend::BackendError;
use crate::backend::shaders::{RadiusRule, on_ash};

impl AshBackend {
    /// Writes the boxes, then builds (or refits) the BLAS and builds the TLAS, timed.
    pub(super) fn build_structure(&mut self, update: bool) -> Result<(), BackendError> {
        let spec = self.spec(0, 0, 0)?;
        let boxes_pipeline = pipelines::compute_pipeline(&self.ctx, on_ash::BLAS_BOXES, spec)?;
        let boxes_address = self.buffers.boxes.address;
        let structure = self
            .structure
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        // The kernel writes every box of the buffer (NaN past the step); the build takes the
        // step's clusters only (see `structure`).
        let count = structure.boxes;
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let active = up.data.cluster.clusters_for(up.data.count) as u32;
        let started = Instant::now();
        let cb = self.commands.begin()?;
        self.commands.timestamp(TS_START);
        let group = on_ash::BLAS_BOXES.point().threads();
        let row = BOX_ROW_GROUPS * group;
        self.bind(
            cb,
            vk::PipelineBindPoint::COMPUTE,
            boxes_pipeline,
            Push {
                count,
                width: row,
                ..Push::default()
            },
        );
        let groups = count.div_ceil(group);
        // SAFETY: recording with the pipeline and set bound.
        unsafe {
            self.ctx.device.cmd_dispatch(
                cb,
                groups.min(BOX_ROW_GROUPS),
                count.div_ceil(row).max(1),
                1,
            )
        };
        barrier(
            &self.ctx,
            cb,
            COMPUTE_WRITE,
            (
                vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
                vk::AccessFlags::SHADER_READ | vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR,
            ),
        );
        self.commands.timestamp(TS_BOXES);
        let commands = &self.commands;
        let structure = self.structure.as_mut().expect("checked above");
        if !update {
            structure.built = false;
        }
        structure.record(cb, boxes_address, active, update, || {
            commands.timestamp(TS_BLAS)
        })?;
        self.commands.timestamp(TS_TLAS);
        self.commands.submit_and_wait()?;
        let structure = self.structure.as_mut().expect("checked above");
        structure.built = true;
        let wall = started.elapsed();
        let c = &self.commands;
        self.structure_timings = StructureTimings {
            boxes: c.elapsed(TS_START, TS_BOXES).unwrap_or_default(),
            blas: c.elapsed(TS_BOXES, TS_BLAS).unwrap_or_default(),
            tlas: c.elapsed(TS_BLAS, TS_TLAS).unwrap_or_default(),
            refit: update,
        };
        let total = c.elapsed(TS_START, TS_TLAS).unwrap_or(wall);
        if update {
            self.timings.refit = total;
        } else {
            self.timings.build = total;
        }
        Ok(())
    }

    /// Builds the LBVH over the uploaded particles and current radii (on the CPU, from the
    /// particles the device prepared, by the shaders' radius rule) and uploads it, unless it is
    /// current.
    pub(super) fn ensure_lbvh(&mut self) -> Result<(), BackendError> {
        if self.lbvh.is_some() {
            return Ok(());
        }
        let up = self
            .uploaded
            .as_ref()
            .ok_or(BackendError::NothingUploaded(NAME))?;
        let d = &up.data;
        let n = d.count as u64;
        let points: Vec<[f32; 4]> =
            bytemuck::pod_collect_to_vec(&self.buffers.points.read(n * 16)?);
        let radius: Option<Vec<f32>> = match d.has_radius_attribute {
            true => Some(bytemuck::pod_collect_to_vec(
                &self.buffers.radius.read(n * 4)?,
            )),
            false => None,
        };
        let rule = RadiusRule {
            field: d.field,
            radius_table: d.radius_map_varies.then_some(&d.tables.radius[..]),
            radius_attribute: radius.as_deref(),
        };
        let boxes = cluster_boxes(&points, d.cluster.get(), |p, i| rule.radius(p, i));
        let tree = Lbvh::build(&boxes, &KeyGrid::new(up.series_bounds, d.origin));
        if tree.depth > LBVH_STACK_SIZE {
            return Err(device_error(
                "building the LBVH",
                format!("depth {} exceeds the traversal stack", tree.depth),
            ));
        }
        let nodes: &[u8] = bytemuck::cast_slice(&tree.nodes);
        let box_bytes: &[u8] = bytemuck::cast_slice(&boxes);
        let range = self.ctx.info.max_storage_buffer_range;
        if nodes.len().max(box_bytes.len()) as u64 > range {
            return Err(device_error(
                "building the LBVH",
                format!(
                    "{} clusters exceed this device's storage-buffer limit \
                     (maxStorageBufferRange = {} MiB); use a larger cluster size",
                    boxes.len(),
                    range >> 20
                ),
            ));
        }
        let mut rebind = false;
        if nodes.len() as u64 > self.buffers.lbvh_nodes.size {
            self.buffers.lbvh_nodes = storage(&self.ctx, "LBVH nodes", nodes.len() as u64)?;
            rebind = true;
        }
        if box_bytes.len() as u64 > self.buffers.lbvh_boxes.size {
            self.buffers.lbvh_boxes = storage(&self.ctx, "LBVH boxes", box_bytes.len() as u64)?;
            rebind = true;
        }
        self.buffers.lbvh_nodes.write(0, nodes)?;
        self.buffers.lbvh_boxes.write(0, box_bytes)?;
        if rebind {
            self.write_descriptors();
        }
        self.lbvh = Some(tree);
        Ok(())
    }
}
