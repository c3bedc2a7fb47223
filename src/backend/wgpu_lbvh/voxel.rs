//! The voxel-grid baseline on the wgpu backend ([`crate::backend::voxel`]): the grid is a 3D
//! texture of the sums (rgba32float: Phi and the Theta numerator per cell centre), filled slab
//! by slab along z. For each slab the slab buffer is cleared, `voxel_particles.comp` writes each
//! particle as the kernel sees it (the shared map and RBF code), `voxel_splat.wgsl` adds each
//! particle's kernel to the slab's cells with f32 atomic adds (compare-exchange loops), and the
//! slab is copied into the texture. A slab holds what one storage binding does (128 MiB on
//! lavapipe: a 512³ grid is 2 GiB, 16 slabs); the texture holds the whole grid, where the
//! device's 3D-texture limit allows. `voxel_render.comp` marches the texture with the shared
//! integrators (trilinear between cell centres: `shared/voxel_sample.glsl`) into the
//! accumulation the other frame kernels fill. All of a voxelisation is one submission, timed on
//! the device where it has timestamps.

use std::time::Instant;

use super::WgpuBackend;
use super::context::{Layout, device_error};
use super::render::write_tiling;
use super::util::{self, bind, dispatch, grid, storage, write};
use crate::backend::BackendError;
use crate::backend::shaders::on_wgpu;
use crate::backend::shaders::{GpuFrame, GpuVoxels};
use crate::backend::voxel::{VoxelGeometry, VoxelGrid};
use crate::values::FrameParams;
use crate::values::shader_constants::spec;

/// Bytes per cell of the grid and of the slab buffer (four f32 sums).
const CELL_BYTES: u64 = 16;
/// Bytes per particle of the first pass's output (two vec4s).
const SPLAT_BYTES: u64 = 32;
/// Rows of a buffer-to-texture copy start at multiples of this many bytes (WebGPU's
/// `COPY_BYTES_PER_ROW_ALIGNMENT`), so the slab buffer's rows are padded to it.
const ROW_ALIGNMENT: u64 = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64;

/// The grid the backend holds: its geometry, the texture of its sums, and the uniform the
/// march reads.
pub(super) struct Voxels {
    geometry: VoxelGeometry,
    texture: wgpu::Texture,
    view: wgpu::TextureView,
    march_uniform: wgpu::Buffer,
}

/// Buffers the splat reuses between voxelisations: the slab, the particles as the kernel
/// sees them, and the passes' uniform entries, each kept at the largest size used.
#[derive(Default)]
pub(super) struct SplatBuffers {
    slab: Option<wgpu::Buffer>,
    splats: Option<wgpu::Buffer>,
    ranges: Option<wgpu::Buffer>,
}

/// Cells per row of the slab buffer: the grid's row padded to the copy alignment.
fn row_cells(dims: [usize; 3]) -> u64 {
    (dims[0] as u64 * CELL_BYTES).next_multiple_of(ROW_ALIGNMENT) / CELL_BYTES
}

/// Makes `slot` a buffer of at least `bytes` (by `make`) unless it is one.
fn buffer_at_least(
    ctx: &super::GpuContext,
    slot: &mut Option<wgpu::Buffer>,
    label: &str,
    bytes: u64,
    make: fn(&super::GpuContext, &str, u64) -> wgpu::Buffer,
) -> Result<(), BackendError> {
    if slot.as_ref().is_none_or(|b| b.size() < bytes) {
        *slot = None;
        *slot = Some(ctx.scoped(&format!("{label} ({bytes} bytes)"), || {
            make(ctx, label, bytes)
        })?);
    }
    Ok(())
}

/// How a voxelisation covers the grid: slabs of whole layers along z, each as large as one
/// storage binding holds, and chunks of particles, each as many splats as one binding holds;
/// one pass per (slab, chunk).
struct SlabPlan {
    dims: [usize; 3],
    /// Cells per row of the slab buffer ([`row_cells`]).
    row: u64,
    layer_bytes: u64,
    layers_per_slab: usize,
    slabs: usize,
    /// Particles.
    count: usize,
    /// Particles per chunk.
    chunk: usize,
    chunks: usize,
}

