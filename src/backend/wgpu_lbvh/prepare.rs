//! Preparing a step on the device. The CPU makes one pass over the step, in its own order,
//! straight into mapped staging memory (`gpu_data::StepStaging::write`: f32 local positions
//! with t, the radius attribute, and the lo parts when the precision needs them); the device
//! copies it and does the rest, every stage a compute pass with a CPU twin in
//! `backend::shaders::cpu`:
//!
//! 1. `hilbert_keys.wgsl`: each particle's 63-bit Hilbert key as two words, and the identity
//!    permutation;
//! 2. `radix_sort.wgsl` by the low words, `gather.wgsl` (`gather_words`) of the high words into
//!    that order, `radix_sort.wgsl` again by them: stable both times, so the order is the
//!    63-bit key's with ties in step order, [`crate::accel::hilbert_order`]'s bit for bit;
//! 3. `gather.wgsl`: the particles, their lo parts and radius attribute into the sorted order,
//!    in the scene's buffers, which the tree build reads.
//!
//! The sorted permutation stays on the device: a radius-attribute or precision change gathers
//! the new array through it without sorting again. Every buffer here is made for the largest
//! step seen (or reserved) and reused, staging included.

use bytemuck::{Pod, Zeroable};

use super::context::{GpuContext, Layout, device_error};
use super::sort::RadixSort;
use super::util::{
    SplitBuffer, Staging, encode_pass, grid, poison, read_u32, storage, storage_with_usage,
    submit_and_wait, write,
};
use super::{PARTICLE_BYTES, WORD_BYTES};
use crate::accel::HilbertQuantizer;
use crate::backend::BackendError;
use crate::backend::gpu_data::{GpuStepData, Slots, Slots16, StepStaging};
use crate::backend::shaders::on_wgpu;
use crate::field::FieldSettings;
use crate::values::Step;

/// `PrepareParams` of `shaders_wgsl/shared/prepare_params.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct PrepareParams {
    grid_lo: [f32; 4],
    grid_scale: [f32; 4],
    count: u32,
    part_vec4s: u32,
    pad: [u32; 2],
}

/// The step's arrays in its own order on the device, with their staging.
struct Raw<B> {
    staging: Staging,
    device: B,
}

/// Mapped staging memory for a step ([`Prepare::map`]).
pub(super) struct StagingViews {
    points: Vec<wgpu::BufferViewMut>,
    radius: Vec<wgpu::BufferViewMut>,
}

/// The buffers of the scene the preparation writes (in Hilbert order).
pub(super) struct Targets<'a> {
    pub particles: &'a SplitBuffer,
    pub particles_lo: Option<&'a SplitBuffer>,
    pub radius_attribute: Option<&'a wgpu::Buffer>,
}

/// The preparation's buffers, for up to `capacity` particles.
pub(super) struct Prepare {
    capacity: usize,
    max_binding: u64,
    params: wgpu::Buffer,
    points: Raw<SplitBuffer>,
    /// Made the first time a step needs them.
    points_lo: Option<Raw<SplitBuffer>>,
    radius_attribute: Option<Raw<wgpu::Buffer>>,
    /// The sort's keys and values, its scratch, and the keys' high words. After a
    /// preparation `values` holds the order (`order[k]`: the step's index of sorted particle k).
    keys: wgpu::Buffer,
    values: wgpu::Buffer,
    keys_tmp: wgpu::Buffer,
    values_tmp: wgpu::Buffer,
    keys_hi: wgpu::Buffer,
    sort: RadixSort,
}

/// The usages a raw array's device buffer has beside storage: on unified memory it is its own
/// staging ([`Staging::aliasing`]), so the host maps it.
fn raw_usage(ctx: &GpuContext) -> wgpu::BufferUsages {
    if ctx.unified_memory {
        wgpu::BufferUsages::MAP_WRITE
    } else {
        wgpu::BufferUsages::empty()
    }
}

fn split(
    ctx: &GpuContext,
    label: &str,
    capacity: usize,
    max_binding: u64,
) -> Result<Raw<SplitBuffer>, BackendError> {
    let device = SplitBuffer::with_usage(
        ctx,
        label,
        capacity as u64,
        PARTICLE_BYTES,
        max_binding,
        raw_usage(ctx),
    )
    .ok_or_else(|| {
        device_error(format!(
            "{capacity} particles do not fit the {label}' parts"
        ))
    })?;
    let staging = if ctx.unified_memory {
        Staging::aliasing(&device)
    } else {
        Staging::for_split(ctx, label, &device)
    };
    Ok(Raw { staging, device })
}

