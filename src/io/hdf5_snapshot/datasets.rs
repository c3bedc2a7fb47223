//! One particle dataset of an HDF5 snapshot: its shape and type checked, then read whole in its
//! stored type (HDF5 decompresses chunk by chunk into the one array) and converted to f64 in
//! parallel; doubles are used as read.

use ::hdf5::Dataset;
use ::hdf5::types::{FloatSize, IntSize, TypeDescriptor};

use crate::io::{At, DataError};

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

    /// Reads every value (row-major, `components` per particle) as f64, after checking the file
    /// stores as many bytes as the shape claims. (Read block by block through hyperslabs it was
    /// 8x h5py's time on 4M uncompressed particles: each block's selection, copy and conversion.)
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
        let read = match self.kind {
            // Doubles land in the output as HDF5 reads them: no copy, no conversion.
            Kind::F64 => dataset.read_raw::<f64>(),
            Kind::F32 => dataset.read_raw::<f32>().map(|v| widen(&v, f64::from)),
            Kind::I64 => dataset.read_raw::<i64>().map(|v| widen(&v, |x| x as f64)),
            Kind::U64 => dataset.read_raw::<u64>().map(|v| widen(&v, |x| x as f64)),
        };
        let out = read.map_err(|e| {
            at.malformed(format!(
                "dataset '/{group}/{}': cannot read its {} x {} values: {e}",
                self.name, self.rows, self.components
            ))
        })?;
        if out.len() as u64 != values {
            return Err(at.malformed(format!(
                "dataset '/{group}/{}' gave {} values where its shape says {values}",
                self.name,
                out.len()
            )));
        }
        Ok(out)
    }
}

/// `values` as f64, converted in parallel.
fn widen<T: Copy + Send + Sync>(
    values: &[T],
    convert: impl Fn(T) -> f64 + Send + Sync,
) -> Vec<f64> {
    use rayon::prelude::*;
    values.par_iter().map(|&v| convert(v)).collect()
}
