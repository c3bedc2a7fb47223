//! One frame on the wgpu backend: the accumulation (split like the particles when large),
//! the blue-noise mask, the frame constants, and a frame kernel over 8x8 tiles: the
//! integrators' (`lbvh_render.comp`) or Knoll et al.'s splatter's (`lbvh_splat.comp`), both
//! adding to the same accumulation.

use std::time::Instant;

use super::context::{GpuContext, Layout, device_error};
use super::util::{self, PARTS, SplitBuffer, bind, dispatch, grid, parts_needed, storage, write};
use super::{Accumulation, WgpuBackend};
use crate::backend::BackendError;
use crate::backend::shaders::GpuFrame;
use crate::backend::shaders::{Entry, on_wgpu};
use crate::noise::BlueNoiseMask;
use crate::values::FrameParams;
use crate::values::shader_constants::{STBN_DEPTH, STBN_HEIGHT, STBN_WIDTH, spec};

/// What a frame runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameKernel {
    /// The frame's integrator (`lbvh_render.comp`).
    Integrator,
    /// The splatter with at most `k` hits per slab (`lbvh_splat.comp`).
    Splat { k: usize },
}

impl WgpuBackend {
    pub(super) fn run_render(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        self.run_frame(frame, FrameKernel::Integrator)
    }

    /// One splatter frame with at most `k` hits per slab (1 ..= `SPLAT_K_MAX`: the slab's
    /// buffer is the kernel's private array).
    pub(super) fn run_splat(&mut self, frame: &FrameParams, k: usize) -> Result<(), BackendError> {
        crate::backend::check_gpu_splat_k("wgpu", k)?;
        self.run_frame(frame, FrameKernel::Splat { k })
    }

    fn run_frame(&mut self, frame: &FrameParams, kernel: FrameKernel) -> Result<(), BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        self.built_scene()?;
        self.ensure_accumulation(frame.width, frame.height)?;
        // The splatter uses no noise: a scene that only splats never uploads the mask.
        if kernel == FrameKernel::Integrator {
            self.ensure_stbn()?;
        }
        let scene = self.scene.as_ref().expect("checked above");
        let tree = self.tree.as_ref().expect("built");
        self.optical = frame.optical_table.to_vec();
        scene.write_maps(&ctx, Some(tree), &self.optical, &frame.colour_table);
        let mut gpu_frame = GpuFrame::new(frame, scene.data.origin);
        if let FrameKernel::Splat { k } = kernel {
            // shading.w carries the slab's buffer size to splat_pixel.glsl.
            gpu_frame.shading[3] = k as f32;
        }
        write(&ctx, &self.frame_uniform, bytemuck::bytes_of(&gpu_frame));
        let sums = &self.accumulation.as_ref().expect("made above").sums;
        let layout = Layout::of(&[&scene.particles, &tree.nodes, &tree.boxes, sums]);
        let mut variant = scene.variant(frame.integrator, frame.colour, frame.noise);
        let (pipeline_kernel, label) = match kernel {
            FrameKernel::Integrator => (on_wgpu::LBVH_RENDER, "lbvh render"),
            FrameKernel::Splat { .. } => {
                // The splatter reads neither the integrator nor the noise: one variant serves
                // every frame setting of a scene.
                variant[spec::INTEGRATOR] = 0;
                variant[spec::NOISE_KIND] = 0;
                (on_wgpu::LBVH_SPLAT, "lbvh splat")
            }
        };
        let pipeline = ctx.pipeline(pipeline_kernel, Some(variant), layout)?;
        let acc = self.accumulation.as_mut().expect("made above");
        // The splatter stores the first frame's pixels rather than adding them to cleared sums
        // (as the ash backend's kernels do): every pixel is written, so no clear is needed, and
        // a pixel the kernel missed keeps what the buffer held (tests poison it with NaN).
        let store_first = matches!(kernel, FrameKernel::Splat { .. }) && acc.clear;
        let dispatched = write_tiling(
            &ctx,
            &self.tiling_uniform,
            pipeline_kernel,
            (frame.width, frame.height),
            acc.sums.part_len(16),
            store_first,
        );
        let stbn = self.stbn.as_ref();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped(label, || {
            let mut entries = scene.traversal_entries(tree, &self.dummy, layout);
            entries.extend([
                (0, self.frame_uniform.as_entire_binding()),
                (9, self.tiling_uniform.as_entire_binding()),
            ]);
            if kernel == FrameKernel::Integrator {
                let stbn = stbn.expect("made above");
                entries.push((7, stbn.as_entire_binding()));
            }
            entries.extend(acc.sums.entries(22, layout));
            let bg = bind(&ctx, &pipeline, &entries);
            if acc.clear {
                if !store_first {
                    acc.sums.clear(&mut encoder);
                }
                acc.frames = 0;
                acc.clear = false;
            }
            dispatch(
                &mut encoder,
                label,
                &pipeline,
                &bg,
                grid(u64::from(dispatched), 1),
            );
        })?;
        let device_time = util::submit_and_time(&ctx, label, encoder)?;
        acc.frames += 1;
        self.timings.frame = device_time.unwrap_or_else(|| started.elapsed());
        Ok(())
    }
    /// Makes the accumulation for `w` x `h` frames (a new size restarts it), or refuses an
    /// image whose sums outgrow the accumulation's parts.
    pub(super) fn ensure_accumulation(&mut self, w: u32, h: u32) -> Result<(), BackendError> {
        let ctx = self.ctx.clone();
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
        Ok(())
    }

    /// Uploads the blue-noise mask the first time an integrator needs it.
    pub(super) fn ensure_stbn(&mut self) -> Result<(), BackendError> {
        if self.stbn.is_some() {
            return Ok(());
        }
        let ctx = self.ctx.clone();
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
        Ok(())
    }
}

/// Writes a frame kernel's tiling (`TilingBlock` in the shaders) to `uniform`: a `w` x `h`
/// frame in tiles of `kernel`'s workgroup size, [`util::interleave`]d, the accumulation's part
/// length `acc_part` and whether the frame stores its pixels rather than adding them. Returns
/// the workgroups to dispatch.
pub(super) fn write_tiling(
    ctx: &GpuContext,
    uniform: &wgpu::Buffer,
    kernel: Entry,
    (w, h): (u32, u32),
    acc_part: u32,
    store_first: bool,
) -> u32 {
    let [group_x, group_y, _] = kernel.point().workgroup_size;
    let tiles_x = w.div_ceil(group_x);
    let tiles = tiles_x * h.div_ceil(group_y);
    let (blocks, per_block, dispatched) = util::interleave(tiles);
    let tiling = [
        tiles_x,
        tiles,
        blocks,
        per_block,
        acc_part,
        u32::from(store_first),
        0,
        0,
    ];
    write(ctx, uniform, bytemuck::cast_slice(&tiling));
    dispatched
}
