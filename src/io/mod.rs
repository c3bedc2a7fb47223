//! Readers and writers for particle data.
//!
//! Every reader turns one file (or one step of a `.particles` header) into a [`Step`], through
//! [`finish_step`], which checks array lengths, keeps the attributes asked for, drops particles
//! with NaN/Inf values (with a warning that counts them) and refuses empty steps. A series is a
//! file, a directory or a glob, sorted naturally (`step2` before `step10`); in a folder of
//! several name patterns (boundary, restart, species files beside the steps), the pattern with
//! the most steps. A rank of a distributed render reads only its part of a step
//! ([`read_step_part`]).

mod components;
pub mod csv;
pub mod error;
mod finish;
mod finite;
mod format;
mod hdf5_gate;
#[cfg(feature = "hdf5")]
pub mod hdf5_snapshot;
mod listing;
mod mapped;
pub mod natural;
pub mod npy;
pub mod output;
mod part;
pub mod particles;
pub mod ply;
pub mod pvd;
pub mod raw;
pub mod read_options;
mod scalar;
mod source;
pub mod stems;
pub mod text;
pub mod vtk;
mod write;

use std::path::Path;

pub(crate) use components::{array_attribute_names, split_components};
pub use error::{At, DataError, Location, Problem};
pub use finish::{Columns, finish_step};
pub(crate) use finite::{FINITE_BLOCK, all_finite, block_finite};
pub use format::Format;
pub use listing::{
    SimulationBox, StepRef, list_steps, list_steps_reading, simulation_box, step_time,
};
pub use part::{Part, StepPart, slice_step};
pub use read_options::{ParticleType, ReadOptions};
pub use source::SeriesSource;
pub use write::{existing_outputs, write_series, write_series_from};

use crate::values::Step;

/// Which attributes a read keeps. Reading only what a scene needs keeps the memory it costs
/// to what it uses.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum AttributeSelection {
    /// Every attribute the data holds.
    #[default]
    All,
    /// Only the attributes of these names, kept in this order (a name the data lacks is an error).
    Only(Vec<String>),
}

impl AttributeSelection {
    /// Whether an attribute of this name is kept (readers skip decoding the others).
    pub fn keeps(&self, name: &str) -> bool {
        match self {
            AttributeSelection::All => true,
            AttributeSelection::Only(names) => names.iter().any(|n| n == name),
        }
    }
}

/// Reads one step, keeping the attributes `selection` names.
pub fn read_step(step: &StepRef, selection: &AttributeSelection) -> Result<Step, DataError> {
    read_step_part(step, selection, Part::WHOLE).map(|read| read.step)
}

/// Reads rank `part.rank`'s part of one step, keeping the attributes `selection` names: the
/// same records, checks and cleaning as [`read_step`] on them, but possibly empty (the whole
/// step, [`Part::WHOLE`], is refused empty).
pub fn read_step_part(
    step: &StepRef,
    selection: &AttributeSelection,
    part: Part,
) -> Result<StepPart, DataError> {
    let at = step.at();
    let (columns, decoded) = read_columns(step, selection, part)?;
    let step = finish::finish(at, &step.name, columns, selection, !part.is_whole())?;
    Ok(StepPart { step, decoded })
}

/// `part`'s columns of one step, before the checks and cleaning, and the records decoded:
/// every format's reader, each reading what it can of a part alone.
fn read_columns(
    step: &StepRef,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let at = step.at();
    Ok(match step.format {
        Format::Particles => particles::read_step(at, selection, part)?,
        Format::Raw => raw::read_step(at, selection, part)?,
        Format::Npy => npy::read_step(at, selection, part)?,
        Format::Csv => csv::read_step(at, selection, part)?,
        Format::Ply => ply::read_step(at, selection, part)?,
        Format::Hdf5 => hdf5_gate::read_step(at, &step.read, selection, part)?,
        Format::Vtk | Format::VtkXml => {
            vtk::read_step(at, step.format == Format::Vtk, selection, part)?
        }
    })
}

/// The size of an open file, for checking counts against it.
pub(crate) fn file_len(at: At<'_>, file: &std::fs::File) -> Result<u64, DataError> {
    Ok(file.metadata().map_err(|e| at.io(e))?.len())
}

/// Reads one step of `format` from bytes (through a temporary file, as the readers read files):
/// what the fuzz targets and their regression tests call. For `.particles` the bytes are a step
/// file (count + records) under a one-step header.
pub fn read_bytes(format: Format, data: &[u8]) -> Result<Step, DataError> {
    // Memory-backed where available: fuzzers call this many thousand times a second.
    let shm = Path::new("/dev/shm");
    let base = if shm.is_dir() {
        shm.to_path_buf()
    } else {
        std::env::temp_dir()
    };
    let dir = tempfile::Builder::new()
        .prefix("aarbf-read-")
        .tempdir_in(base)
        .map_err(|e| DataError::new("<temporary directory>", None, Problem::Io(e)))?;
    let path = dir.path().join(format!("input.{}", format.extension()));
    let write = |p: &Path, bytes: &[u8]| {
        std::fs::write(p, bytes).map_err(|e| DataError::new(p, None, Problem::Io(e)))
    };
    let (path, name) = if format == Format::Particles {
        write(&path, b"0\n")?;
        let step = particles::step_path(&path, "0");
        write(&step, data)?;
        (step, "0")
    } else {
        write(&path, data)?;
        (path, "input")
    };
    let step = StepRef {
        path,
        format,
        name: name.into(),
        read: ReadOptions::default(),
        time: None,
    };
    read_step(&step, &AttributeSelection::All)
}
