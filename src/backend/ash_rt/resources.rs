//! Buffers (through gpu-allocator), acceleration-structure storage and one-at-a-time command
//! submission with timestamps.
//!
//! Every buffer lives in device-local memory. Where that memory is also host-visible and
//! coherent (lavapipe, integrated GPUs, resizable BAR) the host reads and writes it in place;
//! elsewhere [`Buffer::write`] / [`Buffer::read`] go through a staging buffer and a copy.

use std::cell::Cell;
use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};

use super::context::{Context, device_error, vk_error};
use crate::backend::BackendError;

/// A buffer and its memory. Dropping it frees both (the owner makes sure the device no
/// longer uses it: every submission here is waited for).
pub struct Buffer {
    ctx: Arc<Context>,
    /// The Vulkan buffer.
    pub raw: vk::Buffer,
    allocation: Option<Allocation>,
    /// Its size in bytes.
    pub size: u64,
    /// The device address (0 unless created with `SHADER_DEVICE_ADDRESS`).
    pub address: u64,
    name: String,
}

thread_local! {
    static BUFFERS_MADE: Cell<u64> = const { Cell::new(0) };
}

/// Buffers this thread has made ([`Buffer::new`] makes every buffer of this backend): tests
/// check that stepping through a reserved series makes none (per thread, so tests running
/// beside each other on the shared device do not count each other's).
pub fn buffers_made() -> u64 {
    BUFFERS_MADE.with(Cell::get)
}

fn allocation_error(
    ctx: &Context,
    name: &str,
    size: u64,
    e: gpu_allocator::AllocationError,
) -> BackendError {
    match e {
        gpu_allocator::AllocationError::OutOfMemory => {
            let held = ctx
                .allocator()
                .as_ref()
                .map_or(0, |a| a.generate_report().total_capacity_bytes);
            device_error(
                &format!("allocating {name}"),
                out_of_memory(size, ctx.info.device_local_heap, held),
            )
        }
        e => device_error(&format!("allocating {name}"), e),
    }
}

/// What an out-of-memory error says: the need, the device's memory and what this process
/// already holds of it, and what to change.
fn out_of_memory(size: u64, heap: u64, held: u64) -> String {
    let mib = |b: u64| b as f64 / 1048576.0;
    format!(
        "out of device memory: {:.1} MiB needed, the device-local heap is {:.1} MiB and this \
         process holds {:.1} MiB of device memory already (try fewer particles, a larger \
         cluster size or a smaller image)",
        mib(size),
        mib(heap),
        mib(held)
    )
}