impl Prepare {
    /// Buffers for `capacity` particles, no binding larger than `max_binding` (the caller has
    /// checked that the particles fit their parts and the 4-byte arrays one binding).
    pub(super) fn new(
        ctx: &GpuContext,
        capacity: usize,
        max_binding: u64,
    ) -> Result<Prepare, BackendError> {
        let words = capacity.max(1) as u64 * WORD_BYTES;
        ctx.scoped(
            &format!("step preparation buffers for {capacity} particles"),
            || -> Result<Prepare, BackendError> {
                Ok(Prepare {
                    capacity,
                    max_binding,
                    params: super::util::uniform(
                        ctx,
                        "prepare params",
                        std::mem::size_of::<PrepareParams>() as u64,
                    ),
                    points: split(ctx, "raw particles", capacity, max_binding)?,
                    points_lo: None,
                    radius_attribute: None,
                    keys: storage(ctx, "hilbert keys", words),
                    values: storage(ctx, "hilbert order", words),
                    keys_tmp: storage(ctx, "hilbert keys scratch", words),
                    values_tmp: storage(ctx, "hilbert order scratch", words),
                    keys_hi: storage(ctx, "hilbert keys, high words", words),
                    sort: RadixSort::new(ctx, capacity),
                })
            },
        )?
    }

    pub(super) fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes the preparation holds beside the scene: the raw arrays on the device, as much
    /// again in their staging memory, and the sort's buffers.
    pub(super) fn bytes(&self) -> usize {
        // The particles' staging is their device buffers themselves on unified memory.
        let points_copies = if self.points.staging.aliases() { 1 } else { 2 };
        let raw = points_copies
            * (self.points.device.size() + self.points_lo.as_ref().map_or(0, |r| r.device.size()))
            + self.radius_attribute.as_ref().map_or(0, |r| {
                let copies = if r.staging.aliases() { 1 } else { 2 };
                copies * r.device.size()
            });
        let sort = [
            &self.keys,
            &self.values,
            &self.keys_tmp,
            &self.values_tmp,
            &self.keys_hi,
        ]
        .iter()
        .map(|b| b.size())
        .sum::<u64>();
        (raw + sort) as usize + self.sort.bytes()
    }

    /// Fills the sort's buffers and the raw arrays with 0xFF (tests).
    pub(super) fn poison(&self, ctx: &GpuContext) {
        for b in [
            &self.keys,
            &self.values,
            &self.keys_tmp,
            &self.values_tmp,
            &self.keys_hi,
        ] {
            poison(ctx, b);
        }
        self.points.device.poison(ctx);
        if let Some(r) = &self.points_lo {
            r.device.poison(ctx);
        }
        if let Some(r) = &self.radius_attribute {
            poison(ctx, &r.device);
        }
    }

    /// The order of the last prepared step (tests).
    pub(super) fn order(&self, ctx: &GpuContext, n: usize) -> Result<Vec<u32>, BackendError> {
        read_u32(ctx, &self.values, n)
    }

    fn lo(&mut self, ctx: &GpuContext) -> Result<&mut Raw<SplitBuffer>, BackendError> {
        if self.points_lo.is_none() {
            let (capacity, max_binding) = (self.capacity, self.max_binding);
            self.points_lo = Some(ctx.scoped("raw particle lo parts", || {
                split(ctx, "raw particle lo parts", capacity, max_binding)
            })??);
        }
        self.points_lo
            .as_mut()
            .ok_or_else(|| device_error("raw particle lo parts"))
    }

    /// The raw radius-attribute buffer (with an SPH kernel's volumes after it: see
    /// `gpu_data::factor_layout`), holding at least `words` floats (made again when a step
    /// needs more).
    fn radius(
        &mut self,
        ctx: &GpuContext,
        words: usize,
    ) -> Result<&mut Raw<wgpu::Buffer>, BackendError> {
        let bytes = words.max(self.capacity).max(1) as u64 * WORD_BYTES;
        if self
            .radius_attribute
            .as_ref()
            .is_none_or(|r| r.device.size() < words as u64 * WORD_BYTES)
        {
            self.radius_attribute = Some(ctx.scoped("raw radius attribute", || {
                let device = storage_with_usage(ctx, "raw radius attribute", bytes, raw_usage(ctx));
                let staging = if ctx.unified_memory {
                    Staging::aliasing_buffer(&device)
                } else {
                    Staging::new(ctx, "raw radius attribute", bytes, bytes)
                };
                Raw { staging, device }
            })?);
        }
        self.radius_attribute
            .as_mut()
            .ok_or_else(|| device_error("raw radius attribute"))
    }

