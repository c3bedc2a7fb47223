//! Write-only slots over the memory a step is staged into, and the staging pass that fills
//! them in parallel.

use std::marker::PhantomData;
use std::ptr::NonNull;

use rayon::prelude::*;

use super::Extremes;

/// Write-only slots: exclusive access to `len` elements that are written and never read. The
/// staging pass writes the memory the device copies from, which a GPU API maps for writing
/// only (it may be write-combined: a read is slow, or not promised at all); each GPU backend
/// makes slots of its mapped memory, and [`Slots::from_mut`] of a host array.
pub struct Slots<'a, T> {
    ptr: NonNull<T>,
    len: usize,
    _memory: PhantomData<&'a mut [T]>,
}

// SAFETY: slots are like `&mut [T]`: their access is exclusive, so sending them sends no more
// than the right to write `T`s.
unsafe impl<T: Send> Send for Slots<'_, T> {}

impl<'a, T> Slots<'a, T> {
    /// Slots over `len` elements from `ptr`.
    ///
    /// # Safety
    /// `ptr` is aligned for `T` and valid for writes of `len` elements, and nothing else
    /// accesses them during `'a`.
    #[inline]
    pub unsafe fn from_raw(ptr: NonNull<T>, len: usize) -> Slots<'a, T> {
        Slots {
            ptr,
            len,
            _memory: PhantomData,
        }
    }

    /// Slots over a host array.
    #[inline]
    pub fn from_mut(slice: &'a mut [T]) -> Slots<'a, T> {
        let len = slice.len();
        // SAFETY: a mutable borrow for 'a meets every condition.
        unsafe { Slots::from_raw(NonNull::from(slice).cast(), len) }
    }

    /// How many slots.
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no slots.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The first `mid` slots and the rest.
    #[inline]
    #[track_caller]
    pub fn split_at(self, mid: usize) -> (Slots<'a, T>, Slots<'a, T>) {
        assert!(mid <= self.len, "mid > len");
        // SAFETY: the two runs are disjoint parts of this one, which they replace.
        unsafe {
            (
                Slots::from_raw(self.ptr, mid),
                Slots::from_raw(self.ptr.add(mid), self.len - mid),
            )
        }
    }

    /// Consecutive runs of `n` slots, and the fewer than `n` left after them.
    #[inline]
    pub fn chunks(self, n: usize) -> (impl Iterator<Item = Slots<'a, T>>, Slots<'a, T>) {
        assert!(n != 0, "chunk size must be non-zero");
        let whole = self.len / n;
        let (full, tail) = self.split_at(whole * n);
        let ptr = full.ptr;
        // SAFETY: the runs are disjoint parts of `full`, which they replace.
        let runs = (0..whole).map(move |j| unsafe { Slots::from_raw(ptr.add(j * n), n) });
        (runs, tail)
    }

    /// Writes `src` (of the slots' length) into the slots.
    #[inline]
    #[track_caller]
    pub fn copy_from_slice(&mut self, src: &[T])
    where
        T: Copy,
    {
        assert_eq!(self.len, src.len(), "a slot per value");
        // SAFETY: the slots are valid for writes of `len` elements and cannot overlap `src`,
        // which is borrowed while they are borrowed mutably.
        unsafe {
            self.ptr
                .as_ptr()
                .copy_from_nonoverlapping(src.as_ptr(), src.len())
        }
    }

    /// The first slot's address, for writes the methods here do not make (never reads).
    #[inline]
    pub fn as_mut_ptr(&mut self) -> *mut T {
        self.ptr.as_ptr()
    }
}

/// Write-only slots of an array of 16-byte elements (a particle's vec4) or 4-byte ones (its
/// radius attribute).
pub type Slots16<'a> = Slots<'a, [u8; 16]>;
/// Write-only slots of an array of 4-byte elements (a particle's radius attribute).
pub type Slots4<'a> = Slots<'a, [u8; 4]>;

/// Slots over a host array of vec4s.
pub fn slots16(v: &mut [[f32; 4]]) -> Slots16<'_> {
    Slots::from_mut(bytemuck::cast_slice_mut(v))
}

/// Slots over a host array of f32s.
pub fn slots4(v: &mut [f32]) -> Slots4<'_> {
    Slots::from_mut(bytemuck::cast_slice_mut(v))
}

/// Particles one task of a staging pass converts (large enough that rayon's overhead is
/// nothing, small enough that two cores share the work evenly).
pub(super) const CHUNK: usize = 1 << 14;

/// Writes `f(i, extremes)` for every particle `i` of `parts` (slots for particles `first ..`,
/// the parts in order, covering a prefix of the step), its second value into the matching slot
/// of a second array when one is given (covering the same particles from 0), in parallel over
/// tasks of [`CHUNK`] particles; returns the extremes the calls gathered. (The tasks are whole
/// chunks; the few particles past a part's last chunk run on the calling thread.)
pub(super) fn for_each_particle<'a, A, B, F>(
    parts: Vec<(usize, Slots<'a, A>)>,
    mut second: Option<Slots<'a, B>>,
    f: F,
) -> Extremes
where
    A: Copy + Default + Send,
    B: Copy + Default + Send,
    F: Fn(usize, &mut Extremes) -> (A, Option<B>) + Sync,
{
    // Chunks are runs of CHUNK slots.
    let mut chunks: Vec<(usize, Slots<'a, A>, Option<Slots<'a, B>>)> = Vec::new();
    let mut tails = Vec::new();
    for (first, slots) in parts {
        let len = slots.len();
        let paired = match second.take() {
            Some(s) => {
                let available = s.len();
                let (head, rest) = s.split_at(len.min(available));
                second = Some(rest);
                Some(head.chunks(CHUNK))
            }
            None => None,
        };
        let whole = len / CHUNK;
        let (full, tail) = slots.chunks(CHUNK);
        let (mut paired_full, paired_tail) = match paired {
            Some((f, t)) => (Some(f), Some(t)),
            None => (None, None),
        };
        for (j, chunk) in full.enumerate() {
            let b = paired_full.as_mut().and_then(Iterator::next);
            chunks.push((first + j * CHUNK, chunk, b));
        }
        tails.push((first + whole * CHUNK, tail, paired_tail));
    }
    let chunked = chunks
        .into_par_iter()
        .map(|(first, a, b)| {
            let mut e = Extremes::NONE;
            fill(first, a, b, &f, &mut e);
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
    mut a: Slots<'_, A>,
    mut b: Option<Slots<'_, B>>,
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
pub(super) fn stream_into<A: Copy>(mut dst: Slots<'_, A>, src: &[A]) {
    assert_eq!(dst.len(), src.len(), "a slot per value");
    #[cfg(target_arch = "x86_64")]
    if size_of::<A>() == 16 {
        let to = dst.as_mut_ptr().cast::<core::arch::x86_64::__m128i>();
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
