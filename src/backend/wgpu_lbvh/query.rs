//! Field queries on the wgpu backend: points (hi/lo pairs with double-single positions) in
//! chunks through the query kernel, Phi and the Theta numerator back.

use std::time::Instant;

use glam::DVec3;

use super::context::Layout;
use super::util::{self, bind, dispatch, grid, storage, uniform, write};
use super::{QUERY_CHUNK, WgpuBackend};
use crate::backend::BackendError;
use crate::backend::shaders::on_wgpu;
use crate::values::{Integrator, NoiseKind};

impl WgpuBackend {
    pub(super) fn run_query(
        &mut self,
        points: &[DVec3],
    ) -> Result<Vec<(f64, [f64; 3])>, BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        if points.is_empty() {
            return Ok(Vec::new());
        }
        // A query point is one vec4, or with double-single positions two (hi, lo).
        let per_point = if self
            .scene
            .as_ref()
            .expect("checked above")
            .data
            .double_single()
        {
            2
        } else {
            1
        };
        let chunk = QUERY_CHUNK
            .min((self.max_binding / (16 * per_point as u64)) as usize)
            .min(points.len());
        if self
            .query_buffers
            .as_ref()
            .is_none_or(|q| q.0 < chunk || q.2.size() < (chunk * per_point) as u64 * 16)
        {
            self.query_buffers = Some(ctx.scoped("query buffers", || {
                (
                    chunk,
                    uniform(&ctx, "query count", 16),
                    storage(&ctx, "query points", (chunk * per_point) as u64 * 16),
                    storage(&ctx, "query results", chunk as u64 * 16),
                )
            })?);
        }
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self
            .tree
            .as_ref()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        let (_, count_buffer, points_buffer, results_buffer) =
            self.query_buffers.as_ref().expect("made above");
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes]);
        let pipeline = ctx.pipeline(
            on_wgpu::LBVH_QUERY,
            Some(scene.variant(Integrator::Ea, scene.colour_mode(), NoiseKind::Stbn)),
            layout,
        )?;
        let bg = ctx.scoped("query bind group", || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, count_buffer.as_entire_binding()),
                (7, points_buffer.as_entire_binding()),
                (8, results_buffer.as_entire_binding()),
            ]);
            bind(&ctx, &pipeline, &entries)
        })?;
        let mut out = Vec::with_capacity(points.len());
        let mut bytes = Vec::new();
        // The chunks' dispatches on the device's clock, where it has one.
        let mut device_time: Option<std::time::Duration> = None;
        let mut local: Vec<[f32; 4]> = Vec::with_capacity(chunk * per_point);
        for part in points.chunks(chunk) {
            local.clear();
            for &x in part {
                scene.data.push_query(x, &mut local);
            }
            write(&ctx, points_buffer, bytemuck::cast_slice(&local));
            let groups = (part.len() as u32).div_ceil(on_wgpu::LBVH_QUERY.point().threads());
            let (blocks, per_block, dispatched) = util::interleave(groups);
            write(
                &ctx,
                count_buffer,
                bytemuck::cast_slice(&[part.len() as u32, groups, blocks, per_block]),
            );
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let span = util::DeviceSpan::begin(&ctx, &mut encoder);
            ctx.scoped("query", || {
                dispatch(
                    &mut encoder,
                    "lbvh query",
                    &pipeline,
                    &bg,
                    grid(u64::from(dispatched), 1),
                );
            })?;
            if let Some(span) = &span {
                span.end(&mut encoder);
            }
            bytes.clear();
            util::read_into(
                &ctx,
                Some(encoder),
                results_buffer,
                0,
                part.len() as u64 * 16,
                &mut bytes,
            )?;
            if let Some(span) = span {
                *device_time.get_or_insert_default() += span.read(&ctx)?;
            }
            let values: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&bytes);
            out.extend(values.iter().map(|v| {
                (
                    f64::from(v[0]),
                    [f64::from(v[1]), f64::from(v[2]), f64::from(v[3])],
                )
            }));
        }
        self.timings.query = device_time.unwrap_or_else(|| started.elapsed());
        Ok(out)
    }
}
