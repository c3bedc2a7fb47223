//! Write-only slots over the memory a step is staged into, and the staging pass that fills
//! them in parallel.

use rayon::prelude::*;
use wgpu::WriteOnly;

use super::Extremes;

/// Write-only slots of an array of 16-byte elements (a particle's vec4) or 4-byte ones (its
/// radius attribute): memory the device copies from (mapped staging buffers are write-only),
/// or a host array.
pub type Slots16<'a> = WriteOnly<'a, [[u8; 16]]>;
pub type Slots4<'a> = WriteOnly<'a, [[u8; 4]]>;

/// Slots over a host array of vec4s.
pub fn slots16(v: &mut [[f32; 4]]) -> Slots16<'_> {
    WriteOnly::from_mut(bytemuck::cast_slice_mut(v))
}

/// Slots over a host array of f32s.
pub fn slots4(v: &mut [f32]) -> Slots4<'_> {
    WriteOnly::from_mut(bytemuck::cast_slice_mut(v))
}

/// Particles one task of a staging pass converts (large enough that rayon's overhead is
/// nothing, small enough that two cores share the work evenly).
pub(super) const CHUNK: usize = 1 << 14;

/// Writes `f(i, extremes)` for every particle `i` of `parts` (slots for particles `first ..`,
/// the parts in order, covering a prefix of the step), its second value into the matching slot
/// of a second array when one is given (covering the same particles from 0), in parallel over
/// tasks of [`CHUNK`] particles; returns the extremes the calls gathered. (A mapped slice
/// cannot move to another thread, a fixed-size array of slots can: the tasks are whole chunks,
/// and the few particles past a part's last chunk run on the calling thread.)
pub(super) fn for_each_particle<'a, A, B, F>(
    parts: Vec<(usize, WriteOnly<'a, [A]>)>,
    mut second: Option<WriteOnly<'a, [B]>>,
    f: F,
) -> Extremes
where
    A: Copy + Default + Send,
    B: Copy + Default + Send,
    F: Fn(usize, &mut Extremes) -> (A, Option<B>) + Sync,
{
    type Chunk<'a, T> = WriteOnly<'a, [T; CHUNK]>;
    let mut chunks: Vec<(usize, Chunk<'a, A>, Option<Chunk<'a, B>>)> = Vec::new();
    let mut tails = Vec::new();
    for (first, slots) in parts {
        let len = slots.len();
        let paired = match second.take() {
            Some(s) => {
                let available = s.len();
                let (head, rest) = s.split_at(len.min(available));
                second = Some(rest);
                Some(head.into_chunks::<CHUNK>())
            }
            None => None,
        };
        let (full, tail) = slots.into_chunks::<CHUNK>();
        let whole = full.len();
        let (paired_full, paired_tail) = match paired {
            Some((f, t)) => (Some(f.into_iter()), Some(t)),
            None => (None, None),
        };
        let mut paired_full = paired_full;
        for (j, chunk) in full.into_iter().enumerate() {
            let b = paired_full.as_mut().and_then(Iterator::next);
            chunks.push((first + j * CHUNK, chunk, b));
        }
        tails.push((first + whole * CHUNK, tail, paired_tail));
    }
    let chunked = chunks
        .into_par_iter()
        .map(|(first, a, b)| {
            let mut e = Extremes::NONE;
            fill(first, a.into(), b.map(Into::into), &f, &mut e);
            e
        })
        .reduce(|| Extremes::NONE, Extremes::merge);
    let mut e = Extremes::NONE;
    for (first, a, b) in tails {
        fill(first, a, b, &f, &mut e);
    }
    Extremes::merge(chunked, e)
}

/// Writes `f(i)` for particles `first ..` into `a` (and the second values into `b`), a batch
/// at a time: the values are made in a small array and copied into the slots in one go, which
/// costs less than a write through a slot per particle.
pub(super) fn fill<A, B, F>(
    first: usize,
    mut a: WriteOnly<'_, [A]>,
    mut b: Option<WriteOnly<'_, [B]>>,
    f: &F,
    e: &mut Extremes,
) where
    A: Copy + Default,
    B: Copy + Default,
    F: Fn(usize, &mut Extremes) -> (A, Option<B>),
{
    const BATCH: usize = 256;
    let mut values_a = [A::default(); BATCH];
    let mut values_b = [B::default(); BATCH];
    let mut at = first;
    while !a.is_empty() {
        let k = BATCH.min(a.len());
        for j in 0..k {
            let (x, y) = f(at + j, e);
            values_a[j] = x;
            if let Some(y) = y {
                values_b[j] = y;
            }
        }
        let (head, rest) = a.split_at(k);
        stream_into(head, &values_a[..k]);
        a = rest;
        if let Some(slots) = b.take() {
            let m = k.min(slots.len());
            let (mut head, rest) = slots.split_at(m);
            head.copy_from_slice(&values_b[..m]);
            b = Some(rest);
        }
        at += k;
    }
}

/// Copies `src` into `dst` (of equal length). Slots of 16 bytes at 16-byte addresses (the
/// staging pass's particles) are written with non-temporal stores: the step goes to memory the
/// device reads, not to the CPU's caches, and a plain store first reads each line it fills
/// (16 MiB of writes per 1M particles cost 32 MiB of traffic), where an in-memory copy of the
/// step (`memcpy`) uses the same stores (docs/notes/2026-12-03-playback.md, "Non-temporal
/// stores in the staging pass").
pub(super) fn stream_into<A: Copy>(mut dst: WriteOnly<'_, [A]>, src: &[A]) {
    assert_eq!(dst.len(), src.len(), "a slot per value");
    #[cfg(target_arch = "x86_64")]
    if size_of::<A>() == 16 {
        let to = dst
            .as_raw_element_ptr()
            .as_ptr()
            .cast::<core::arch::x86_64::__m128i>();
        if to.is_aligned() {
            for (i, v) in src.iter().enumerate() {
                // SAFETY: `dst` holds `src.len()` writable 16-byte slots from `to`, which is
                // 16-byte aligned (checked); SSE2 is part of x86-64. The value is read
                // unaligned from `src`.
                unsafe {
                    let v = core::ptr::read_unaligned((v as *const A).cast());
                    core::arch::x86_64::_mm_stream_si128(to.add(i), v);
                }
            }
            // Non-temporal stores are weakly ordered: fence them before the slots are handed
            // on (to another thread, or unmapped for the device).
            // SAFETY: SSE2 is part of x86-64.
            unsafe { core::arch::x86_64::_mm_sfence() };
            return;
        }
    }
    dst.copy_from_slice(src);
}