    /// Maps the staging memory a step of `n` particles writes (after the device's last copy
    /// from it, which is over by then): the points', and the radius attribute's (with an SPH
    /// kernel's volumes) when it has `factor_words` floats. Not CPU work on the step: a wait
    /// for the device, kept out of the pass.
    pub(super) fn map(
        &mut self,
        ctx: &GpuContext,
        n: usize,
        factor_words: usize,
    ) -> Result<StagingViews, BackendError> {
        assert!(n <= self.capacity);
        let radius = match factor_words {
            0 => Vec::new(),
            words => self
                .radius(ctx, words)?
                .staging
                .views(ctx, words as u64 * WORD_BYTES)?,
        };
        Ok(StagingViews {
            points: self.points.staging.views(ctx, n as u64 * PARTICLE_BYTES)?,
            radius,
        })
    }

    /// The staging pass into the views [`Self::map`] made: writes the checked step (and the lo
    /// parts when the precision needs them). The CPU's whole share of a step change.
    pub(super) fn stage(
        &mut self,
        ctx: &GpuContext,
        staging: StepStaging<'_>,
        views: StagingViews,
        step: &Step,
    ) -> Result<GpuStepData, BackendError> {
        let n = staging.len();
        let StagingViews {
            points: mut views,
            radius: mut radius_views,
        } = views;
        let part = self.points.staging.part_bytes();
        let data = staging.write(
            slots(&mut views, part),
            radius_views.first_mut().map(view_slots::<4>),
        );
        drop((views, radius_views));
        if data.double_single {
            let lo = self.lo(ctx)?;
            let part = lo.staging.part_bytes();
            let mut views = lo.staging.views(ctx, n as u64 * PARTICLE_BYTES)?;
            data.write_lo(step, slots(&mut views, part));
        }
        Ok(data)
    }

    /// Copies what [`Self::stage`] wrote to the device, and waits; on unified memory, where
    /// the staging is the device's buffers ([`Staging::aliasing`]), only unmaps them: no
    /// command buffer, nothing to submit, no round trip to the device's queue.
    pub(super) fn copy(
        &mut self,
        ctx: &GpuContext,
        data: &GpuStepData,
    ) -> Result<(), BackendError> {
        let n = data.count as u64;
        let lo = self.points_lo.as_mut().filter(|_| data.double_single);
        let factor_bytes = data.factor_words() as u64 * WORD_BYTES;
        let radius = self
            .radius_attribute
            .as_mut()
            .filter(|_| data.has_factors());
        let mut copies: Vec<(&mut Staging, &[wgpu::Buffer], u64)> = vec![(
            &mut self.points.staging,
            self.points.device.buffers(),
            n * PARTICLE_BYTES,
        )];
        if let Some(lo) = lo {
            copies.push((&mut lo.staging, lo.device.buffers(), n * PARTICLE_BYTES));
        }
        if let Some(r) = radius {
            copies.push((
                &mut r.staging,
                std::slice::from_ref(&r.device),
                factor_bytes,
            ));
        }
        if copies.iter().all(|(staging, ..)| staging.aliases()) {
            for (staging, ..) in copies {
                staging.unmap();
            }
            return Ok(());
        }
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("step upload", || {
            for (staging, dst, bytes) in copies {
                staging.encode_copy(&mut encoder, dst, bytes);
            }
        })?;
        submit_and_wait(ctx, "step upload", encoder)
    }

    fn write_params(&self, ctx: &GpuContext, quantizer: &HilbertQuantizer, count: usize) {
        let [lx, ly, lz] = quantizer.lo();
        let [sx, sy, sz] = quantizer.scale();
        let p = PrepareParams {
            grid_lo: [lx, ly, lz, 0.0],
            grid_scale: [sx, sy, sz, 0.0],
            count: count as u32,
            part_vec4s: self.points.device.part_capacity(16),
            pad: [0; 2],
        };
        write(ctx, &self.params, bytemuck::bytes_of(&p));
    }

    /// Encodes stage 1 for the first `n` staged particles.
    fn encode_keys(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        n: usize,
    ) -> Result<(), BackendError> {
        let layout = Layout::of(&[&self.points.device]);
        let mut entries = vec![
            (0, self.params.as_entire_binding()),
            (1, self.keys.as_entire_binding()),
            (2, self.keys_hi.as_entire_binding()),
            (3, self.values.as_entire_binding()),
        ];
        entries.extend(self.points.device.entries(10, layout));
        encode_pass(
            ctx,
            encoder,
            "hilbert keys",
            on_wgpu::HILBERT_KEYS,
            None,
            layout,
            &entries,
            grid(n as u64, on_wgpu::HILBERT_KEYS.point().threads()),
        )
    }

