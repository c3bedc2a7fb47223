//! Buffer and dispatch helpers.

use super::context::{GpuContext, Layout, device_error};
use crate::backend::BackendError;

/// Workgroups for `threads` threads of `group`-sized workgroups, as a 2D grid (x at most
/// 65535, the WebGPU minimum limit); the kernels compute their index as
/// `(wg.y * groups.x + wg.x) * group + local`.
pub(super) fn grid(threads: u64, group: u32) -> (u32, u32) {
    let groups = threads.div_ceil(u64::from(group)).max(1);
    let x = groups.min(65_535);
    (x as u32, groups.div_ceil(x) as u32)
}

/// Interleaved dispatch order for `groups` workgroups: `(B, S, B * S)` such that workgroup `i`
/// does group `(i mod B) S + i / B` (those at or beyond `groups` do nothing). Consecutive
/// workgroups land in different blocks, so a driver that splits a dispatch into contiguous
/// ranges per thread (lavapipe) balances work that varies across the image or query order.
pub(super) fn interleave(groups: u32) -> (u32, u32, u32) {
    let blocks = groups.clamp(1, 64);
    let per_block = groups.div_ceil(blocks).max(1);
    (blocks, per_block, blocks * per_block)
}

/// A storage buffer of at least `bytes` (rounded up to 16, never 0), copyable both ways.
pub(super) fn storage(ctx: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    storage_with_usage(ctx, label, bytes, wgpu::BufferUsages::empty())
}

/// [`storage`], the buffer also having `extra` usages (`MAP_WRITE` for
/// [`Staging::aliasing_buffer`]).
pub(super) fn storage_with_usage(
    ctx: &GpuContext,
    label: &str,
    bytes: u64,
    extra: wgpu::BufferUsages,
) -> wgpu::Buffer {
    ctx.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC
            | extra,
        mapped_at_creation: false,
    })
}

