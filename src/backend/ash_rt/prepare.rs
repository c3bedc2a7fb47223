//! Preparing a step on the device (ash). The CPU's one pass writes the step, in its own order,
//! into host-visible staging memory (`gpu_data::StepStaging::write`); the device copies it and
//! runs the wgpu backend's stages (`wgpu_lbvh::prepare` explains them: 63-bit Hilbert keys, two
//! stable 32-bit radix sorts with the high words gathered between them, the gather into Hilbert
//! order) as compute passes of this backend's own (`shaders_glsl/vulkan/hilbert_keys.comp`,
//! `radix_sort.comp`, `gather.comp`: the sort needs workgroup
//! atomics, which the GLSL both backends share may not use), with the same CPU twins, into the
//! buffers the structure build reads. The order stays on the device, so a radius-attribute or
//! precision change gathers the new array without sorting again. Every buffer is made for the
//! largest step (or the reserved count) and reused.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::buffers::addressed;
use super::context::{Context, device_error};
use super::pipelines::{PreparePush, prepare_pipeline};
use super::resources::{
    Buffer, COMPUTE_READ, COMPUTE_READ_WRITE, COMPUTE_WRITE, Commands, TRANSFER_WRITE, barrier,
};
use crate::accel::HilbertQuantizer;
use crate::backend::BackendError;
use crate::backend::gpu_data::{GpuStepData, Slots, Slots4, Slots16, StepStaging};
use crate::backend::shaders::{Entry, on_ash};
use crate::field::FieldSettings;
use crate::values::Step;
use crate::values::shader_constants::{SORT_RADIX, SORT_TILE};

/// Workgroups per row of the per-element kernels' 2D launches (at most 65535 per dimension).
const ROW_GROUPS: u32 = 65_535;
/// Passes of 4-bit digits over 32-bit keys.
const SORT_PASSES: u32 = 8;

/// A step's array in its own order: the host-visible memory the CPU writes it into and, where
/// that memory is not device-local (a discrete GPU without resizable BAR), the device array it
/// is copied to. Where the host-visible memory is device-local (integrated GPUs, resizable BAR,
/// lavapipe) the shaders read what the CPU wrote in place and a step change copies nothing.
struct Raw {
    staging: Buffer,
    device: Option<Buffer>,
}

/// Whether a step's arrays are read where the CPU wrote them when the memory allows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Staging {
    InPlaceWherePossible,
    AlwaysCopy,
}

impl Raw {
    fn new(
        ctx: &Arc<Context>,
        label: &str,
        bytes: u64,
        mode: Staging,
    ) -> Result<Raw, BackendError> {
        let staging = Buffer::new(
            ctx,
            label,
            bytes,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::CpuToGpu,
        )?;
        let device =
            if mode == Staging::InPlaceWherePossible && staging.device_local_and_host_coherent() {
                None
            } else {
                Some(addressed(ctx, label, bytes)?)
            };
        Ok(Raw { staging, device })
    }

    /// The array the shaders read.
    fn on_device(&self) -> &Buffer {
        self.device.as_ref().unwrap_or(&self.staging)
    }

    fn bytes(&self) -> u64 {
        self.staging.size + self.device.as_ref().map_or(0, |d| d.size)
    }

    /// Write-only slots over the first `n` elements of `N` bytes of the staging memory.
    fn slots<const N: usize>(&mut self, n: usize) -> Result<Slots<'_, [u8; N]>, BackendError> {
        let bytes = self.staging.host_slice().ok_or_else(|| {
            device_error("staging a step", "the staging memory is not host-visible")
        })?;
        Ok(Slots::from_mut(bytes[..n * N].as_chunks_mut::<N>().0))
    }

    /// Records copying the first `bytes` bytes to the device array, if there is one to copy
    /// to; whether it recorded a copy.
    fn record_copy(&self, ctx: &Context, cb: vk::CommandBuffer, bytes: u64) -> bool {
        let Some(device) = self.device.as_ref().filter(|_| bytes > 0) else {
            return false;
        };
        let region = [vk::BufferCopy::default().size(bytes)];
        // SAFETY: recording; both buffers are alive and hold `bytes`.
        unsafe {
            ctx.device
                .cmd_copy_buffer(cb, self.staging.raw, device.raw, &region)
        };
        true
    }
}

