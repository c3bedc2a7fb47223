//! One particle dataset of an HDF5 snapshot: its shape and type checked, then read and
//! converted to f64, and whether every value is finite found as it is (so `finish_step` need
//! not sweep the step again). A contiguous, uncompressed dataset of native doubles or floats
//! is one run of the values' bytes in the file: read directly, a block at a time by the
//! calling thread and helpers, each block widened and checked while in cache. Any other is read whole by HDF5 in its stored
//! type (decompressed chunk by chunk into the one array) and converted in parallel; doubles
//! are used as read.

use std::ops::Range;

use ::hdf5::Dataset;
use ::hdf5::types::{FloatSize, IntSize, TypeDescriptor};

use crate::io::{At, DataError};

/// Deflate cannot shrink data by more than about 1032:1, so a dataset whose stored bytes are
/// fewer than its logical bytes over this claims rows it does not hold (chunks never written
/// read as fill values): refused before anything is allocated for them.
const MAX_COMPRESSION_RATIO: u64 = 1100;

/// How a dataset's values are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    F32,
    F64,
    I64,
    U64,
}

impl Kind {
    fn of(descriptor: &TypeDescriptor) -> Option<(Kind, u64)> {
        Some(match descriptor {
            TypeDescriptor::Float(FloatSize::U4) => (Kind::F32, 4),
            TypeDescriptor::Float(FloatSize::U8) => (Kind::F64, 8),
            TypeDescriptor::Integer(size) => (Kind::I64, int_bytes(*size)),
            TypeDescriptor::Unsigned(size) => (Kind::U64, int_bytes(*size)),
            _ => return None,
        })
    }
}

fn int_bytes(size: IntSize) -> u64 {
    match size {
        IntSize::U1 => 1,
        IntSize::U2 => 2,
        IntSize::U4 => 4,
        IntSize::U8 => 8,
    }
}

/// A particle dataset: `rows` particles of `components` values each.
#[derive(Clone, Debug)]
pub(super) struct Column {
    /// The dataset's name within its particle-type group (`Coordinates`).
    pub name: String,
    pub rows: usize,
    pub components: usize,
    pub kind: Kind,
    bytes_per_value: u64,
}

impl Column {
    /// The shape and type of `dataset`; `None` for datasets that are not per-particle numbers
    /// (strings, compound types, more than two dimensions), which cannot be attributes.
    pub(super) fn of(name: &str, dataset: &Dataset) -> Option<Column> {
        let (kind, bytes_per_value) = Kind::of(&dataset.dtype().ok()?.to_descriptor().ok()?)?;
        let shape = dataset.shape();
        let (rows, components) = match shape.as_slice() {
            [rows] => (*rows, 1),
            [rows, components] if *components > 0 => (*rows, *components),
            _ => return None,
        };
        Some(Column {
            name: name.to_owned(),
            rows,
            components,
            kind,
            bytes_per_value,
        })
    }

    /// Reads the values of the rows `rows` (row-major, `components` per particle) as f64 into
    /// `out` (exactly that many rows x components long), after checking the file stores as
    /// many bytes as the shape claims, and says whether every value is finite. A contiguous
    /// dataset of native floats or doubles is read from the file directly ([`read_direct`]);
    /// otherwise all rows are read by HDF5 (doubles straight into `out`, other types into one
    /// buffer of their own, converted into `out` in parallel), and some rows as a hyperslab.
    /// (Read block by block through HDF5's hyperslabs it was 8x h5py's time on 4M uncompressed
    /// particles: each block's selection, copy and conversion; a rank's part is one hyperslab.)
    pub(super) fn read_into(
        &self,
        at: At<'_>,
        group: &str,
        dataset: &Dataset,
        rows: Range<usize>,
        out: &mut [f64],
    ) -> Result<bool, DataError> {
        let values = self.rows as u64 * self.components as u64;
        let logical = values * self.bytes_per_value;
        let stored = dataset.storage_size();
        let ratio = if dataset.filters().is_empty() {
            1
        } else {
            MAX_COMPRESSION_RATIO
        };
        if stored.saturating_mul(ratio) < logical {
            return Err(at.malformed(format!(
                "dataset '/{group}/{}' claims {} x {} values ({logical} bytes) but the file \
                 stores only {stored} bytes of it",
                self.name, self.rows, self.components
            )));
        }
        let wanted = rows.len() as u64 * self.components as u64;
        if rows.end > self.rows || out.len() as u64 != wanted {
            return Err(at.malformed(format!(
                "dataset '/{group}/{}' has {} rows of {} values where rows {}..{} ({} values) \
                 were expected",
                self.name,
                self.rows,
                self.components,
                rows.start,
                rows.end,
                out.len()
            )));
        }
        let cannot = |e: String| {
            at.malformed(format!(
                "dataset '/{group}/{}': cannot read its {} x {} values: {e}",
                self.name, self.rows, self.components
            ))
        };
        #[cfg(unix)]
        if let Some(offset) = self.direct_offset(at, dataset, logical) {
            let skip = rows.start as u64 * self.components as u64 * self.bytes_per_value;
            return read_direct(at.file, offset + skip, self.kind, out)
                .map_err(|e| cannot(e.to_string()));
        }
        if rows.len() < self.rows {
            let read = match self.kind {
                Kind::F64 => self.read_rows::<f64>(dataset, rows, out, |x| x),
                Kind::F32 => self.read_rows::<f32>(dataset, rows, out, f64::from),
                Kind::I64 => self.read_rows::<i64>(dataset, rows, out, |x| x as f64),
                Kind::U64 => self.read_rows::<u64>(dataset, rows, out, |x| x as f64),
            };
            return read.map_err(|e| cannot(e.to_string()));
        }
        let n = out.len();
        let read = match self.kind {
            Kind::F64 => dataset
                .read_into_raw::<f64>(out)
                .map(|_| crate::io::all_finite(out)),
            Kind::F32 => read_widened::<f32>(dataset, n, out, f64::from),
            Kind::I64 => read_widened::<i64>(dataset, n, out, |x| x as f64),
            Kind::U64 => read_widened::<u64>(dataset, n, out, |x| x as f64),
        };
        read.map_err(|e| cannot(e.to_string()))
    }