impl SlabPlan {
    /// The plan for a grid of `dims` cells and `count` particles, or why the device cannot
    /// hold the grid.
    fn new(
        ctx: &super::GpuContext,
        dims: [usize; 3],
        count: usize,
        max_binding: u64,
    ) -> Result<SlabPlan, BackendError> {
        let max_3d = u64::from(ctx.limits.max_texture_dimension_3d);
        if dims.iter().any(|&d| d as u64 > max_3d) {
            return Err(device_error(format!(
                "a voxel grid of {dims:?} cells does not fit a 3D texture: {} allows at most \
                 {max_3d} texels along each side (max_texture_dimension_3d)",
                ctx.info.name
            )));
        }
        let row = row_cells(dims);
        let layer_bytes = row * dims[1] as u64 * CELL_BYTES;
        if layer_bytes > max_binding {
            return Err(device_error(format!(
                "one layer of a {dims:?} voxel grid needs {layer_bytes} bytes of slab buffer, \
                 more than the {max_binding} bytes {} binds per storage buffer",
                ctx.info.name
            )));
        }
        let layers_per_slab = (max_binding / layer_bytes).min(dims[2] as u64) as usize;
        let chunk = ((max_binding / SPLAT_BYTES) as usize).min(count).max(1);
        Ok(SlabPlan {
            dims,
            row,
            layer_bytes,
            layers_per_slab,
            slabs: dims[2].div_ceil(layers_per_slab),
            count,
            chunk,
            chunks: count.div_ceil(chunk),
        })
    }

    /// Slab `s`'s first layer and its number of layers.
    fn layers(&self, s: usize) -> (usize, usize) {
        let first_layer = s * self.layers_per_slab;
        (
            first_layer,
            self.layers_per_slab.min(self.dims[2] - first_layer),
        )
    }

    /// Chunk `c`'s first particle and its number of particles.
    fn particles(&self, c: usize) -> (usize, usize) {
        let first = c * self.chunk;
        (first, self.chunk.min(self.count - first))
    }
}

/// Records the copy of slab buffer `slab` (`layers` layers) into the grid's texture from
/// layer `first_layer` on.
fn copy_slab(
    encoder: &mut wgpu::CommandEncoder,
    slab: &wgpu::Buffer,
    texture: &wgpu::Texture,
    plan: &SlabPlan,
    first_layer: usize,
    layers: usize,
) {
    let dims = plan.dims;
    encoder.copy_buffer_to_texture(
        wgpu::TexelCopyBufferInfo {
            buffer: slab,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some((plan.row * CELL_BYTES) as u32),
                rows_per_image: Some(dims[1] as u32),
            },
        },
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d {
                x: 0,
                y: 0,
                z: first_layer as u32,
            },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::Extent3d {
            width: dims[0] as u32,
            height: dims[1] as u32,
            depth_or_array_layers: layers as u32,
        },
    );
}