/// The buffers the preparation writes, in Hilbert order.
pub(super) struct Targets<'a> {
    pub points: &'a Buffer,
    pub points_lo: Option<&'a Buffer>,
    pub radius: Option<&'a Buffer>,
}

/// The preparation's buffers, for up to `capacity` particles.
pub(super) struct Prepare {
    ctx: Arc<Context>,
    capacity: usize,
    staging: Staging,
    points: Raw,
    /// Made the first time a step needs them.
    points_lo: Option<Raw>,
    radius: Option<Raw>,
    /// The sort's keys and values, its scratch, the keys' high words and the digit histogram.
    /// After a preparation `values` holds the order.
    keys: Buffer,
    values: Buffer,
    keys_tmp: Buffer,
    values_tmp: Buffer,
    keys_hi: Buffer,
    histogram: Buffer,
}

impl Prepare {
    pub(super) fn new(
        ctx: &Arc<Context>,
        capacity: usize,
        staging: Staging,
    ) -> Result<Prepare, BackendError> {
        let n = capacity.max(1) as u64;
        let tiles = n.div_ceil(u64::from(SORT_TILE));
        Ok(Prepare {
            ctx: ctx.clone(),
            capacity,
            staging,
            points: Raw::new(ctx, "raw particles", n * 16, staging)?,
            points_lo: None,
            radius: None,
            keys: addressed(ctx, "hilbert keys", n * 4)?,
            values: addressed(ctx, "hilbert order", n * 4)?,
            keys_tmp: addressed(ctx, "hilbert keys scratch", n * 4)?,
            values_tmp: addressed(ctx, "hilbert order scratch", n * 4)?,
            keys_hi: addressed(ctx, "hilbert keys, high words", n * 4)?,
            histogram: addressed(
                ctx,
                "radix sort histogram",
                u64::from(SORT_RADIX) * tiles * 4,
            )?,
        })
    }

    pub(super) fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes the preparation holds: staging memory, the raw arrays on the device, and the
    /// sort's buffers.
    pub(super) fn bytes(&self) -> usize {
        let raws = [
            Some(&self.points),
            self.points_lo.as_ref(),
            self.radius.as_ref(),
        ];
        let raw: u64 = raws.into_iter().flatten().map(Raw::bytes).sum();
        let sort: u64 = [
            &self.keys,
            &self.values,
            &self.keys_tmp,
            &self.values_tmp,
            &self.keys_hi,
            &self.histogram,
        ]
        .iter()
        .map(|b| b.size)
        .sum();
        (raw + sort) as usize
    }

    fn lo(&mut self) -> Result<&mut Raw, BackendError> {
        if self.points_lo.is_none() {
            self.points_lo = Some(Raw::new(
                &self.ctx,
                "raw particle lo parts",
                self.capacity.max(1) as u64 * 16,
                self.staging,
            )?);
        }
        self.points_lo
            .as_mut()
            .ok_or_else(|| device_error("staging a step", "no lo parts"))
    }

    /// The raw radius-attribute buffer (with an SPH kernel's volumes after it:
    /// `gpu_data::factor_layout`), holding at least `words` floats (made again when a step
    /// needs more).
    fn radius(&mut self, words: usize) -> Result<&mut Raw, BackendError> {
        if self
            .radius
            .as_ref()
            .is_none_or(|r| r.on_device().size < words as u64 * 4)
        {
            self.radius = None;
            self.radius = Some(Raw::new(
                &self.ctx,
                "raw radius attribute",
                words.max(self.capacity).max(1) as u64 * 4,
                self.staging,
            )?);
        }
        self.radius
            .as_mut()
            .ok_or_else(|| device_error("staging a step", "no radius attribute"))
    }

