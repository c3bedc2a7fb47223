//! One frame on the wgpu backend: the accumulation (split like the particles when large),
//! the blue-noise mask, the frame constants, and the render kernel over 8x8 tiles.

use std::time::Instant;

use super::context::{Kernel, Layout, device_error};
use super::util::{self, PARTS, SplitBuffer, bind, dispatch, grid, parts_needed, storage, write};
use super::{Accumulation, WgpuBackend};
use crate::backend::BackendError;
use crate::backend::shaders::GpuFrame;
use crate::noise::BlueNoiseMask;
use crate::values::FrameParams;
use crate::values::shader_constants::{STBN_DEPTH, STBN_HEIGHT, STBN_WIDTH};

impl WgpuBackend {
    pub(super) fn run_render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        let (w, h) = (frame.width, frame.height);
        let bytes = u64::from(w) * u64::from(h) * 16;
        let pixels = u64::from(w) * u64::from(h);
        if parts_needed(pixels, 16, self.max_binding) > PARTS {
            return Err(device_error(format!(
                "a {w}x{h} image needs {bytes} bytes of accumulation, more than {PARTS} x {}; \
                 {} binds at most {} bytes per storage buffer",
                self.max_binding, ctx.info.name, self.max_binding
            )));
        }
        if self
            .accumulation
            .as_ref()
            .is_none_or(|a| a.width != w || a.height != h)
        {
            self.accumulation = None;
            let max_binding = self.max_binding;
            let sums = ctx
                .scoped(&format!("accumulation buffer ({bytes} bytes)"), || {
                    SplitBuffer::new(&ctx, "accumulation", pixels, 16, max_binding)
                })?
                .ok_or_else(|| device_error("the accumulation does not fit its parts"))?;
            self.accumulation = Some(Accumulation {
                width: w,
                height: h,
                frames: 0,
                sums,
                clear: true,
            });
        }
        if self.stbn.is_none() {
            let mask = BlueNoiseMask::builtin();
            if (mask.width, mask.height, mask.depth) != (STBN_WIDTH, STBN_HEIGHT, STBN_DEPTH) {
                return Err(device_error(format!(
                    "the shaders expect a 128x128x64 blue-noise mask, not {}x{}x{}",
                    mask.width, mask.height, mask.depth
                )));
            }
            let words = mask.packed_words();
            let buffer = ctx.scoped("blue-noise mask", || {
                storage(&ctx, "stbn mask", words.len() as u64 * 4)
            })?;
            write(&ctx, &buffer, bytemuck::cast_slice(&words));
            self.stbn = Some(buffer);
        }
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self.tree.as_ref().expect("built");
        self.optical = frame.optical_table.to_vec();
        scene.write_maps(&ctx, Some(tree), &self.optical, &frame.colour_table);
        write(
            &ctx,
            &self.frame_uniform,
            bytemuck::bytes_of(&GpuFrame::new(frame, scene.data.origin)),
        );
        let sums = &self.accumulation.as_ref().expect("made above").sums;
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes, sums]);
        let pipeline = ctx.pipeline(
            Kernel::Render,
            Some(scene.variant(frame.integrator, frame.colour, frame.noise)),
            layout,
        )?;
        let tiles_x = w.div_ceil(8);
        let tiles = tiles_x * h.div_ceil(8);
        let (blocks, per_block, dispatched) = util::interleave(tiles);
        let acc_part = self
            .accumulation
            .as_ref()
            .map_or(u32::MAX, |a| a.sums.part_len(16));
        write(
            &ctx,
            &self.tiling_uniform,
            bytemuck::cast_slice(&[tiles_x, tiles, blocks, per_block, acc_part, 0, 0, 0]),
        );
        let acc = self.accumulation.as_mut().expect("made above");
        let stbn = self.stbn.as_ref().expect("made above");
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("render", || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, self.frame_uniform.as_entire_binding()),
                (7, stbn.as_entire_binding()),
                (9, self.tiling_uniform.as_entire_binding()),
            ]);
            entries.extend(acc.sums.entries(22, layout));
            let bg = bind(&ctx, &pipeline, &entries);
            if acc.clear {
                acc.sums.clear(&mut encoder);
                acc.frames = 0;
                acc.clear = false;
            }
            dispatch(
                &mut encoder,
                "lbvh render",
                &pipeline,
                &bg,
                grid(u64::from(dispatched), 1),
            );
        })?;
        util::submit_and_wait(&ctx, "render", encoder)?;
        acc.frames += 1;
        self.timings.frame = started.elapsed();
        Ok(())
    }
}