    /// The rows `rows` of `dataset` in the type `T` (one hyperslab, which HDF5 reads chunk by
    /// chunk), converted into `out`; whether every value is finite.
    fn read_rows<T: ::hdf5::H5Type + Copy>(
        &self,
        dataset: &Dataset,
        rows: Range<usize>,
        out: &mut [f64],
        convert: impl Fn(T) -> f64,
    ) -> ::hdf5::Result<bool> {
        if rows.is_empty() {
            return Ok(true);
        }
        let stored: Vec<T> = if self.components == 1 && dataset.ndim() == 1 {
            dataset
                .read_slice_1d::<T, _>(rows)?
                .iter()
                .copied()
                .collect()
        } else {
            dataset
                .read_slice_2d::<T, _>((rows, ..))?
                .iter()
                .copied()
                .collect()
        };
        Ok(widen_checked(&stored, out, convert))
    }

    /// Where the dataset's values lie in its file as one run of bytes that are the values
    /// themselves, if they do: a contiguous dataset, unfiltered, its storage allocated, not in
    /// an external file, of doubles or floats in this machine's byte order, within the file.
    /// (`H5Dget_offset`, which h5py offers as `get_offset` for reading such data directly.)
    #[cfg(unix)]
    fn direct_offset(&self, at: At<'_>, dataset: &Dataset, logical: u64) -> Option<u64> {
        use ::hdf5::Datatype;
        use ::hdf5::dataset::Layout;
        let native = match self.kind {
            Kind::F64 => Datatype::from_type::<f64>(),
            Kind::F32 => Datatype::from_type::<f32>(),
            Kind::I64 | Kind::U64 => return None,
        };
        let plist = dataset.dcpl().ok()?;
        let direct = plist.layout() == Layout::Contiguous
            && plist.filters().is_empty()
            && plist.external().is_empty()
            && dataset.storage_size() == logical
            && dataset.dtype().ok()? == native.ok()?;
        let offset = dataset.offset().filter(|_| direct)?;
        let file_len = std::fs::metadata(at.file).ok()?.len();
        (offset.checked_add(logical)? <= file_len).then_some(offset)
    }
}

/// Readers a direct read may use at most: the calling thread and helpers (beyond a few, the
/// memory bus is the limit).
const MAX_READERS: usize = 4;

/// Reads `out.len()` values of `kind` (f64 or f32, native) at `offset` in `file` into `out`, a
/// block of 64K values at a time: doubles `pread` into `out`, floats into a small buffer and
/// widened from there, each block checked for finiteness while it is in cache; whether every
/// value is finite. The calling thread reads, and helper threads (one per other core, up to
/// [`MAX_READERS`] in all) take blocks from the same queue when the system runs them: on an
/// idle core a helper takes about a third off the read, and on a busy machine the caller does
/// not wait for one to start (rayon's pool made it wait: the caller handed the pool all the
/// blocks, 1.21x h5py at the median of ten rounds on a busy machine against 1.13x for the
/// caller alone), nor, during playback, for the renderer's jobs in that pool.
#[cfg(unix)]
fn read_direct(
    file: &std::path::Path,
    offset: u64,
    kind: Kind,
    out: &mut [f64],
) -> std::io::Result<bool> {
    use std::os::unix::fs::FileExt;
    use std::sync::{Mutex, PoisonError};
    const BLOCK: usize = crate::io::FINITE_BLOCK;
    let file = std::fs::File::open(file)?;
    let helpers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(MAX_READERS)
        .min(out.len().div_ceil(BLOCK))
        .saturating_sub(1);
    let blocks = Mutex::new(out.chunks_mut(BLOCK).enumerate());
    let read = || -> std::io::Result<bool> {
        let mut floats = vec![0f32; if kind == Kind::F32 { BLOCK } else { 0 }];
        let mut finite = true;
        loop {
            let next = blocks.lock().unwrap_or_else(PoisonError::into_inner).next();
            let Some((b, out)) = next else {
                return Ok(finite);
            };
            if kind == Kind::F64 {
                let at = offset + (b * BLOCK * 8) as u64;
                file.read_exact_at(bytemuck::cast_slice_mut(out), at)?;
                finite &= crate::io::block_finite(out);
            } else {
                let stored = &mut floats[..out.len()];
                let at = offset + (b * BLOCK * 4) as u64;
                file.read_exact_at(bytemuck::cast_slice_mut(stored), at)?;
                finite &= widen_checked(stored, out, f64::from);
            }
        }
    };
    std::thread::scope(|scope| {
        let helpers: Vec<_> = (0..helpers).map(|_| scope.spawn(read)).collect();
        let mine = read();
        helpers.into_iter().fold(mine, |all, helper| {
            let theirs = helper
                .join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            Ok(all? & theirs?)
        })
    })
}