impl WgpuBackend {
    pub(super) fn run_voxelize(
        &mut self,
        frame: &FrameParams,
        n: usize,
    ) -> Result<(), BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        let geometry = VoxelGeometry::new("wgpu", frame.box_min, frame.box_max, n)?;
        let scene = self
            .scene
            .as_ref()
            .ok_or(BackendError::NothingUploaded("wgpu"))?;
        let plan = SlabPlan::new(&ctx, geometry.dims, scene.data.count, self.max_binding)?;
        self.ensure_grid_texture(&geometry)?;
        buffer_at_least(
            &ctx,
            &mut self.splat_buffers.slab,
            "voxel slab",
            plan.layers_per_slab as u64 * plan.layer_bytes,
            storage,
        )?;
        buffer_at_least(
            &ctx,
            &mut self.splat_buffers.splats,
            "voxel splats",
            plan.chunk as u64 * SPLAT_BYTES,
            storage,
        )?;
        let scene = self.scene.as_ref().expect("checked above");
        scene.write_maps(&ctx, self.tree.as_ref(), &self.optical, &frame.colour_table);
        let base = GpuVoxels::new(&geometry, scene.data.origin, plan.row as u32, frame.colour);
        let voxels = self.voxels.as_mut().expect("made above");
        voxels.geometry = geometry;
        write(&ctx, &voxels.march_uniform, bytemuck::bytes_of(&base));
        let entry = self.write_pass_ranges(&plan, base)?;
        let encoder = self.record_voxelize(frame, &plan, entry)?;
        let device_time = util::submit_and_time(&ctx, "voxelize", encoder)?;
        self.timings.voxelize = device_time.unwrap_or_else(|| started.elapsed());
        let SlabPlan {
            dims,
            layers_per_slab,
            slabs,
            count,
            chunks,
            ..
        } = plan;
        tracing::debug!(
            "wgpu: voxelised {count} particles into {dims:?} cells in {slabs} slab(s) of \
             {layers_per_slab} layer(s), {chunks} chunk(s) of particles"
        );
        Ok(())
    }

    /// Makes the grid's texture (and the march's uniform) unless the grid has its dimensions.
    fn ensure_grid_texture(&mut self, geometry: &VoxelGeometry) -> Result<(), BackendError> {
        let dims = geometry.dims;
        if self
            .voxels
            .as_ref()
            .is_some_and(|v| v.geometry.dims == dims)
        {
            return Ok(());
        }
        let ctx = &self.ctx;
        self.voxels = None;
        let bytes = geometry.bytes();
        let (texture, march_uniform) = ctx
            .scoped(&format!("voxel grid texture ({bytes} bytes)"), || {
                let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
                    label: Some("voxel grid"),
                    size: wgpu::Extent3d {
                        width: dims[0] as u32,
                        height: dims[1] as u32,
                        depth_or_array_layers: dims[2] as u32,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D3,
                    format: wgpu::TextureFormat::Rgba32Float,
                    usage: wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_DST
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                });
                let uniform =
                    util::uniform(ctx, "voxel grid", std::mem::size_of::<GpuVoxels>() as u64);
                (texture, uniform)
            })
            .map_err(|e| {
                let e = match e {
                    BackendError::Device { message, .. } => message,
                    other => other.to_string(),
                };
                device_error(format!(
                    "{e} (a voxel grid of {dims:?} cells is one rgba32float 3D texture of \
                     {} MiB, more than {} allocates: use a smaller --voxel-grid)",
                    bytes >> 20,
                    ctx.info.name
                ))
            })?;
        let view = texture.create_view(&Default::default());
        self.voxels = Some(Voxels {
            geometry: *geometry,
            texture,
            view,
            march_uniform,
        });
        Ok(())
    }

    /// Writes one uniform entry per pass (slab, chunk), `base` with the pass's range, at the
    /// device's offset alignment (the passes of one submission each read their own range);
    /// returns the entries' stride.
    fn write_pass_ranges(&mut self, plan: &SlabPlan, base: GpuVoxels) -> Result<u64, BackendError> {
        let ctx = &self.ctx;
        let align = u64::from(ctx.limits.min_uniform_buffer_offset_alignment);
        let entry = (std::mem::size_of::<GpuVoxels>() as u64).next_multiple_of(align);
        let passes = plan.slabs * plan.chunks;
        let mut entries = vec![0u8; passes * entry as usize];
        for s in 0..plan.slabs {
            let (first_layer, layers) = plan.layers(s);
            for c in 0..plan.chunks {
                let (first, in_chunk) = plan.particles(c);
                let mut v = base;
                v.range = [
                    first as u32,
                    in_chunk as u32,
                    first_layer as u32,
                    layers as u32,
                ];
                let at = (s * plan.chunks + c) * entry as usize;
                entries[at..at + std::mem::size_of::<GpuVoxels>()]
                    .copy_from_slice(bytemuck::bytes_of(&v));
            }
        }
        buffer_at_least(
            ctx,
            &mut self.splat_buffers.ranges,
            "voxel pass ranges",
            entries.len() as u64,
            util::uniform,
        )?;
        let ranges = self.splat_buffers.ranges.as_ref().expect("made above");
        write(ctx, ranges, &entries);
        Ok(entry)
    }

    /// Records a voxelisation's passes: per slab, the slab cleared, each chunk's particles made
    /// as the kernel sees them (once, when there is one chunk) and splatted into it, and the
    /// slab copied into the texture. `entry` is the stride of the passes' uniform entries.
    fn record_voxelize(
        &self,
        frame: &FrameParams,
        plan: &SlabPlan,
        entry: u64,
    ) -> Result<wgpu::CommandEncoder, BackendError> {
        let ctx = &self.ctx;
        let scene = self.scene.as_ref().expect("checked by run_voxelize");
        let mut variant = scene.variant(frame.integrator, frame.colour, frame.noise);
        // Neither pass integrates or draws noise: one variant per scene and colour mode.
        variant[spec::INTEGRATOR] = 0;
        variant[spec::NOISE_KIND] = 0;
        let particles_layout = Layout::of(&[&scene.particles]);
        let prepare = ctx.pipeline(on_wgpu::VOXEL_PARTICLES, Some(variant), particles_layout)?;
        let splat = ctx.pipeline(on_wgpu::VOXEL_SPLAT, None, Layout::Whole)?;
        let slab = self.splat_buffers.slab.as_ref().expect("made above");
        let splats = self.splat_buffers.splats.as_ref().expect("made above");
        let ranges = self.splat_buffers.ranges.as_ref().expect("made above");
        let voxels = self.voxels.as_ref().expect("made above");
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("voxelize", || {
            for s in 0..plan.slabs {
                let (first_layer, layers) = plan.layers(s);
                encoder.clear_buffer(slab, 0, None);
                for c in 0..plan.chunks {
                    let pass = (s * plan.chunks + c) as u64;
                    let in_chunk = plan.particles(c).1 as u64;
                    let range = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: ranges,
                        offset: pass * entry,
                        size: wgpu::BufferSize::new(std::mem::size_of::<GpuVoxels>() as u64),
                    });
                    // With one chunk the particles as the kernel sees them are the same for
                    // every slab: made once.
                    if plan.chunks > 1 || s == 0 {
                        let mut bound = vec![
                            (0, range.clone()),
                            (1, scene.field_uniform.as_entire_binding()),
                            (3, scene.maps.as_entire_binding()),
                            (
                                4,
                                scene
                                    .radius_attribute
                                    .as_ref()
                                    .unwrap_or(&self.dummy)
                                    .as_entire_binding(),
                            ),
                            (8, splats.as_entire_binding()),
                        ];
                        bound.extend(scene.particles.entries(10, particles_layout));
                        bound.extend(
                            scene
                                .particles_lo
                                .as_ref()
                                .unwrap_or(&scene.particles)
                                .entries(26, particles_layout),
                        );
                        let bg = bind(ctx, &prepare, &bound);
                        dispatch(
                            &mut encoder,
                            "voxel particles",
                            &prepare,
                            &bg,
                            grid(in_chunk, on_wgpu::VOXEL_PARTICLES.point().threads()),
                        );
                    }
                    let bg = bind(
                        ctx,
                        &splat,
                        &[
                            (0, range),
                            (8, splats.as_entire_binding()),
                            (9, slab.as_entire_binding()),
                        ],
                    );
                    let groups = grid(in_chunk, on_wgpu::VOXEL_SPLAT.point().threads());
                    dispatch(&mut encoder, "voxel splat", &splat, &bg, groups);
                }
                copy_slab(
                    &mut encoder,
                    slab,
                    &voxels.texture,
                    plan,
                    first_layer,
                    layers,
                );
            }
        })?;
        Ok(encoder)
    }

    /// One frame of the frame's integrator over the grid, into the accumulation.
    pub(super) fn run_voxel_frame(&mut self, frame: &FrameParams) -> Result<(), BackendError> {
        let started = Instant::now();
        let ctx = self.ctx.clone();
        if self.voxels.is_none() {
            return Err(BackendError::NoVoxelGrid("wgpu"));
        }
        if self.scene.is_none() {
            return Err(BackendError::NothingUploaded("wgpu"));
        }
        self.ensure_accumulation(frame.width, frame.height)?;
        self.ensure_stbn()?;
        let scene = self.scene.as_ref().expect("checked above");
        self.optical = frame.optical_table.to_vec();
        scene.write_maps(&ctx, self.tree.as_ref(), &self.optical, &frame.colour_table);
        write(
            &ctx,
            &self.frame_uniform,
            bytemuck::bytes_of(&GpuFrame::new(frame, scene.data.origin)),
        );
        let voxels = self.voxels.as_ref().expect("checked above");
        let acc = self.accumulation.as_mut().expect("made above");
        let layout = Layout::of(&[&acc.sums]);
        let mut variant = scene.variant(frame.integrator, frame.colour, frame.noise);
        // The march reads no particle: what varies the particles' kernel does not vary it.
        for unread in [
            spec::CLUSTER_SIZE,
            spec::RADIUS_MAP_VARIES,
            spec::DENSITY_MAP_VARIES,
            spec::HAS_RADIUS_ATTRIBUTE,
            spec::POSITION_DS,
            spec::RT_HIT_PER_PARTICLE,
            spec::COMPENSATED_SUM,
        ] {
            variant[unread] = 0;
        }
        let pipeline = ctx.pipeline(on_wgpu::VOXEL_RENDER, Some(variant), layout)?;
        let dispatched = write_tiling(
            &ctx,
            &self.tiling_uniform,
            on_wgpu::VOXEL_RENDER,
            (frame.width, frame.height),
            acc.sums.part_len(16),
            false,
        );
        let stbn = self.stbn.as_ref().expect("made above");
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("voxel render", || {
            let mut entries = vec![
                (0, self.frame_uniform.as_entire_binding()),
                (3, scene.maps.as_entire_binding()),
                (5, wgpu::BindingResource::TextureView(&voxels.view)),
                (6, voxels.march_uniform.as_entire_binding()),
                (7, stbn.as_entire_binding()),
                (9, self.tiling_uniform.as_entire_binding()),
            ];
            entries.extend(acc.sums.entries(22, layout));
            let bg = bind(&ctx, &pipeline, &entries);
            if acc.clear {
                acc.sums.clear(&mut encoder);
                acc.frames = 0;
                acc.clear = false;
            }
            dispatch(
                &mut encoder,
                "voxel render",
                &pipeline,
                &bg,
                grid(u64::from(dispatched), 1),
            );
        })?;
        let device_time = util::submit_and_time(&ctx, "voxel render", encoder)?;
        acc.frames += 1;
        self.timings.frame = device_time.unwrap_or_else(|| started.elapsed());
        Ok(())
    }

    /// The grid's sums, read back from the texture.
    pub(super) fn read_voxels(&self) -> Result<VoxelGrid, BackendError> {
        let voxels = self
            .voxels
            .as_ref()
            .ok_or(BackendError::NoVoxelGrid("wgpu"))?;
        let ctx = &self.ctx;
        let dims = voxels.geometry.dims;
        let row = row_cells(dims);
        let bytes = row * CELL_BYTES * (dims[1] * dims[2]) as u64;
        let buffer = ctx.scoped("voxel readback", || storage(ctx, "voxel readback", bytes))?;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("voxel readback copy", || {
            encoder.copy_texture_to_buffer(
                voxels.texture.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some((row * CELL_BYTES) as u32),
                        rows_per_image: Some(dims[1] as u32),
                    },
                },
                voxels.texture.size(),
            );
        })?;
        let mut raw = Vec::new();
        util::read_into(ctx, Some(encoder), &buffer, 0, bytes, &mut raw)?;
        let padded: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&raw);
        let sums = padded
            .chunks_exact(row as usize)
            .flat_map(|r| r[..dims[0]].iter().copied())
            .collect();
        Ok(VoxelGrid::from_sums(voxels.geometry, sums))
    }

    /// Bytes of the grid's texture and of the splat's buffers.
    pub(super) fn voxel_bytes(&self) -> usize {
        let b = &self.splat_buffers;
        self.voxels.as_ref().map_or(0, |v| v.geometry.bytes())
            + [&b.slab, &b.splats, &b.ranges]
                .into_iter()
                .map(|b| b.as_ref().map_or(0, |b| b.size() as usize))
                .sum::<usize>()
    }

    /// Fills the grid's texture with 0xFF (NaN) (tests: the next voxelisation must write every
    /// cell).
    pub fn poison_voxels(&self) -> Result<(), BackendError> {
        let voxels = self
            .voxels
            .as_ref()
            .ok_or(BackendError::NoVoxelGrid("wgpu"))?;
        let dims = voxels.geometry.dims;
        let row_bytes = dims[0] as u64 * CELL_BYTES;
        let poison = vec![0xFFu8; (row_bytes * (dims[1] * dims[2]) as u64) as usize];
        self.ctx.queue.write_texture(
            voxels.texture.as_image_copy(),
            &poison,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row_bytes as u32),
                rows_per_image: Some(dims[1] as u32),
            },
            voxels.texture.size(),
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_rows_are_padded_to_the_copy_alignment() {
        assert_eq!(row_cells([16, 3, 3]), 16);
        assert_eq!(row_cells([17, 3, 3]), 32);
        assert_eq!(row_cells([1, 1, 1]), 16);
    }
}
