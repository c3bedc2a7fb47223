//! Buffer and dispatch helpers.

use super::context::{GpuContext, device_error};
use crate::backend::BackendError;

/// Workgroups for `threads` threads of `group`-sized workgroups, as a 2D grid (x at most
/// 65535, the WebGPU minimum limit); the kernels compute their index as
/// `(wg.y * groups.x + wg.x) * group + local`.
pub fn grid(threads: u64, group: u32) -> (u32, u32) {
    let groups = threads.div_ceil(u64::from(group)).max(1);
    let x = groups.min(65_535);
    (x as u32, groups.div_ceil(x) as u32)
}

/// Interleaved dispatch order for `groups` workgroups: `(B, S, B * S)` such that workgroup `i`
/// does group `(i mod B) S + i / B` (those at or beyond `groups` do nothing). Consecutive
/// workgroups land in different blocks, so a driver that splits a dispatch into contiguous
/// ranges per thread (lavapipe) balances work that varies across the image or query order.
pub fn interleave(groups: u32) -> (u32, u32, u32) {
    let blocks = groups.clamp(1, 64);
    let per_block = groups.div_ceil(blocks).max(1);
    (blocks, per_block, blocks * per_block)
}

/// A storage buffer of at least `bytes` (rounded up to 16, never 0), copyable both ways.
pub fn storage(ctx: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

pub fn uniform(ctx: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Writes `data` at offset 0 (nothing for empty data).
pub fn write(ctx: &GpuContext, buffer: &wgpu::Buffer, data: &[u8]) {
    if !data.is_empty() {
        ctx.queue.write_buffer(buffer, 0, data);
    }
}

/// Fills a whole buffer with 0xFF bytes (a NaN / u32::MAX poison, for tests).
pub fn poison(ctx: &GpuContext, buffer: &wgpu::Buffer) {
    ctx.queue
        .write_buffer(buffer, 0, &vec![0xFF; buffer.size() as usize]);
}

/// A bind group for `pipeline`'s group 0 with whole buffers (or ranges) at the given bindings.
pub fn bind(
    ctx: &GpuContext,
    pipeline: &wgpu::ComputePipeline,
    entries: &[(u32, wgpu::BindingResource<'_>)],
) -> wgpu::BindGroup {
    let layout = pipeline.get_bind_group_layout(0);
    let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
        .iter()
        .map(|(binding, resource)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: resource.clone(),
        })
        .collect();
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &layout,
        entries: &entries,
    })
}

/// One compute pass with one dispatch.
pub fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: (u32, u32),
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups(groups.0, groups.1, 1);
}

/// Reads `bytes` bytes from `offset` of `buffer` (which needs COPY_SRC), waiting for the
/// device.
pub fn read(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    offset: u64,
    bytes: u64,
) -> Result<Vec<u8>, BackendError> {
    let mut out = Vec::new();
    read_into(ctx, None, buffer, offset, bytes, &mut out)?;
    Ok(out)
}

/// Submits `encoder` (if any) followed by a copy of `bytes` bytes at `offset` of `buffer`,
/// waits, and appends them to `out`.
pub fn read_into(
    ctx: &GpuContext,
    encoder: Option<wgpu::CommandEncoder>,
    buffer: &wgpu::Buffer,
    offset: u64,
    bytes: u64,
    out: &mut Vec<u8>,
) -> Result<(), BackendError> {
    let size = bytes.next_multiple_of(4).max(4);
    let staging = ctx.scoped("readback buffer", || {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    })?;
    let mut encoder =
        encoder.unwrap_or_else(|| ctx.device.create_command_encoder(&Default::default()));
    ctx.scoped("readback", || {
        if bytes > 0 {
            encoder.copy_buffer_to_buffer(
                buffer,
                offset,
                &staging,
                0,
                size.min(buffer.size() - offset),
            );
        }
        ctx.queue.submit([encoder.finish()]);
    })?;
    let (sender, receiver) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = sender.send(r);
    });
    ctx.wait()?;
    receiver
        .recv()
        .map_err(|_| device_error("readback: the map callback never ran"))?
        .map_err(|e| device_error(format!("readback: {e}")))?;
    {
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| device_error(format!("readback: {e}")))?;
        out.extend_from_slice(&view[..bytes as usize]);
    }
    staging.unmap();
    Ok(())
}

/// Reads `count` u32 words.
pub fn read_u32(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    count: usize,
) -> Result<Vec<u32>, BackendError> {
    let bytes = read(ctx, buffer, 0, count as u64 * 4)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Submits `encoder` and waits for it.
pub fn submit_and_wait(
    ctx: &GpuContext,
    what: &str,
    encoder: wgpu::CommandEncoder,
) -> Result<(), BackendError> {
    ctx.scoped(what, || {
        ctx.queue.submit([encoder.finish()]);
    })?;
    ctx.wait()
}
