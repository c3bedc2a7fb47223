//! The HDF5 reader where this build has it (the default feature `hdf5`), else an error that
//! says how to get it.

use std::path::Path;

#[cfg(not(feature = "hdf5"))]
use super::Problem;
use super::{At, AttributeSelection, Columns, DataError, Part, ReadOptions};

/// `part`'s particles of the snapshot, and how many were decoded.
#[cfg(feature = "hdf5")]
pub(super) fn read_step(
    at: At<'_>,
    read: &ReadOptions,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    super::hdf5_snapshot::read_step(at, read, selection, part)
}

/// Without HDF5 support: an error that says how to get it.
#[cfg(not(feature = "hdf5"))]
pub(super) fn read_step(
    at: At<'_>,
    _read: &ReadOptions,
    _selection: &AttributeSelection,
    _part: Part,
) -> Result<(Columns, usize), DataError> {
    Err(at.err(Problem::UnknownFormat(
        "this aarbf was built without HDF5 support; build it with the default features \
         (the `hdf5` feature, which needs the HDF5 library: `apt-get install libhdf5-dev` or \
         `cargo xtask setup`), e.g. `cargo install --path . --features hdf5`"
            .into(),
    )))
}

#[cfg(feature = "hdf5")]
pub(super) fn time(path: &Path) -> Option<f64> {
    super::hdf5_snapshot::time(path)
}

#[cfg(not(feature = "hdf5"))]
pub fn time(_path: &Path) -> Option<f64> {
    None
}

#[cfg(feature = "hdf5")]
pub(super) fn simulation_box(
    path: &Path,
    read: &ReadOptions,
) -> Result<Option<super::SimulationBox>, DataError> {
    super::hdf5_snapshot::simulation_box(path, read)
}

#[cfg(not(feature = "hdf5"))]
pub fn simulation_box(
    _path: &Path,
    _read: &ReadOptions,
) -> Result<Option<super::SimulationBox>, DataError> {
    Ok(None)
}