impl Buffer {
    /// A buffer of `size` bytes (at least 16) with `usage` plus transfers, in device-local
    /// memory (or host memory for `location` `CpuToGpu` / `GpuToCpu`).
    pub fn new(
        ctx: &Arc<Context>,
        name: &str,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
    ) -> Result<Buffer, BackendError> {
        let size = size.max(16);
        BUFFERS_MADE.with(|c| c.set(c.get() + 1));
        let usage = usage | vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST;
        let device = &ctx.device;
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: a valid create info.
        let raw = unsafe { device.create_buffer(&info, None) }
            .map_err(|e| vk_error(&format!("creating {name}"), e))?;
        // SAFETY: raw was just created on this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(raw) };
        let allocation = {
            let mut guard = ctx.allocator();
            let allocator = guard
                .as_mut()
                .expect("the allocator lives as long as the context");
            allocator.allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            })
        };
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: unused, unbound buffer.
                unsafe { device.destroy_buffer(raw, None) };
                return Err(allocation_error(ctx, name, size, e));
            }
        };
        let mut buffer = Buffer {
            ctx: ctx.clone(),
            raw,
            allocation: Some(allocation),
            size,
            address: 0,
            name: name.to_owned(),
        };
        let a = buffer.allocation.as_ref().expect("set above");
        // SAFETY: memory and offset come from the allocator for this buffer's requirements.
        unsafe { device.bind_buffer_memory(raw, a.memory(), a.offset()) }
            .map_err(|e| vk_error(&format!("binding memory to {name}"), e))?;
        if usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS) {
            // SAFETY: the buffer has the usage and bound memory.
            buffer.address = unsafe {
                device
                    .get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(raw))
            };
        }
        Ok(buffer)
    }

    /// Whether the buffer's memory is the device's own and the host's writes need no flush
    /// (integrated GPUs, resizable BAR, lavapipe): the host writes what the shaders read.
    pub fn device_local_and_host_coherent(&self) -> bool {
        self.allocation.as_ref().is_some_and(|a| {
            a.memory_properties().contains(
                vk::MemoryPropertyFlags::DEVICE_LOCAL
                    | vk::MemoryPropertyFlags::HOST_VISIBLE
                    | vk::MemoryPropertyFlags::HOST_COHERENT,
            )
        })
    }

    /// The buffer's bytes, when the host can touch them in place.
    pub fn host_slice(&mut self) -> Option<&mut [u8]> {
        let a = self.allocation.as_mut()?;
        let coherent = a.memory_properties().contains(
            vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
        );
        if coherent { a.mapped_slice_mut() } else { None }
    }

    /// Writes `bytes` at `offset` (directly, or through a staging buffer and a waited copy).
    pub fn write(&mut self, offset: u64, bytes: &[u8]) -> Result<(), BackendError> {
        if bytes.is_empty() {
            return Ok(());
        }
        if offset + bytes.len() as u64 > self.size {
            return Err(device_error(
                &format!("writing {}", self.name),
                format!(
                    "{} bytes at {offset} overflow {} bytes",
                    bytes.len(),
                    self.size
                ),
            ));
        }
        if let Some(slice) = self.host_slice() {
            slice[offset as usize..offset as usize + bytes.len()].copy_from_slice(bytes);
            return Ok(());
        }
        let ctx = self.ctx.clone();
        let mut staging = Buffer::new(
            &ctx,
            "staging (upload)",
            bytes.len() as u64,
            vk::BufferUsageFlags::empty(),
            MemoryLocation::CpuToGpu,
        )?;
        staging
            .host_slice()
            .ok_or_else(|| device_error("staging upload", "memory is not host-visible"))?
            [..bytes.len()]
            .copy_from_slice(bytes);
        let region = vk::BufferCopy::default()
            .dst_offset(offset)
            .size(bytes.len() as u64);
        one_off(&ctx, |cb| {
            // SAFETY: both buffers are alive and large enough.
            unsafe {
                ctx.device
                    .cmd_copy_buffer(cb, staging.raw, self.raw, &[region])
            }
        })
    }

    /// Reads `len` bytes from the start (directly, or through a staging buffer).
    pub fn read(&mut self, len: u64) -> Result<Vec<u8>, BackendError> {
        let len = len.min(self.size);
        if let Some(slice) = self.host_slice() {
            return Ok(slice[..len as usize].to_vec());
        }
        let ctx = self.ctx.clone();
        let mut staging = Buffer::new(
            &ctx,
            "staging (readback)",
            len,
            vk::BufferUsageFlags::empty(),
            MemoryLocation::GpuToCpu,
        )?;
        let region = vk::BufferCopy::default().size(len);
        one_off(&ctx, |cb| {
            // SAFETY: both buffers are alive and large enough.
            unsafe {
                ctx.device
                    .cmd_copy_buffer(cb, self.raw, staging.raw, &[region])
            }
        })?;
        Ok(staging
            .host_slice()
            .ok_or_else(|| device_error("staging readback", "memory is not host-visible"))?
            [..len as usize]
            .to_vec())
    }

    /// Descriptor info for the whole buffer.
    pub fn descriptor(&self) -> vk::DescriptorBufferInfo {
        vk::DescriptorBufferInfo::default()
            .buffer(self.raw)
            .offset(0)
            .range(vk::WHOLE_SIZE)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if let Some(a) = self.allocation.take() {
            let mut guard = self.ctx.allocator();
            if let Some(allocator) = guard.as_mut()
                && let Err(e) = allocator.free(a)
            {
                tracing::warn!("freeing {}: {e}", self.name);
            }
        }
        // SAFETY: the device no longer uses the buffer (every submission is waited for).
        unsafe { self.ctx.device.destroy_buffer(self.raw, None) };
    }
}