pub(super) fn uniform(ctx: &GpuContext, label: &str, bytes: u64) -> wgpu::Buffer {
    ctx.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(16),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Writes `data` at offset 0 (nothing for empty data).
pub(super) fn write(ctx: &GpuContext, buffer: &wgpu::Buffer, data: &[u8]) {
    if !data.is_empty() {
        ctx.queue.write_buffer(buffer, 0, data);
    }
}

/// Fills a whole buffer with 0xFF bytes (a NaN / u32::MAX poison, for tests).
pub(super) fn poison(ctx: &GpuContext, buffer: &wgpu::Buffer) {
    ctx.queue
        .write_buffer(buffer, 0, &vec![0xFF; buffer.size() as usize]);
}

/// A bind group for `pipeline`'s group 0 with whole buffers (or ranges) at the given bindings.
pub(super) fn bind(
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
pub(super) fn dispatch(
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

/// Encodes one pass of `kernel` (its pipeline for `variant` and `layout`, compiled on first
/// use) bound to `entries`, dispatching `groups` workgroups.
#[allow(clippy::too_many_arguments)]
pub(super) fn encode_pass(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    kernel: crate::backend::shaders::Entry,
    variant: super::context::Variant,
    layout: Layout,
    entries: &[(u32, wgpu::BindingResource<'_>)],
    groups: (u32, u32),
) -> Result<(), BackendError> {
    let pipeline = ctx.pipeline(kernel, variant, layout)?;
    let bind_group = bind(ctx, &pipeline, entries);
    dispatch(encoder, label, &pipeline, &bind_group, groups);
    Ok(())
}

/// Reads `bytes` bytes from `offset` of `buffer` (which needs COPY_SRC), waiting for the
/// device.
pub(super) fn read(
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
pub(super) fn read_into(
    ctx: &GpuContext,
    encoder: Option<wgpu::CommandEncoder>,
    buffer: &wgpu::Buffer,
    offset: u64,
    bytes: u64,
    out: &mut Vec<u8>,
) -> Result<(), BackendError> {
    let size = bytes.next_multiple_of(4).max(4);
    let staging = ctx.scoped("readback buffer", || {
        ctx.create_buffer(&wgpu::BufferDescriptor {
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
pub(super) fn read_u32(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    count: usize,
) -> Result<Vec<u32>, BackendError> {
    let bytes = read(ctx, buffer, 0, count as u64 * 4)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Submits `encoder` and waits for it.
pub(super) fn submit_and_wait(
    ctx: &GpuContext,
    what: &str,
    encoder: wgpu::CommandEncoder,
) -> Result<(), BackendError> {
    ctx.scoped(what, || {
        ctx.queue.submit([encoder.finish()]);
    })?;
    ctx.wait()
}

/// Submits `encoder` and waits for it, returning the time the device spent on it, from
/// timestamps written in command buffers submitted just before and after it (`None` where the
/// device has no timestamps inside encoders: the caller times it on the host).
pub(super) fn submit_and_time(
    ctx: &GpuContext,
    what: &str,
    encoder: wgpu::CommandEncoder,
) -> Result<Option<std::time::Duration>, BackendError> {
    let mut before = ctx.device.create_command_encoder(&Default::default());
    let Some(span) = DeviceSpan::begin(ctx, &mut before) else {
        submit_and_wait(ctx, what, encoder)?;
        return Ok(None);
    };
    let mut after = ctx.device.create_command_encoder(&Default::default());
    span.end(&mut after);
    ctx.scoped(what, || {
        ctx.queue
            .submit([before.finish(), encoder.finish(), after.finish()]);
    })?;
    ctx.wait()?;
    span.read(ctx).map(Some)
}

/// The device's time between two points of recorded work (where it writes timestamps inside
/// encoders): [`DeviceSpan::begin`] records the first timestamp, [`DeviceSpan::end`] the second
/// with their resolution, and [`DeviceSpan::read`], once that work has completed, the time
/// between them. Holds the context's timestamps until read (the context is shared between
/// threads), so nothing between begin and read may time anything else.
pub(super) struct DeviceSpan<'a> {
    ts: &'a super::context::Timestamps,
    _one_at_a_time: std::sync::MutexGuard<'a, ()>,
}

impl<'a> DeviceSpan<'a> {
    pub(super) fn begin(ctx: &'a GpuContext, encoder: &mut wgpu::CommandEncoder) -> Option<Self> {
        let ts = ctx.timestamps.as_ref()?;
        let guard = ts.lock.lock().unwrap_or_else(|e| e.into_inner());
        encoder.write_timestamp(&ts.queries, 0);
        Some(DeviceSpan {
            ts,
            _one_at_a_time: guard,
        })
    }

    pub(super) fn end(&self, encoder: &mut wgpu::CommandEncoder) {
        let ts = self.ts;
        encoder.write_timestamp(&ts.queries, 1);
        encoder.resolve_query_set(&ts.queries, 0..2, &ts.resolved, 0);
        encoder.copy_buffer_to_buffer(&ts.resolved, 0, &ts.readback, 0, 16);
    }

    /// The time between the two timestamps (the work holding `end` must have completed).
    pub(super) fn read(self, ctx: &GpuContext) -> Result<std::time::Duration, BackendError> {
        let ts = self.ts;
        let (sender, receiver) = std::sync::mpsc::channel();
        ts.readback.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = sender.send(r);
        });
        ctx.wait()?;
        receiver
            .recv()
            .map_err(|_| device_error("timestamps: the map callback never ran"))?
            .map_err(|e| device_error(format!("timestamps: {e}")))?;
        let ticks: [u64; 2] = {
            let view = ts
                .readback
                .get_mapped_range(..)
                .map_err(|e| device_error(format!("timestamps: {e}")))?;
            bytemuck::pod_read_unaligned(&view[..16])
        };
        ts.readback.unmap();
        let nanos = ticks[1].saturating_sub(ticks[0]) as f64 * f64::from(ts.period);
        Ok(std::time::Duration::from_nanos(nanos as u64))
    }
}

pub(super) use super::context::PARTS;

impl Layout {
    /// Split when any array the kernel binds is in more than one part.
    pub fn of(arrays: &[&SplitBuffer]) -> Layout {
        if arrays.iter().any(|a| a.parts_used() > 1) {
            Layout::Split
        } else {
            Layout::Whole
        }
    }
}

/// The largest part a split array uses: the binding limit, capped at 2 GiB so that every word
/// index of a 4-part array fits a u32 in the shaders.
pub(super) fn part_limit(max_binding: u64) -> u64 {
    max_binding.min(1 << 31)
}

/// The parts an array of `elems` elements of `elem_bytes` bytes needs under a binding limit of
/// `max_binding` bytes (at least 1; may exceed [`PARTS`], which the caller refuses).
pub(super) fn parts_needed(elems: u64, elem_bytes: u64, max_binding: u64) -> u64 {
    let per_part = part_limit(max_binding) / elem_bytes;
    if per_part == 0 {
        return u64::MAX;
    }
    elems.div_ceil(per_part).max(1)
}

/// An array that may be larger than one storage-buffer binding: up to [`PARTS`] buffers of
/// whole elements, each at most the binding limit. A kernel compiled for [`Layout::Whole`]
/// binds the first (which then holds everything); one compiled for [`Layout::Split`] binds all
/// [`PARTS`] at consecutive bindings and picks the part with a compare against the part length
/// (`part_len`). Every part is its own buffer even when unused (16 bytes then), since a split
/// kernel binds an unsplit array's placeholders too, and a placeholder shared between arrays
/// would be bound read-only and read-write in one dispatch, which wgpu refuses.
pub struct SplitBuffer {
    parts: Vec<wgpu::Buffer>,
    /// Bytes per part (all but the last used part are full).
    part_bytes: u64,
    /// Parts holding data (the rest are placeholders).
    used: usize,
    /// Bytes of data the parts hold.
    bytes: u64,
}

impl SplitBuffer {
    /// Room for `elems` elements of `elem_bytes` bytes in parts of at most `max_binding` bytes;
    /// None when that takes more than [`PARTS`] parts. Call inside [`GpuContext::scoped`].
    pub fn new(
        ctx: &GpuContext,
        label: &str,
        elems: u64,
        elem_bytes: u64,
        max_binding: u64,
    ) -> Option<SplitBuffer> {
        Self::with_usage(
            ctx,
            label,
            elems,
            elem_bytes,
            max_binding,
            wgpu::BufferUsages::empty(),
        )
    }

    /// [`Self::new`], the parts also having `extra` usages (`MAP_WRITE` for
    /// [`Staging::aliasing`]).
    pub fn with_usage(
        ctx: &GpuContext,
        label: &str,
        elems: u64,
        elem_bytes: u64,
        max_binding: u64,
        extra: wgpu::BufferUsages,
    ) -> Option<SplitBuffer> {
        let needed = parts_needed(elems, elem_bytes, max_binding);
        if needed > PARTS {
            return None;
        }
        let part_bytes = part_limit(max_binding) / elem_bytes * elem_bytes;
        let bytes = elems * elem_bytes;
        let parts = (0..PARTS)
            .map(|i| {
                let size = if i < needed {
                    bytes.saturating_sub(i * part_bytes).min(part_bytes)
                } else {
                    16
                };
                ctx.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("{label} (part {i})")),
                    size: size.max(16).next_multiple_of(16),
                    usage: wgpu::BufferUsages::STORAGE
                        | wgpu::BufferUsages::COPY_DST
                        | wgpu::BufferUsages::COPY_SRC
                        | extra,
                    mapped_at_creation: false,
                })
            })
            .collect();
        Some(SplitBuffer {
            parts,
            part_bytes,
            used: needed as usize,
            bytes,
        })
    }

    /// Elements of `unit_bytes` bytes (16: vec4, 4: u32) per part, for the shaders;
    /// 0xFFFFFFFF when one part holds everything (their first branch is then always taken).
    pub fn part_len(&self, unit_bytes: u64) -> u32 {
        if self.used <= 1 {
            u32::MAX
        } else {
            u32::try_from(self.part_bytes / unit_bytes).unwrap_or(u32::MAX)
        }
    }

    /// Parts holding data.
    pub fn parts_used(&self) -> usize {
        self.used
    }

    /// Elements of `unit_bytes` bytes a full part holds (for kernels that bind this array
    /// beside a split one of the same element size, whose part length this then is too).
    pub fn part_capacity(&self, unit_bytes: u64) -> u32 {
        u32::try_from(self.part_bytes / unit_bytes).unwrap_or(u32::MAX)
    }

    /// The part buffers (the placeholders too).
    pub fn buffers(&self) -> &[wgpu::Buffer] {
        &self.parts
    }

    /// Bytes of data the buffer has room for.
    pub fn size(&self) -> u64 {
        self.bytes
    }

    /// The bind-group entries from binding `first` on: [`PARTS`] of them for a kernel
    /// compiled for [`Layout::Split`], the one part for [`Layout::Whole`] (which only an array
    /// in one part may be bound to).
    pub fn entries(&self, first: u32, layout: Layout) -> Vec<(u32, wgpu::BindingResource<'_>)> {
        debug_assert!(layout == Layout::Split || self.used <= 1);
        let parts = match layout {
            Layout::Whole => 1,
            Layout::Split => self.parts.len(),
        };
        self.parts[..parts]
            .iter()
            .zip(first..)
            .map(|(b, i)| (i, b.as_entire_binding()))
            .collect()
    }

    /// The (part, offset in it, length) pieces of bytes `start .. start + len`.
    fn pieces(&self, start: u64, len: u64) -> Vec<(usize, u64, u64)> {
        let mut out = Vec::new();
        let (mut at, end) = (start, start + len);
        while at < end {
            let part = (at / self.part_bytes) as usize;
            let offset = at % self.part_bytes;
            let n = (self.part_bytes - offset).min(end - at);
            out.push((part, offset, n));
            at += n;
        }
        out
    }

    /// Writes `data` from byte 0 on (at most [`Self::size`] bytes).
    pub fn write(&self, ctx: &GpuContext, data: &[u8]) {
        let mut from = 0usize;
        for (part, offset, n) in self.pieces(0, data.len() as u64) {
            let n = n as usize;
            ctx.queue
                .write_buffer(&self.parts[part], offset, &data[from..from + n]);
            from += n;
        }
    }

    /// Reads bytes `0 .. bytes` (at most [`Self::size`]).
    pub fn read(&self, ctx: &GpuContext, bytes: u64) -> Result<Vec<u8>, BackendError> {
        let mut out = Vec::with_capacity(bytes as usize);
        for (part, offset, n) in self.pieces(0, bytes) {
            read_into(ctx, None, &self.parts[part], offset, n, &mut out)?;
        }
        Ok(out)
    }

    /// Encodes zeroing every part.
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder) {
        for b in &self.parts {
            encoder.clear_buffer(b, 0, None);
        }
    }

    /// Fills every part with 0xFF (tests).
    pub fn poison(&self, ctx: &GpuContext) {
        for b in &self.parts {
            poison(ctx, b);
        }
    }
}

/// Memory the host writes and the device copies from: MAP_WRITE buffers cut into the parts of
/// the array they fill (a [`SplitBuffer`]'s, or one part for an array in one buffer), made
/// once for a capacity and mapped again for each write, so stepping through a series
/// makes no buffer. The CPU converts a step straight into them (one copy of its bytes,
/// `gpu_data`), write-only: mapped memory may be uncached on the host.
pub(super) struct Staging {
    parts: Vec<wgpu::Buffer>,
    part_bytes: u64,
    mapped: bool,
    /// The parts are the destination's own (mappable storage on a unified-memory device):
    /// nothing to copy.
    aliases: bool,
}

impl Staging {
    /// Room for `bytes` bytes in parts of `part_bytes`, mapped. Call inside
    /// [`GpuContext::scoped`].
    pub(super) fn new(ctx: &GpuContext, label: &str, bytes: u64, part_bytes: u64) -> Staging {
        let bytes = bytes.max(16);
        let count = bytes.div_ceil(part_bytes);
        let parts = (0..count)
            .map(|i| {
                ctx.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("{label} staging (part {i})")),
                    size: (bytes - i * part_bytes)
                        .min(part_bytes)
                        .next_multiple_of(16),
                    usage: wgpu::BufferUsages::MAP_WRITE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: true,
                })
            })
            .collect();
        Staging {
            parts,
            part_bytes,
            mapped: true,
            aliases: false,
        }
    }

    /// Staging that is `dst` itself, whose parts were made mappable
    /// ([`SplitBuffer::with_usage`] with `MAP_WRITE`): views write into the buffers the
    /// kernels read, and [`Self::encode_copy`] only unmaps them.
    pub(super) fn aliasing(dst: &SplitBuffer) -> Staging {
        Self::aliasing_parts(
            dst.buffers()[..dst.parts_used().max(1)].to_vec(),
            dst.part_bytes,
        )
    }

    /// Staging that is the one buffer `dst` itself, made with `MAP_WRITE` ([`Self::aliasing`]
    /// for an array in one buffer).
    pub(super) fn aliasing_buffer(dst: &wgpu::Buffer) -> Staging {
        Self::aliasing_parts(vec![dst.clone()], dst.size())
    }

    fn aliasing_parts(parts: Vec<wgpu::Buffer>, part_bytes: u64) -> Staging {
        Staging {
            parts,
            part_bytes,
            mapped: false,
            aliases: true,
        }
    }

    /// Staging for the whole of `dst`, in its parts.
    pub(super) fn for_split(ctx: &GpuContext, label: &str, dst: &SplitBuffer) -> Staging {
        Staging::new(ctx, label, dst.size(), dst.part_bytes)
    }

    /// Bytes per part (all but the last are full).
    pub(super) fn part_bytes(&self) -> u64 {
        self.part_bytes
    }

    /// Whether this staging is its destination's own memory ([`Self::aliasing`]).
    pub(super) fn aliases(&self) -> bool {
        self.aliases
    }

    /// Maps every part again (after the device's last copy from them, which it waits for).
    fn map(&mut self, ctx: &GpuContext) -> Result<(), BackendError> {
        if self.mapped {
            return Ok(());
        }
        let (sender, receiver) = std::sync::mpsc::channel();
        for b in &self.parts {
            let sender = sender.clone();
            b.map_async(wgpu::MapMode::Write, .., move |r| {
                let _ = sender.send(r);
            });
        }
        drop(sender);
        ctx.wait()?;
        // Blocking: with the device shared between threads, another thread's poll may be the
        // one that runs these callbacks, a moment after this thread's poll returned.
        for _ in &self.parts {
            receiver
                .recv()
                .map_err(|_| device_error("staging: a map callback never ran"))?
                .map_err(|e| device_error(format!("staging: {e}")))?;
        }
        self.mapped = true;
        Ok(())
    }

    /// Write-only views of bytes `0 .. bytes`, one per part they reach (each from the part's
    /// start); drop them before [`Self::encode_copy`].
    pub(super) fn views(
        &mut self,
        ctx: &GpuContext,
        bytes: u64,
    ) -> Result<Vec<wgpu::BufferViewMut>, BackendError> {
        self.map(ctx)?;
        let mut out = Vec::new();
        let mut left = bytes;
        for b in &self.parts {
            if left == 0 {
                break;
            }
            let n = left.min(self.part_bytes);
            out.push(
                b.get_mapped_range_mut(..n)
                    .map_err(|e| device_error(format!("staging: {e}")))?,
            );
            left -= n;
        }
        Ok(out)
    }

    /// Unmaps the parts (after writing through [`Self::views`]).
    pub(super) fn unmap(&mut self) {
        for b in &self.parts {
            b.unmap();
        }
        self.mapped = false;
    }

    /// Unmaps the parts and encodes copying bytes `0 .. bytes` into `dst` (buffers cut into the
    /// same parts; nothing when the parts are `dst`'s own).
    pub(super) fn encode_copy(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        dst: &[wgpu::Buffer],
        bytes: u64,
    ) {
        self.unmap();
        if self.aliases {
            return;
        }
        let mut left = bytes;
        for (src, dst) in self.parts.iter().zip(dst) {
            if left == 0 {
                break;
            }
            let n = left.min(self.part_bytes);
            encoder.copy_buffer_to_buffer(src, 0, dst, 0, n);
            left -= n;
        }
    }
}

/// `n` floats of `buffer` from float `first` (tests).
pub(super) fn read_f32s(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    first: usize,
    n: usize,
) -> Result<Vec<f32>, BackendError> {
    if n == 0 {
        return Ok(Vec::new());
    }
    Ok(bytemuck::pod_collect_to_vec(&read(
        ctx,
        buffer,
        first as u64 * 4,
        n as u64 * 4,
    )?))
}
