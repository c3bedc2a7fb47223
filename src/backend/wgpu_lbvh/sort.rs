//! The host side of `shaders_wgsl/radix_sort.wgsl`: a stable LSD radix sort of (key, value)
//! u32 pairs, 4-bit digits, 8 passes (count, scan, scatter each), ping-ponging between two
//! buffer pairs; after the even number of passes the result is back in the first pair.

use bytemuck::{Pod, Zeroable};

use super::context::{GpuContext, Layout};
use super::util::{bind, dispatch, grid, poison, read_u32, storage, write};
use crate::backend::BackendError;
use crate::backend::shaders::on_wgpu;
use crate::values::shader_constants::{SORT_RADIX, SORT_TILE};

/// Passes of 4-bit digits over 32-bit keys.
const PASSES: u32 = 8;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct SortParams {
    count: u32,
    shift: u32,
    tiles: u32,
    pad: u32,
}

/// The sort's own buffers: per-pass parameters and the digit histogram.
pub struct RadixSort {
    params: wgpu::Buffer,
    stride: u64,
    histogram: wgpu::Buffer,
    tiles_capacity: u32,
}

impl RadixSort {
    /// The buffers for sorts of up to `capacity` keys, on `ctx`'s device.
    pub fn new(ctx: &GpuContext, capacity: usize) -> RadixSort {
        let stride = u64::from(ctx.limits.min_uniform_buffer_offset_alignment).max(16);
        let tiles_capacity = (capacity as u32).div_ceil(SORT_TILE).max(1);
        RadixSort {
            params: ctx.create_buffer(&wgpu::BufferDescriptor {
                label: Some("radix sort params"),
                size: stride * u64::from(PASSES),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            stride,
            histogram: storage(
                ctx,
                "radix sort histogram",
                u64::from(SORT_RADIX * tiles_capacity) * 4,
            ),
            tiles_capacity,
        }
    }

    /// Bytes of its digit histogram (the parameters' few bytes left out).
    pub fn bytes(&self) -> usize {
        self.histogram.size() as usize
    }

    /// Encodes the sort of the first `count` pairs of (`keys`, `values`) (at most the capacity
    /// it was made for), using (`keys_tmp`, `values_tmp`) as scratch. Writes its parameters to
    /// the queue, so the encoder must be submitted before another sort is encoded.
    #[allow(clippy::too_many_arguments)]
    pub fn encode(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        count: u32,
        keys: &wgpu::Buffer,
        values: &wgpu::Buffer,
        keys_tmp: &wgpu::Buffer,
        values_tmp: &wgpu::Buffer,
    ) -> Result<(), BackendError> {
        if count <= 1 {
            return Ok(());
        }
        let tiles = count.div_ceil(SORT_TILE);
        if tiles > self.tiles_capacity {
            return Err(super::context::device_error(format!(
                "radix sort: {count} keys exceed the {} it was made for",
                self.tiles_capacity * SORT_TILE
            )));
        }
        let count_pipeline = ctx.pipeline(on_wgpu::RADIX_SORT_COUNT, None, Layout::Whole)?;
        let scan_pipeline = ctx.pipeline(on_wgpu::RADIX_SORT_SCAN, None, Layout::Whole)?;
        let scatter_pipeline = ctx.pipeline(on_wgpu::RADIX_SORT_SCATTER, None, Layout::Whole)?;
        let groups = grid(u64::from(tiles), 1);
        for pass in 0..PASSES {
            let params = SortParams {
                count,
                shift: 4 * pass,
                tiles,
                pad: 0,
            };
            let offset = self.stride * u64::from(pass);
            ctx.queue
                .write_buffer(&self.params, offset, bytemuck::bytes_of(&params));
            let params_binding = || {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &self.params,
                    offset,
                    size: std::num::NonZeroU64::new(16),
                })
            };
            let (kin, vin, kout, vout) = if pass % 2 == 0 {
                (keys, values, keys_tmp, values_tmp)
            } else {
                (keys_tmp, values_tmp, keys, values)
            };
            let count_bg = bind(
                ctx,
                &count_pipeline,
                &[
                    (0, params_binding()),
                    (1, kin.as_entire_binding()),
                    (5, self.histogram.as_entire_binding()),
                ],
            );
            let scan_bg = bind(
                ctx,
                &scan_pipeline,
                &[
                    (0, params_binding()),
                    (5, self.histogram.as_entire_binding()),
                ],
            );
            let scatter_bg = bind(
                ctx,
                &scatter_pipeline,
                &[
                    (0, params_binding()),
                    (1, kin.as_entire_binding()),
                    (2, vin.as_entire_binding()),
                    (3, kout.as_entire_binding()),
                    (4, vout.as_entire_binding()),
                    (5, self.histogram.as_entire_binding()),
                ],
            );
            dispatch(encoder, "sort count", &count_pipeline, &count_bg, groups);
            dispatch(encoder, "sort scan", &scan_pipeline, &scan_bg, (1, 1));
            dispatch(
                encoder,
                "sort scatter",
                &scatter_pipeline,
                &scatter_bg,
                groups,
            );
        }
        Ok(())
    }
}

/// Sorts (key, index) pairs on the GPU by key, stably: the sorted keys and the input index of
/// each (a test entry point for the sort stage; the scratch buffers are poisoned first).
pub fn sort_pairs(ctx: &GpuContext, keys: &[u32]) -> Result<(Vec<u32>, Vec<u32>), BackendError> {
    let n = keys.len();
    let bytes = (n.max(1) * 4) as u64;
    let values: Vec<u32> = (0..n as u32).collect();
    let (k, v, kt, vt) = ctx.scoped("sort buffers", || {
        (
            storage(ctx, "keys", bytes),
            storage(ctx, "values", bytes),
            storage(ctx, "keys scratch", bytes),
            storage(ctx, "values scratch", bytes),
        )
    })?;
    write(ctx, &k, bytemuck::cast_slice(keys));
    write(ctx, &v, bytemuck::cast_slice(&values));
    poison(ctx, &kt);
    poison(ctx, &vt);
    let sort = RadixSort::new(ctx, n);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    ctx.scoped("sort", || {
        sort.encode(ctx, &mut encoder, n as u32, &k, &v, &kt, &vt)
    })??;
    super::util::submit_and_wait(ctx, "sort", encoder)?;
    Ok((read_u32(ctx, &k, n)?, read_u32(ctx, &v, n)?))
}