/// Records `record` into a fresh command buffer, submits it and waits.
fn one_off(ctx: &Arc<Context>, record: impl FnOnce(vk::CommandBuffer)) -> Result<(), BackendError> {
    let commands = Commands::new(ctx, 0)?;
    let cb = commands.begin()?;
    record(cb);
    commands.submit_and_wait()
}

/// A command pool with one command buffer, a fence and a timestamp query pool: one recording,
/// submitted and waited for, at a time.
pub struct Commands {
    ctx: Arc<Context>,
    pool: vk::CommandPool,
    /// The command buffer being recorded.
    pub cb: vk::CommandBuffer,
    fence: vk::Fence,
    /// The timestamp query pool.
    pub queries: vk::QueryPool,
    query_count: u32,
}

impl Commands {
    /// A pool, command buffer and fence on `ctx`'s queue, with `timestamps` timestamp queries.
    pub fn new(ctx: &Arc<Context>, timestamps: u32) -> Result<Commands, BackendError> {
        let device = &ctx.device;
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(ctx.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create infos throughout; each object is destroyed in Drop.
        unsafe {
            let pool = device
                .create_command_pool(&pool_info, None)
                .map_err(|e| vk_error("creating a command pool", e))?;
            let mut commands = Commands {
                ctx: ctx.clone(),
                pool,
                cb: vk::CommandBuffer::null(),
                fence: vk::Fence::null(),
                queries: vk::QueryPool::null(),
                query_count: 0,
            };
            commands.cb = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .map_err(|e| vk_error("allocating a command buffer", e))?[0];
            commands.fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(|e| vk_error("creating a fence", e))?;
            if timestamps > 0 && ctx.info.timestamp_period.is_some() {
                commands.queries = device
                    .create_query_pool(
                        &vk::QueryPoolCreateInfo::default()
                            .query_type(vk::QueryType::TIMESTAMP)
                            .query_count(timestamps),
                        None,
                    )
                    .map_err(|e| vk_error("creating a timestamp query pool", e))?;
                commands.query_count = timestamps;
            }
            Ok(commands)
        }
    }

    /// Starts a recording (resetting the timestamps).
    pub fn begin(&self) -> Result<vk::CommandBuffer, BackendError> {
        let device = &self.ctx.device;
        // SAFETY: the buffer is not in use (the previous submission was waited for).
        unsafe {
            device
                .reset_command_buffer(self.cb, vk::CommandBufferResetFlags::empty())
                .map_err(|e| vk_error("resetting a command buffer", e))?;
            device
                .begin_command_buffer(
                    self.cb,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(|e| vk_error("beginning a command buffer", e))?;
            if self.query_count > 0 {
                device.cmd_reset_query_pool(self.cb, self.queries, 0, self.query_count);
            }
        }
        Ok(self.cb)
    }

    /// Writes timestamp `index` once all earlier commands are done.
    pub fn timestamp(&self, index: u32) {
        if index < self.query_count {
            // SAFETY: recording; the query was reset in `begin`.
            unsafe {
                self.ctx.device.cmd_write_timestamp(
                    self.cb,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    self.queries,
                    index,
                )
            };
        }
    }

    /// Ends the recording, submits it and waits for it.
    pub fn submit_and_wait(&self) -> Result<(), BackendError> {
        let device = &self.ctx.device;
        // SAFETY: a recording command buffer; the fence is unsignalled; the queue is locked.
        unsafe {
            device
                .end_command_buffer(self.cb)
                .map_err(|e| vk_error("recording commands", e))?;
            let cbs = [self.cb];
            let submit = [vk::SubmitInfo::default().command_buffers(&cbs)];
            {
                let queue = self.ctx.queue();
                device
                    .queue_submit(*queue, &submit, self.fence)
                    .map_err(|e| vk_error("submitting commands", e))?;
            }
            let waited = device.wait_for_fences(&[self.fence], true, u64::MAX);
            device
                .reset_fences(&[self.fence])
                .map_err(|e| vk_error("resetting a fence", e))?;
            waited.map_err(|e| vk_error("waiting for the device", e))
        }
    }

    /// Seconds between timestamps `a` and `b` of the last submission (`None` without
    /// timestamps).
    pub fn elapsed(&self, a: u32, b: u32) -> Option<std::time::Duration> {
        let period = self.ctx.info.timestamp_period?;
        if b >= self.query_count {
            return None;
        }
        let mut ticks = [0u64; 2];
        // SAFETY: both queries were written by the waited submission.
        unsafe {
            self.ctx
                .device
                .get_query_pool_results(
                    self.queries,
                    a,
                    &mut ticks[..1],
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
                .ok()?;
            self.ctx
                .device
                .get_query_pool_results(
                    self.queries,
                    b,
                    &mut ticks[1..],
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
                .ok()?;
        }
        let mask = self.ctx.info.timestamp_mask;
        let delta = (ticks[1] & mask).wrapping_sub(ticks[0] & mask) & mask;
        Some(std::time::Duration::from_nanos(
            (delta as f64 * period) as u64,
        ))
    }
}

impl Drop for Commands {
    fn drop(&mut self) {
        let device = &self.ctx.device;
        // SAFETY: nothing is in flight (every submission is waited for).
        unsafe {
            if self.query_count > 0 {
                device.destroy_query_pool(self.queries, None);
            }
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

/// A copy's (or fill's) writes, as the source of a [`barrier`].
pub const TRANSFER_WRITE: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::TRANSFER,
    vk::AccessFlags::TRANSFER_WRITE,
);
/// A compute shader's reads, as the destination of a [`barrier`].
pub const COMPUTE_READ: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::COMPUTE_SHADER,
    vk::AccessFlags::SHADER_READ,
);
/// A compute shader's writes, as the source of a [`barrier`].
pub const COMPUTE_WRITE: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::COMPUTE_SHADER,
    vk::AccessFlags::SHADER_WRITE,
);
/// A compute shader's reads and writes (a pass that adds to what the one before wrote), as
/// the destination of a [`barrier`].
pub const COMPUTE_READ_WRITE: (vk::PipelineStageFlags, vk::AccessFlags) = (
    vk::PipelineStageFlags::COMPUTE_SHADER,
    vk::AccessFlags::from_raw(
        vk::AccessFlags::SHADER_READ.as_raw() | vk::AccessFlags::SHADER_WRITE.as_raw(),
    ),
);

/// Records a global memory barrier from the `src` (stage, access) to the `dst` one.
pub fn barrier(
    ctx: &Context,
    cb: vk::CommandBuffer,
    src: (vk::PipelineStageFlags, vk::AccessFlags),
    dst: (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let b = [vk::MemoryBarrier::default()
        .src_access_mask(src.1)
        .dst_access_mask(dst.1)];
    // SAFETY: recording.
    unsafe {
        ctx.device.cmd_pipeline_barrier(
            cb,
            src.0,
            dst.0,
            vk::DependencyFlags::empty(),
            &b,
            &[],
            &[],
        )
    };
}

#[cfg(test)]
mod tests {
    #[test]
    fn out_of_memory_names_the_need_the_limit_and_the_remedy() {
        let m = super::out_of_memory(3 << 30, 8 << 30, 6 << 30);
        for part in [
            "3072.0 MiB needed",
            "device-local heap is 8192.0 MiB",
            "holds 6144.0 MiB",
            "a larger cluster size",
        ] {
            assert!(m.contains(part), "{m:?} lacks {part:?}");
        }
    }
}