    /// Encodes `dst[k] = src[order[k]]` over 4-byte words.
    fn encode_gather_words(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
        n: usize,
    ) -> Result<(), BackendError> {
        self.encode_gather_section(ctx, encoder, src, dst, 0, n)
    }

    /// The radius attribute and an SPH kernel's volumes into the sorted order: each section of
    /// the radius-attribute buffer (`gpu_data::factor_layout`) gathered on its own.
    fn encode_gather_factors(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        data: &GpuStepData,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
    ) -> Result<(), BackendError> {
        for first in data.factor_sections() {
            self.encode_gather_section(ctx, encoder, src, dst, first, data.count)?;
        }
        Ok(())
    }

    /// Encodes `dst[first + k] = src[first + order[k]]` for `k < n` over 4-byte words (`first`
    /// a multiple of 64: a binding's offset is a multiple of 256 bytes).
    fn encode_gather_section(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        dst: &wgpu::Buffer,
        first: usize,
        n: usize,
    ) -> Result<(), BackendError> {
        if n == 0 {
            return Ok(());
        }
        let section = |buffer| {
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer,
                offset: first as u64 * WORD_BYTES,
                size: wgpu::BufferSize::new(n as u64 * WORD_BYTES),
            })
        };
        encode_pass(
            ctx,
            encoder,
            "gather words",
            on_wgpu::GATHER_WORDS,
            None,
            Layout::Whole,
            &[
                (0, self.params.as_entire_binding()),
                (1, self.values.as_entire_binding()),
                (2, section(src)),
                (3, section(dst)),
            ],
            grid(n as u64, on_wgpu::GATHER_WORDS.point().threads()),
        )
    }

    /// Encodes `dst[k] = src[order[k]]` over the split vec4 arrays.
    fn encode_gather_vec4s(
        &self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        src: &SplitBuffer,
        dst: &SplitBuffer,
        n: usize,
    ) -> Result<(), BackendError> {
        let layout = Layout::of(&[src, dst]);
        let mut entries = vec![
            (0, self.params.as_entire_binding()),
            (1, self.values.as_entire_binding()),
        ];
        entries.extend(src.entries(10, layout));
        entries.extend(dst.entries(14, layout));
        encode_pass(
            ctx,
            encoder,
            "gather vec4s",
            on_wgpu::GATHER_VEC4S,
            None,
            layout,
            &entries,
            grid(n as u64, on_wgpu::GATHER_VEC4S.point().threads()),
        )
    }

    /// Stages 1-3 on the copied step: keys, the two sorts, and the gather into `targets`;
    /// submits and waits.
    pub(super) fn run(
        &self,
        ctx: &GpuContext,
        data: &GpuStepData,
        targets: &Targets<'_>,
    ) -> Result<(), BackendError> {
        let n = data.count;
        self.write_params(ctx, &data.quantizer, n);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.scoped("step preparation", || -> Result<(), BackendError> {
            self.encode_keys(ctx, &mut encoder, n)?;
            // Both sorts write the same per-pass parameters (same count, same shifts), so
            // encoding them before one submit is safe (`RadixSort::encode`).
            let sort = |encoder: &mut wgpu::CommandEncoder| {
                self.sort.encode(
                    ctx,
                    encoder,
                    n as u32,
                    &self.keys,
                    &self.values,
                    &self.keys_tmp,
                    &self.values_tmp,
                )
            };
            sort(&mut encoder)?;
            self.encode_gather_words(ctx, &mut encoder, &self.keys_hi, &self.keys, n)?;
            sort(&mut encoder)?;
            self.encode_gather_vec4s(ctx, &mut encoder, &self.points.device, targets.particles, n)?;
            if data.double_single
                && let (Some(lo), Some(dst)) = (&self.points_lo, targets.particles_lo)
            {
                self.encode_gather_vec4s(ctx, &mut encoder, &lo.device, dst, n)?;
            }
            if data.has_factors()
                && let (Some(r), Some(dst)) = (&self.radius_attribute, targets.radius_attribute)
            {
                self.encode_gather_factors(ctx, &mut encoder, data, &r.device, dst)?;
            }
            Ok(())
        })??;
        submit_and_wait(ctx, "step preparation", encoder)
    }

    /// After a field change ([`GpuStepData::apply_field`]): stages, copies and gathers into
    /// the existing order the radius attribute `settings` names (when `radius` is given) and
    /// the lo parts (when `lo` is given).
    pub(super) fn regather(
        &mut self,
        ctx: &GpuContext,
        data: &GpuStepData,
        step: &Step,
        settings: &FieldSettings,
        radius: Option<&wgpu::Buffer>,
        lo: Option<&SplitBuffer>,
    ) -> Result<(), BackendError> {
        let n = data.count;
        if let Some(dst) = radius {
            let words = data.factor_words();
            let raw = self.radius(ctx, words)?;
            let mut views = raw.staging.views(ctx, words as u64 * WORD_BYTES)?;
            if let Some(v) = views.first_mut() {
                data.write_factors(step, settings, view_slots::<4>(v))?;
            }
            drop(views);
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            ctx.scoped("radius attribute upload", || {
                raw.staging.encode_copy(
                    &mut encoder,
                    std::slice::from_ref(&raw.device),
                    words as u64 * WORD_BYTES,
                );
            })?;
            self.write_params(ctx, &data.quantizer, n);
            if let Some(raw) = &self.radius_attribute {
                ctx.scoped("radius attribute gather", || {
                    self.encode_gather_factors(ctx, &mut encoder, data, &raw.device, dst)
                })??;
            }
            submit_and_wait(ctx, "radius attribute", encoder)?;
        }
        if let Some(dst) = lo {
            let raw = self.lo(ctx)?;
            let part = raw.staging.part_bytes();
            let mut views = raw.staging.views(ctx, n as u64 * PARTICLE_BYTES)?;
            data.write_lo(step, slots(&mut views, part));
            drop(views);
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            ctx.scoped("lo parts upload", || {
                raw.staging.encode_copy(
                    &mut encoder,
                    raw.device.buffers(),
                    n as u64 * PARTICLE_BYTES,
                );
            })?;
            self.write_params(ctx, &data.quantizer, n);
            if let Some(raw) = &self.points_lo {
                ctx.scoped("lo parts gather", || {
                    self.encode_gather_vec4s(ctx, &mut encoder, &raw.device, dst, n)
                })??;
            }
            submit_and_wait(ctx, "lo parts", encoder)?;
        }
        Ok(())
    }
}

