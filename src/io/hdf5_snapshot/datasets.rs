//! One particle dataset of an HDF5 snapshot: its shape and type checked, then read block by
//! block (hyperslabs of whole chunks), converted to f64.

use ::hdf5::types::{FloatSize, IntSize, TypeDescriptor};
use ::hdf5::{Dataset, H5Type};

use crate::io::{At, DataError};

/// Elements read per hyperslab: large enough that HDF5's per-call cost vanishes, small enough
/// that the block's copy stays in cache-sized pieces of the whole.
const BLOCK_ELEMENTS: usize = 1 << 20;

/// Deflate cannot shrink data by more than about 1032:1, so a dataset whose stored bytes are
/// fewer than its logical bytes over this claims rows it does not hold (chunks never written
/// read as fill values): refused before anything is allocated for them.
const MAX_COMPRESSION_RATIO: u64 = 1100;

/// How a dataset's values are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
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
pub struct Column {
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
    pub fn of(name: &str, dataset: &Dataset) -> Option<Column> {
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

    /// Reads every value (row-major, `components` per particle) as f64, a block of whole
    /// chunks at a time, after checking the file stores as many bytes as the shape claims.
    pub fn read(&self, at: At<'_>, group: &str, dataset: &Dataset) -> Result<Vec<f64>, DataError> {
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
        let mut out = Vec::with_capacity(values as usize);
        let chunk_rows = dataset
            .chunk()
            .and_then(|c| c.first().copied())
            .unwrap_or(1)
            .max(1);
        let block_rows = (BLOCK_ELEMENTS / self.components)
            .max(1)
            .div_ceil(chunk_rows)
            * chunk_rows;
        let mut start = 0;
        while start < self.rows {
            let end = (start + block_rows).min(self.rows);
            let read = match self.kind {
                Kind::F32 => self.block::<f32>(dataset, start, end, &mut out, f64::from),
                Kind::F64 => self.block::<f64>(dataset, start, end, &mut out, |v| v),
                Kind::I64 => self.block::<i64>(dataset, start, end, &mut out, |v| v as f64),
                Kind::U64 => self.block::<u64>(dataset, start, end, &mut out, |v| v as f64),
            };
            read.map_err(|e| {
                at.malformed(format!(
                    "dataset '/{group}/{}': cannot read rows {start}..{end}: {e}",
                    self.name
                ))
            })?;
            start = end;
        }
        Ok(out)
    }

    fn block<T: H5Type + Copy>(
        &self,
        dataset: &Dataset,
        start: usize,
        end: usize,
        out: &mut Vec<f64>,
        convert: impl Fn(T) -> f64,
    ) -> ::hdf5::Result<()> {
        let values = if self.components == 1 && dataset.ndim() == 1 {
            dataset
                .read_slice_1d::<T, _>(start..end)?
                .into_raw_vec_and_offset()
                .0
        } else {
            dataset
                .read_slice_2d::<T, _>((start..end, ..))?
                .into_raw_vec_and_offset()
                .0
        };
        out.extend(values.into_iter().map(convert));
        Ok(())
    }
}