    /// The staging pass: writes the checked step (and the lo parts when the precision needs
    /// them) into the staging memory. The CPU's whole share of a step change.
    pub(super) fn stage(
        &mut self,
        staging: StepStaging<'_>,
        step: &Step,
    ) -> Result<GpuStepData, BackendError> {
        let n = staging.len();
        if n > self.capacity {
            return Err(device_error(
                "staging a step",
                format!("{n} particles exceed the {} staged", self.capacity),
            ));
        }
        let words = staging.factor_words();
        if words > 0 {
            self.radius(words)?;
        }
        let Prepare { points, radius, .. } = self;
        let points: Slots16<'_> = points.slots::<16>(n)?;
        let radius: Option<Slots4<'_>> = match radius {
            Some(r) if words > 0 => Some(r.slots::<4>(words)?),
            _ => None,
        };
        let data = staging.write(vec![(0, points)], radius);
        if data.double_single {
            let lo = self.lo()?.slots::<16>(n)?;
            data.write_lo(step, vec![(0, lo)]);
        }
        Ok(data)
    }

    /// After a field change ([`GpuStepData::apply_field`]): stages the radius attribute
    /// `settings` names (with `radius`) and the lo parts (with `lo`) for [`Self::record_gathers`].
    pub(super) fn restage(
        &mut self,
        data: &GpuStepData,
        step: &Step,
        settings: &FieldSettings,
        radius: bool,
        lo: bool,
    ) -> Result<(), BackendError> {
        let n = data.count;
        if radius {
            let words = data.factor_words();
            data.write_factors(step, settings, self.radius(words)?.slots::<4>(words)?)?;
        }
        if lo {
            data.write_lo(step, vec![(0, self.lo()?.slots::<16>(n)?)]);
        }
        Ok(())
    }

    /// Records one dispatch of `kind` with `push`.
    fn dispatch(
        &self,
        cb: vk::CommandBuffer,
        kind: Entry,
        push: &PreparePush,
        groups: (u32, u32),
    ) -> Result<(), BackendError> {
        let ctx = &self.ctx;
        let pipeline = prepare_pipeline(ctx, kind)?;
        // SAFETY: recording; the pipeline uses the prepare layout, whose push range is
        // `PreparePush`.
        unsafe {
            ctx.device
                .cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, pipeline);
            ctx.device.cmd_push_constants(
                cb,
                ctx.layouts.prepare,
                vk::ShaderStageFlags::COMPUTE,
                0,
                bytemuck::bytes_of(push),
            );
            ctx.device.cmd_dispatch(cb, groups.0, groups.1, 1);
        }
        barrier(ctx, cb, COMPUTE_WRITE, COMPUTE_READ_WRITE);
        Ok(())
    }

    /// Records a per-element kernel over `n` elements with `arrays`.
    fn elements(
        &self,
        cb: vk::CommandBuffer,
        kind: Entry,
        quantizer: &HilbertQuantizer,
        n: u32,
        arrays: [u64; 5],
    ) -> Result<(), BackendError> {
        let [lx, ly, lz] = quantizer.lo();
        let [sx, sy, sz] = quantizer.scale();
        // Elements per row of the 2D launch.
        let group = kind.point().threads();
        let row = ROW_GROUPS * group;
        let push = PreparePush {
            grid_lo: [lx, ly, lz, 0.0],
            grid_scale: [sx, sy, sz, 0.0],
            count: n,
            width: row,
            arrays,
            ..PreparePush::default()
        };
        let groups = n.div_ceil(group).max(1);
        self.dispatch(
            cb,
            kind,
            &push,
            (groups.min(ROW_GROUPS), n.div_ceil(row).max(1)),
        )
    }

    /// Records the stable sort of the first `n` (keys, values) pairs.
    fn record_sort(&self, cb: vk::CommandBuffer, n: u32) -> Result<(), BackendError> {
        if n <= 1 {
            return Ok(());
        }
        let tiles = n.div_ceil(SORT_TILE);
        for pass in 0..SORT_PASSES {
            let (from, to) = if pass % 2 == 0 {
                (
                    (&self.keys, &self.values),
                    (&self.keys_tmp, &self.values_tmp),
                )
            } else {
                (
                    (&self.keys_tmp, &self.values_tmp),
                    (&self.keys, &self.values),
                )
            };
            let push = PreparePush {
                count: n,
                shift: 4 * pass,
                tiles,
                arrays: [
                    from.0.address,
                    from.1.address,
                    to.0.address,
                    to.1.address,
                    self.histogram.address,
                ],
                ..PreparePush::default()
            };
            self.dispatch(cb, on_ash::RADIX_SORT_COUNT, &push, (tiles, 1))?;
            self.dispatch(cb, on_ash::RADIX_SORT_SCAN, &push, (1, 1))?;
            self.dispatch(cb, on_ash::RADIX_SORT_SCATTER, &push, (tiles, 1))?;
        }
        Ok(())
    }

    /// Records the copy of what [`Self::stage`] wrote to the device; whether there was
    /// anything to copy (nothing where the staging memory is the device's, see [`Raw`]: the
    /// submission that follows makes the host's writes visible to the device).
    pub(super) fn record_copy(&self, cb: vk::CommandBuffer, data: &GpuStepData) -> bool {
        let n = data.count as u64;
        let ctx = &self.ctx;
        let mut copied = self.points.record_copy(ctx, cb, n * 16);
        if let Some(raw) = self.points_lo.as_ref().filter(|_| data.double_single) {
            copied |= raw.record_copy(ctx, cb, n * 16);
        }
        if let Some(raw) = self.radius.as_ref().filter(|_| data.has_factors()) {
            copied |= raw.record_copy(ctx, cb, data.factor_words() as u64 * 4);
        }
        if copied {
            barrier(ctx, cb, TRANSFER_WRITE, COMPUTE_READ);
        }
        copied
    }

    /// Records the preparation of the copied step ([`Self::record_copy`], submitted before)
    /// into `targets`.
    pub(super) fn record(
        &self,
        cb: vk::CommandBuffer,
        data: &GpuStepData,
        targets: &Targets<'_>,
    ) -> Result<(), BackendError> {
        let n = data.count as u32;
        let lo = self
            .points_lo
            .as_ref()
            .filter(|_| data.double_single)
            .zip(targets.points_lo);
        let radius = self
            .radius
            .as_ref()
            .filter(|_| data.has_factors())
            .zip(targets.radius);
        if n == 0 {
            return Ok(());
        }
        self.elements(
            cb,
            on_ash::HILBERT_KEYS,
            &data.quantizer,
            n,
            [
                self.points.on_device().address,
                self.keys.address,
                self.keys_hi.address,
                self.values.address,
                0,
            ],
        )?;
        self.record_sort(cb, n)?;
        self.gather(cb, on_ash::GATHER_WORDS, data, &self.keys_hi, &self.keys)?;
        self.record_sort(cb, n)?;
        self.gather(
            cb,
            on_ash::GATHER_VEC4S,
            data,
            self.points.on_device(),
            targets.points,
        )?;
        if let Some((raw, dst)) = lo {
            self.gather(cb, on_ash::GATHER_VEC4S, data, raw.on_device(), dst)?;
        }
        if let Some((raw, dst)) = radius {
            self.gather_factors(cb, data, raw.on_device(), dst)?;
        }
        Ok(())
    }

    /// Records the gathers of the radius attribute's and an SPH kernel's volumes' sections of
    /// the radius-attribute buffer (`gpu_data::factor_layout`), each through the order.
    fn gather_factors(
        &self,
        cb: vk::CommandBuffer,
        data: &GpuStepData,
        from: &Buffer,
        to: &Buffer,
    ) -> Result<(), BackendError> {
        for first in data.factor_sections() {
            let offset = first as u64 * 4;
            self.elements(
                cb,
                on_ash::GATHER_WORDS,
                &data.quantizer,
                data.count as u32,
                [
                    self.values.address,
                    from.address + offset,
                    to.address + offset,
                    0,
                    0,
                ],
            )?;
        }
        Ok(())
    }

    /// Records `to[k] = from[order[k]]` over the step's particles.
    fn gather(
        &self,
        cb: vk::CommandBuffer,
        kind: Entry,
        data: &GpuStepData,
        from: &Buffer,
        to: &Buffer,
    ) -> Result<(), BackendError> {
        self.elements(
            cb,
            kind,
            &data.quantizer,
            data.count as u32,
            [self.values.address, from.address, to.address, 0, 0],
        )
    }

    /// Records the copy of what [`Self::restage`] wrote and its gathers through the kept order.
    pub(super) fn record_gathers(
        &self,
        cb: vk::CommandBuffer,
        data: &GpuStepData,
        radius: Option<&Buffer>,
        lo: Option<&Buffer>,
    ) -> Result<(), BackendError> {
        let n = data.count as u64;
        let ctx = &self.ctx;
        let radius = self.radius.as_ref().zip(radius);
        let lo = self.points_lo.as_ref().zip(lo);
        let mut copied = false;
        if let Some((raw, _)) = radius {
            copied |= raw.record_copy(ctx, cb, data.factor_words() as u64 * 4);
        }
        if let Some((raw, _)) = lo {
            copied |= raw.record_copy(ctx, cb, n * 16);
        }
        if copied {
            barrier(ctx, cb, TRANSFER_WRITE, COMPUTE_READ);
        }
        if n == 0 {
            return Ok(());
        }
        if let Some((raw, dst)) = radius {
            self.gather_factors(cb, data, raw.on_device(), dst)?;
        }
        if let Some((raw, dst)) = lo {
            self.gather(cb, on_ash::GATHER_VEC4S, data, raw.on_device(), dst)?;
        }
        Ok(())
    }

    /// Stage 1 alone on `points` (local coordinates in xyz), its outputs poisoned first: each
    /// particle's key and the permutation it writes (tests).
    pub(super) fn hilbert_keys(
        &mut self,
        commands: &Commands,
        points: &[[f32; 4]],
        quantizer: &HilbertQuantizer,
    ) -> Result<(Vec<u64>, Vec<u32>), BackendError> {
        let n = points.len();
        self.poison()?;
        self.points.staging.write(0, bytemuck::cast_slice(points))?;
        let cb = commands.begin()?;
        self.points.record_copy(&self.ctx, cb, n as u64 * 16);
        barrier(&self.ctx, cb, TRANSFER_WRITE, COMPUTE_READ);
        self.elements(
            cb,
            on_ash::HILBERT_KEYS,
            quantizer,
            n as u32,
            [
                self.points.on_device().address,
                self.keys.address,
                self.keys_hi.address,
                self.values.address,
                0,
            ],
        )?;
        commands.submit_and_wait()?;
        let lo: Vec<u32> = bytemuck::pod_collect_to_vec(&self.keys.read(n as u64 * 4)?);
        let hi: Vec<u32> = bytemuck::pod_collect_to_vec(&self.keys_hi.read(n as u64 * 4)?);
        let keys = lo
            .iter()
            .zip(&hi)
            .map(|(&l, &h)| u64::from(h) << 32 | u64::from(l))
            .collect();
        Ok((keys, self.order(n)?))
    }

    /// The radix sort alone on (`keys`, their indices), its scratch poisoned first: the sorted
    /// keys and the input index of each (tests).
    pub(super) fn sort_pairs(
        &mut self,
        commands: &Commands,
        keys: &[u32],
    ) -> Result<(Vec<u32>, Vec<u32>), BackendError> {
        let n = keys.len();
        self.poison()?;
        self.keys.write(0, bytemuck::cast_slice(keys))?;
        let identity: Vec<u32> = (0..n as u32).collect();
        self.values.write(0, bytemuck::cast_slice(&identity))?;
        let cb = commands.begin()?;
        self.record_sort(cb, n as u32)?;
        commands.submit_and_wait()?;
        Ok((
            bytemuck::pod_collect_to_vec(&self.keys.read(n as u64 * 4)?),
            self.order(n)?,
        ))
    }

    /// The order of the last prepared step (tests).
    pub(super) fn order(&mut self, n: usize) -> Result<Vec<u32>, BackendError> {
        Ok(bytemuck::pod_collect_to_vec(
            &self.values.read(n as u64 * 4)?,
        ))
    }

    /// Fills the sort's buffers with 0xFF (tests).
    pub(super) fn poison(&mut self) -> Result<(), BackendError> {
        for b in [
            &mut self.keys,
            &mut self.values,
            &mut self.keys_tmp,
            &mut self.values_tmp,
            &mut self.keys_hi,
        ] {
            b.write(0, &vec![0xFF; b.size as usize])?;
        }
        Ok(())
    }
}