/// The slots of mapped staging views, each with the index of its first particle (`part_bytes`
/// per part).
fn slots(views: &mut [wgpu::BufferViewMut], part_bytes: u64) -> Vec<(usize, Slots16<'_>)> {
    let per_part = (part_bytes / PARTICLE_BYTES) as usize;
    views
        .iter_mut()
        .enumerate()
        .map(|(i, v)| (i * per_part, view_slots::<16>(v)))
        .collect()
}

/// Slots of `N` bytes over a mapped staging view (wgpu hands its memory out write-only).
fn view_slots<const N: usize>(view: &mut wgpu::BufferViewMut) -> Slots<'_, [u8; N]> {
    let mut memory = view.slice(..).into_chunks::<N>().0;
    let len = memory.len();
    // SAFETY: the view's memory is valid for writes of `len` elements of `N` bytes (alignment
    // 1) and the `WriteOnly`'s alone while the view is borrowed; it is consumed here, and its
    // access passes to the slots.
    unsafe { Slots::from_raw(memory.as_raw_element_ptr(), len) }
}

/// Stage 1 alone on `points` (local coordinates in xyz), its outputs poisoned first: each
/// particle's key and the permutation it writes (a test entry point).
pub fn hilbert_keys(
    ctx: &GpuContext,
    points: &[[f32; 4]],
    quantizer: &HilbertQuantizer,
) -> Result<(Vec<u64>, Vec<u32>), BackendError> {
    let n = points.len();
    let prepare = Prepare::new(ctx, n, ctx.max_binding())?;
    prepare.poison(ctx);
    prepare
        .points
        .device
        .write(ctx, bytemuck::cast_slice(points));
    prepare.write_params(ctx, quantizer, n);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    ctx.scoped("hilbert keys", || prepare.encode_keys(ctx, &mut encoder, n))??;
    submit_and_wait(ctx, "hilbert keys", encoder)?;
    let lo = read_u32(ctx, &prepare.keys, n)?;
    let hi = read_u32(ctx, &prepare.keys_hi, n)?;
    let keys = lo
        .iter()
        .zip(&hi)
        .map(|(&l, &h)| u64::from(h) << 32 | u64::from(l))
        .collect();
    Ok((keys, read_u32(ctx, &prepare.values, n)?))
}
