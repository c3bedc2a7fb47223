//! A brick's share of a distributed frame on the wgpu backend ([`Backend::render_owned`],
//! [`Backend::owned_depth`]): `lbvh_owned.comp` over the brick's rectangle, its brick, output
//! and inputs in one storage buffer ([`BrickLaunch`]), read back as f64. Nothing is
//! accumulated.
//!
//! [`Backend::render_owned`]: crate::backend::Backend::render_owned
//! [`Backend::owned_depth`]: crate::backend::Backend::owned_depth

use std::time::Instant;

use super::WgpuBackend;
use super::context::{Layout, device_error};
use super::util::{self, bind, dispatch, storage, write};
use crate::backend::BackendError;
use crate::backend::shaders::brick::BrickLaunch;
use crate::backend::shaders::on_wgpu;
use crate::values::FrameParams;

impl WgpuBackend {
    /// Runs one brick launch of `frame` (its integrator picks the kernel's variant) and returns
    /// its output's bytes.
    pub(super) fn run_owned(
        &mut self,
        frame: &FrameParams,
        launch: &BrickLaunch,
    ) -> Result<Vec<u8>, BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        if launch.rect.is_empty() {
            return Ok(Vec::new());
        }
        let bytes = launch.io.len() as u64;
        if bytes > self.max_binding {
            return Err(device_error(format!(
                "a brick of {} x {} pixels needs {bytes} bytes in one binding; {} binds at \
                 most {} bytes per storage buffer",
                launch.rect.width(),
                launch.rect.height(),
                ctx.info.name,
                self.max_binding
            )));
        }
        let groups = (
            launch.rect.width().div_ceil(8),
            launch.rect.height().div_ceil(8),
        );
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension;
        if groups.0 > max_groups || groups.1 > max_groups {
            return Err(device_error(format!(
                "a brick of {} x {} pixels needs more than {max_groups} workgroups a side",
                launch.rect.width(),
                launch.rect.height()
            )));
        }
        self.ensure_stbn()?;
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self.tree.as_ref().expect("built");
        self.optical = frame.optical_table.to_vec();
        scene.write_maps(&ctx, Some(tree), &self.optical, &frame.colour_table);
        write(&ctx, &self.frame_uniform, bytemuck::bytes_of(&launch.frame));
        let io = ctx.scoped("brick buffer", || storage(&ctx, "brick", bytes))?;
        write(&ctx, &io, &launch.io);
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes]);
        let variant = scene.variant(frame.integrator, frame.colour, frame.noise);
        let pipeline = ctx.pipeline(on_wgpu::LBVH_OWNED, Some(variant), layout)?;
        let stbn = self.stbn.as_ref().expect("made above");
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("lbvh owned", || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, self.frame_uniform.as_entire_binding()),
                (7, stbn.as_entire_binding()),
                (30, io.as_entire_binding()),
            ]);
            let bg = bind(&ctx, &pipeline, &entries);
            dispatch(&mut encoder, "lbvh owned", &pipeline, &bg, groups);
        })?;
        let device_time = util::submit_and_time(&ctx, "lbvh owned", encoder)?;
        let out = util::read(&ctx, &io, BrickLaunch::OUTPUT_OFFSET, launch.output_bytes())?;
        self.timings.frame = device_time.unwrap_or_else(|| started.elapsed());
        Ok(out)
    }
}