/// Reads `dataset` (n values) in the type `T`, into a buffer of its own, and converts it into
/// `out` in parallel; whether every value is finite, found in the same pass.
fn read_widened<T: ::hdf5::H5Type + Copy + Default + Send + Sync>(
    dataset: &Dataset,
    n: usize,
    out: &mut [f64],
    convert: impl Fn(T) -> f64 + Send + Sync,
) -> ::hdf5::Result<bool> {
    use rayon::prelude::*;
    let mut stored = fresh::<T>(n);
    dataset.read_into_raw::<T>(&mut stored)?;
    Ok(out
        .par_chunks_mut(crate::io::FINITE_BLOCK)
        .zip(stored.par_chunks(crate::io::FINITE_BLOCK))
        .map(|(out, stored)| widen_checked(stored, out, &convert))
        .reduce(|| true, |a, b| a & b))
}

/// `out[i] = convert(stored[i])`, and whether every value written is finite (checked as
/// [`crate::io::block_finite`] does, in the same loop).
fn widen_checked<T: Copy>(stored: &[T], out: &mut [f64], convert: impl Fn(T) -> f64) -> bool {
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    const ONE: u64 = 0x0010_0000_0000_0000;
    let carry = out.iter_mut().zip(stored).fold(0, |carry, (o, &v)| {
        *o = convert(v);
        carry | ((o.to_bits() & EXPONENT) + ONE)
    });
    carry >> 63 == 0
}

/// A buffer of `len` zeros for a large read, which the read then fills: allocated zeroed, so
/// its pages come fresh from the system untouched (no pass that clears them), and on Linux
/// advised to be backed by transparent huge pages, as NumPy does for the arrays h5py reads
/// into. Faulting a 100 MB array in 4 KiB pages (25,000 faults, each clearing its page) took a
/// third of an uncompressed read; in 2 MiB pages it is 50 faults.
pub(super) fn fresh<T: Copy + Default>(len: usize) -> Vec<T> {
    let mut v = vec![T::default(); len];
    advise_huge_pages(&mut v);
    v
}

#[cfg(target_os = "linux")]
fn advise_huge_pages<T>(v: &mut [T]) {
    const PAGE: usize = 4096;
    const HUGE_PAGE: usize = 2 << 20;
    let bytes = std::mem::size_of_val(v);
    if bytes < 2 * HUGE_PAGE {
        return;
    }
    let start = (v.as_mut_ptr() as usize).next_multiple_of(PAGE);
    let end = (v.as_mut_ptr() as usize + bytes) / PAGE * PAGE;
    // SAFETY: the range lies within `v`'s allocation (rounded inwards to whole pages), and
    // MADV_HUGEPAGE only tells the kernel how to back those pages: it changes neither their
    // contents nor the mapping's permissions, and a kernel without transparent huge pages
    // ignores it (an error return is harmless: the pages are then ordinary ones).
    unsafe {
        libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages<T>(_v: &mut [T]) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn widening_finds_every_float_that_is_not_finite() {
        let floats = [
            0.0f32,
            -0.0,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            f32::MAX,
            f32::MIN,
        ];
        let mut out = [0.0; 7];
        assert!(widen_checked(&floats, &mut out[..6], f64::from));
        assert_eq!(out[..6], floats.map(f64::from));
        for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN] {
            for at in 0..=floats.len() {
                let mut stored = floats.to_vec();
                stored.insert(at, bad);
                assert!(
                    !widen_checked(&stored, &mut out, f64::from),
                    "{bad:?} at {at}"
                );
            }
        }
        assert!(widen_checked(&[i64::MAX, i64::MIN], &mut out[..2], |x| x as f64));
    }
}
