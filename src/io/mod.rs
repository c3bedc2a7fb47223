//! Readers and writers for particle data.
//!
//! Every reader turns one file (or one step of a `.particles` header) into a [`Step`], through
//! [`finish_step`], which checks array lengths, keeps the attributes asked for, drops particles
//! with NaN/Inf values (with a warning that counts them) and refuses empty steps. A series is a
//! file, a directory or a glob, sorted naturally (`step2` before `step10`); in a folder of
//! several name patterns (boundary, restart, species files beside the steps), the pattern with
//! the most steps.

pub mod csv;
pub mod error;
mod hdf5_gate;
#[cfg(feature = "hdf5")]
pub mod hdf5_snapshot;
mod mapped;
pub mod natural;
pub mod npy;
pub mod output;
pub mod particles;
pub mod ply;
pub mod pvd;
pub mod raw;
pub mod read_options;
mod scalar;
pub mod stems;
pub mod text;
pub mod vtk;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use glam::DVec3;
use serde::{Deserialize, Serialize};

pub use error::{At, DataError, Location, Problem};
pub use read_options::{ParticleType, ReadOptions};

use crate::values::{Attribute, Step};

/// The particle file formats we read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// The AA-RBF sample code's header + binary step files (x, y, z, attribute as f32).
    Particles,
    /// VTK XML poly data / unstructured grid (`.vtp`, `.vtu`, also `.vts`).
    VtkXml,
    /// Legacy VTK (`.vtk`).
    Vtk,
    /// Comma-separated values with a header row.
    Csv,
    /// Stanford PLY, ascii or binary, vertex element.
    Ply,
    /// Knoll et al.'s raw f32 x, y, z, w records.
    Raw,
    /// NumPy `.npy`, an N x (3 + k) array.
    Npy,
    /// HDF5 snapshots of SWIFT, GADGET-2/3/4, AREPO and GIZMO (`.hdf5`, `.h5`), one file or
    /// several per step.
    Hdf5,
}

impl Format {
    pub const ALL: [Format; 8] = [
        Format::Particles,
        Format::VtkXml,
        Format::Vtk,
        Format::Csv,
        Format::Ply,
        Format::Raw,
        Format::Npy,
        Format::Hdf5,
    ];

    /// The format a file's extension names, if any.
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "particles" => Format::Particles,
            "vtp" | "vtu" | "vts" => Format::VtkXml,
            "vtk" => Format::Vtk,
            "csv" => Format::Csv,
            "ply" => Format::Ply,
            "raw" => Format::Raw,
            "npy" => Format::Npy,
            "hdf5" | "h5" => Format::Hdf5,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Format::Particles => "particles",
            Format::VtkXml => "vtk-xml",
            Format::Vtk => "vtk",
            Format::Csv => "csv",
            Format::Ply => "ply",
            Format::Raw => "raw",
            Format::Npy => "npy",
            Format::Hdf5 => "hdf5",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Format {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let lower = s.to_ascii_lowercase();
        Format::ALL
            .into_iter()
            .find(|f| f.name() == lower)
            .or(match lower.as_str() {
                "vtp" | "vtu" | "xml" => Some(Format::VtkXml),
                "h5" => Some(Format::Hdf5),
                _ => None,
            })
            .ok_or_else(|| {
                let names: Vec<_> = Format::ALL.iter().map(|f| f.name()).collect();
                format!("unknown format '{s}'; known: {}", names.join(", "))
            })
    }
}

/// Which attributes a read keeps. Reading only what a scene needs keeps the memory it costs
/// to what it uses.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum AttributeSelection {
    #[default]
    All,
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

/// One step of a series on disk: the file it lives in, and its name.
#[derive(Clone, Debug, PartialEq)]
pub struct StepRef {
    /// The step's file (of a snapshot split over several files, the first).
    pub path: PathBuf,
    pub format: Format,
    pub name: String,
    /// What to read from files that hold a choice (HDF5 snapshots' particle types).
    pub read: ReadOptions,
    /// The step's time where the listing gives it (a `.pvd`'s `timestep`); see [`step_time`].
    pub time: Option<f64>,
}

impl StepRef {
    fn at(&self) -> At<'_> {
        // A `.particles` step's file is named after the header and the step, so the file alone
        // says which step; other formats have one step per file.
        At::new(&self.path, Some(&self.name))
    }
}

/// Lists the steps of the series at `path`: a file, a directory or a glob pattern.
///
/// `format` overrides detection by extension. A directory may hold other files too; only
/// particle files are taken, and of those the files of one name pattern, the one with the
/// most steps ([`stems::choose_series`]; the others are named in a warning).
pub fn list_steps(path: &Path, format: Option<Format>) -> Result<Vec<StepRef>, DataError> {
    list_steps_reading(path, format, ReadOptions::default())
}

/// [`list_steps`], the steps to be read with `read`.
pub fn list_steps_reading(
    path: &Path,
    format: Option<Format>,
    read: ReadOptions,
) -> Result<Vec<StepRef>, DataError> {
    if path.is_file() && pvd::is_collection(path) {
        return pvd::steps(path, format, read);
    }
    let at = At::new(path, None);
    let text = path.to_string_lossy();
    let files: Vec<PathBuf> = if text.contains(['*', '?', '[']) && !path.exists() {
        let paths = glob::glob(&text)
            .map_err(|e| at.err(Problem::Malformed(format!("bad glob pattern: {e}"))))?;
        let mut files = Vec::new();
        for p in paths {
            let p = p.map_err(|e| at.err(Problem::Io(e.into())))?;
            if p.is_file() {
                files.push(p);
            }
        }
        if files.is_empty() {
            return Err(at.malformed("the glob pattern matches no files"));
        }
        files
    } else if path.is_dir() {
        let mut files = Vec::new();
        for entry in std::fs::read_dir(path).map_err(|e| at.io(e))? {
            let p = entry.map_err(|e| at.io(e))?.path();
            if p.is_file() {
                files.push(p);
            }
        }
        files
    } else if path.is_file() {
        vec![path.to_path_buf()]
    } else {
        return Err(at.err(Problem::Io(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "no such file or directory",
        ))));
    };

    let single_file = files.len() == 1 && path.is_file();
    let mut typed: Vec<(PathBuf, Format)> = files
        .into_iter()
        .filter_map(|p| {
            let detected = Format::from_path(&p);
            match (format, detected) {
                (Some(f), _) if single_file => Some((p, f)),
                (Some(f), Some(d)) if f == d => Some((p, f)),
                (Some(_), _) => None,
                (None, Some(d)) => Some((p, d)),
                (None, None) => None,
            }
        })
        .collect();
    if typed.is_empty() {
        let what = match format {
            Some(f) => format!("no {f} files here"),
            None if single_file => format!(
                "cannot tell the format from the extension; pass --format (one of: {})",
                Format::ALL.map(|f| f.name()).join(", ")
            ),
            None => "no particle files here (known extensions: .particles, .vtp, .vtu, .vts, .vtk, .csv, .ply, .raw, .npy, .hdf5, .h5)".into(),
        };
        return Err(at.err(Problem::UnknownFormat(what)));
    }
    // A snapshot split over several files is one step, named by its first file.
    let mut parts = stems::multi_file_sets(&mut typed);
    if let Some((chosen, left_out)) = stems::choose_series(&typed) {
        report_left_out(path, &chosen, &left_out);
        typed.retain(|(p, _)| chosen.files.contains(p));
    }
    let first = typed[0].1;
    if let Some((other, _)) = typed.iter().find(|(_, f)| *f != first) {
        return Err(at.err(Problem::UnknownFormat(format!(
            "the series mixes formats ({} and {}, e.g. {}); pass --format to pick one",
            first,
            Format::from_path(other).map(|f| f.name()).unwrap_or("?"),
            other.display()
        ))));
    }
    typed.sort_by(|a, b| natural::compare(&a.0.to_string_lossy(), &b.0.to_string_lossy()));

    if first == Format::Particles {
        if typed.len() > 1 {
            return Err(at.malformed(format!(
                "{} .particles headers found; each is a whole series, name one",
                typed.len()
            )));
        }
        let header = &typed[0].0;
        let names = particles::read_header(header)?;
        return Ok(names
            .into_iter()
            .map(|name| StepRef {
                path: particles::step_path(header, &name),
                format: Format::Particles,
                name,
                read,
                time: None,
            })
            .collect());
    }
    Ok(typed
        .into_iter()
        .map(|(path, format)| StepRef {
            name: parts.remove(&path).unwrap_or_else(|| {
                path.file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_default()
            }),
            path,
            format,
            read,
            time: None,
        })
        .collect())
}

/// The simulation box a step's file states: an HDF5 snapshot's `BoxSize` (in the units the
/// positions are read in) and whether its run is periodic, with what in the file says so.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulationBox {
    /// The box is `[0, size)` on each axis.
    pub size: [f64; 3],
    pub periodic: bool,
    pub because: String,
}

/// The simulation box `step`'s file states, where its format states one (HDF5 snapshots).
pub fn simulation_box(step: &StepRef) -> Result<Option<SimulationBox>, DataError> {
    match step.format {
        Format::Hdf5 => hdf5_gate::simulation_box(&step.path, &step.read),
        _ => Ok(None),
    }
}

/// The time step `step` records, where its format records one: a `.pvd`'s `timestep`, an HDF5
/// snapshot's `/Header` `Time` (read from the file).
pub fn step_time(step: &StepRef) -> Option<f64> {
    step.time.or_else(|| match step.format {
        Format::Hdf5 => hdf5_gate::time(&step.path),
        _ => None,
    })
}

/// Says which files of a folder or glob were not taken as the series, and how to take them.
fn report_left_out(path: &Path, chosen: &stems::StemGroup, left_out: &[stems::StemGroup]) {
    let groups: Vec<String> = left_out
        .iter()
        .map(|g| match g.files.len() {
            1 => format!("'{}'", g.pattern),
            n => format!("'{}' ({n} files)", g.pattern),
        })
        .collect();
    let message = format!(
        "{}: the series is '{}' ({} steps, the most of any name in it); left out: {}. To open \
         another, name it: --data '{}'",
        path.display(),
        chosen.pattern,
        chosen.files.len(),
        groups.join(", "),
        left_out[0].data_argument()
    );
    // A command lists a series more than once (to learn its attributes, then to open it; the
    // viewer on each change of attribute): said once per process.
    static SAID: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
    let mut said = SAID.lock().unwrap_or_else(|e| e.into_inner());
    if !said.contains(&message) {
        tracing::warn!("{message}");
        said.push(message);
    }
}

/// Reads one step, keeping the attributes `selection` names.
pub fn read_step(step: &StepRef, selection: &AttributeSelection) -> Result<Step, DataError> {
    let at = step.at();
    let columns = match step.format {
        Format::Particles => particles::read_step(at, selection)?,
        Format::VtkXml => vtk::read_step(at, false, selection)?,
        Format::Vtk => vtk::read_step(at, true, selection)?,
        Format::Csv => csv::read_step(at, selection)?,
        Format::Ply => ply::read_step(at, selection)?,
        Format::Raw => raw::read_step(at, selection)?,
        Format::Npy => npy::read_step(at, selection)?,
        Format::Hdf5 => hdf5_gate::read_step(at, &step.read, selection)?,
    };
    finish_step(at, &step.name, columns, selection)
}

/// What a reader hands over: positions and named columns, not yet checked.
pub struct Columns {
    pub positions: Vec<DVec3>,
    /// The selected attributes (a reader decodes only what the selection keeps).
    pub attributes: Vec<Attribute>,
    /// The names of the attributes the file holds that were not decoded (for errors that
    /// say what there is to choose from).
    pub skipped: Vec<String>,
    /// The reader found every position and attribute value finite as it decoded them (false:
    /// it did not check, or found one that is not; [`finish_step`] then checks).
    pub finite: bool,
}

/// Checks and cleans a reader's output: equal lengths, the selected attributes present (and
/// only those kept), particles with a non-finite position or selected attribute dropped with a
/// warning that counts them, and no empty step.
pub fn finish_step(
    at: At<'_>,
    name: &str,
    columns: Columns,
    selection: &AttributeSelection,
) -> Result<Step, DataError> {
    let Columns {
        positions,
        mut attributes,
        skipped,
        finite,
    } = columns;
    let n = positions.len();
    for a in &attributes {
        if a.values.len() != n {
            return Err(at.malformed(format!(
                "attribute '{}' has {} values for {} particles",
                a.name,
                a.values.len(),
                n
            )));
        }
    }
    if let AttributeSelection::Only(wanted) = selection {
        for w in wanted {
            if !attributes.iter().any(|a| &a.name == w) {
                return Err(at.err(Problem::MissingAttribute {
                    name: w.clone(),
                    available: available_list(&attributes, &skipped),
                    names: attributes
                        .iter()
                        .map(|a| a.name.clone())
                        .chain(skipped.iter().cloned())
                        .collect(),
                }));
            }
        }
        attributes.retain(|a| wanted.contains(&a.name));
        attributes.sort_by_key(|a| wanted.iter().position(|w| *w == a.name));
    }
    if n == 0 {
        return Err(at.err(Problem::EmptyStep(String::new())));
    }

    // Simulation output is almost always finite: one parallel pass says so (or the reader
    // did, as it decoded), and only data with a non-finite value pays for the per-particle
    // bookkeeping below.
    if finite
        || (all_finite(bytemuck::cast_slice(&positions))
            && attributes.iter().all(|a| all_finite(&a.values)))
    {
        return Ok(Step {
            name: name.to_owned(),
            positions,
            attributes,
        });
    }
    let mut keep = vec![true; n];
    let mut bad_positions = 0usize;
    for (k, p) in keep.iter_mut().zip(&positions) {
        if !p.is_finite() {
            *k = false;
            bad_positions += 1;
        }
    }
    let mut bad_attributes = Vec::new();
    for a in &attributes {
        let mut count = 0usize;
        for (k, v) in keep.iter_mut().zip(&a.values) {
            if !v.is_finite() {
                count += usize::from(*k);
                *k = false;
            }
        }
        if count > 0 {
            bad_attributes.push(format!("{count} with NaN/Inf '{}'", a.name));
        }
    }
    let dropped = n - keep.iter().filter(|k| **k).count();
    let (positions, attributes) = if dropped > 0 {
        let mut why = Vec::new();
        if bad_positions > 0 {
            why.push(format!("{bad_positions} with NaN/Inf positions"));
        }
        why.extend(bad_attributes);
        let why = why.join(", ");
        if dropped == n {
            return Err(at.err(Problem::EmptyStep(format!(
                ": all {n} particles were dropped ({why})"
            ))));
        }
        tracing::warn!(
            "{}: dropped {dropped} of {n} particles ({why})",
            at.location()
        );
        let positions = filter(&positions, &keep);
        let attributes = attributes
            .into_iter()
            .map(|a| Attribute {
                values: filter(&a.values, &keep),
                name: a.name,
            })
            .collect();
        (positions, attributes)
    } else {
        (positions, attributes)
    };
    Ok(Step {
        name: name.to_owned(),
        positions,
        attributes,
    })
}

/// Values per block of a pass that checks finiteness (512 KiB of doubles: a block stays in
/// cache while it is checked).
pub(crate) const FINITE_BLOCK: usize = 1 << 16;

/// Whether every value is finite: in parallel blocks, each checked without branching (so it
/// runs at memory speed, vectorised), the answer only combined between blocks.
pub(crate) fn all_finite(values: &[f64]) -> bool {
    use rayon::prelude::*;
    values.par_chunks(FINITE_BLOCK).all(block_finite)
}

/// Whether every value of a block is finite, in three integer operations a value: a value is
/// not finite when its exponent bits are all ones, and only then does adding one to them carry
/// into the sign bit. (`f64::is_finite` folded with `&` took twice as long in SSE2.)
pub(crate) fn block_finite(values: &[f64]) -> bool {
    const EXPONENT: u64 = 0x7ff0_0000_0000_0000;
    const ONE: u64 = 0x0010_0000_0000_0000;
    values
        .iter()
        .fold(0, |carry, v| carry | ((v.to_bits() & EXPONENT) + ONE))
        >> 63
        == 0
}

fn filter<T: Copy>(values: &[T], keep: &[bool]) -> Vec<T> {
    values
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(v, _)| *v)
        .collect()
}

fn available_list(attributes: &[Attribute], skipped: &[String]) -> String {
    let mut names: Vec<&str> = attributes.iter().map(|a| a.name.as_str()).collect();
    names.extend(skipped.iter().map(String::as_str));
    if names.is_empty() {
        "no attributes".into()
    } else {
        names
            .iter()
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// The size of an open file, for checking counts against it.
pub(crate) fn file_len(at: At<'_>, file: &std::fs::File) -> Result<u64, DataError> {
    Ok(file.metadata().map_err(|e| at.io(e))?.len())
}

/// Names for the components of a multi-component array, as ParaView shows them.
pub(crate) fn component_names(name: &str, components: usize) -> Vec<String> {
    match components {
        1 => vec![name.to_owned()],
        3 => ["x", "y", "z"]
            .iter()
            .map(|c| format!("{name}_{c}"))
            .collect(),
        n => (0..n).map(|i| format!("{name}_{i}")).collect(),
    }
}

/// Every attribute an array of `components` per particle becomes (see [`split_components`]).
pub(crate) fn array_attribute_names(name: &str, components: usize) -> Vec<String> {
    let mut names = component_names(name, components);
    if components == 3 {
        names.push(magnitude_name(name));
    }
    names
}

fn magnitude_name(name: &str) -> String {
    format!("{name}_magnitude")
}

/// Splits an interleaved array of `components` per particle into named attributes; three
/// components also give their magnitude (`<name>_magnitude`), what users colour by most.
pub(crate) fn split_components(name: &str, data: &[f64], components: usize) -> Vec<Attribute> {
    let n = data.len() / components.max(1);
    let mut out: Vec<Attribute> = component_names(name, components)
        .into_iter()
        .enumerate()
        .map(|(c, name)| Attribute {
            name,
            values: (0..n).map(|i| data[i * components + c]).collect(),
        })
        .collect();
    if components == 3 {
        out.push(Attribute {
            name: magnitude_name(name),
            values: (0..n)
                .map(|i| {
                    let v = &data[i * 3..i * 3 + 3];
                    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
                })
                .collect(),
        });
    }
    out
}

/// Files in `dir` that a [`write_series`] of `stem` could overwrite.
pub fn existing_outputs(dir: &Path, stem: &str) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                n.starts_with(&format!("{stem}.particles")) || n.starts_with(&format!("{stem}_"))
            })
        })
        .collect();
    out.sort();
    out
}

/// Writes `steps` into `dir` as `<stem>.particles` (+ step files) or `<stem>_<i>.<ext>`, one
/// file per step, each atomically (overwriting: callers check first, see
/// [`existing_outputs`]). Formats with a single attribute (`.particles`, `.raw`) carry `attribute`.
/// Returns the path to open the series with.
pub fn write_series(
    dir: &Path,
    stem: &str,
    steps: &[Step],
    format: Format,
    attribute: &str,
) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(dir)?;
    if format == Format::Particles {
        let header = dir.join(format!("{stem}.particles"));
        particles::write_series(&header, steps, attribute)?;
        return Ok(header);
    }
    let width = steps.len().saturating_sub(1).to_string().len().max(4);
    let ext = match format {
        Format::VtkXml => "vtp",
        Format::Csv => "csv",
        Format::Ply => "ply",
        Format::Raw => "raw",
        Format::Npy => "npy",
        Format::Vtk | Format::Particles | Format::Hdf5 => {
            return Err(std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                format!(
                    "writing {format} is not supported; use particles, vtk-xml, csv, ply, raw or npy"
                ),
            ));
        }
    };
    for (i, step) in steps.iter().enumerate() {
        let path = dir.join(format!("{stem}_{i:0width$}.{ext}"));
        output::write_atomically(&path, true, |path| match format {
            Format::VtkXml => vtk::write_vtp(path, step),
            Format::Csv => csv::write_step(path, step),
            Format::Ply => ply::write_step(path, step),
            Format::Raw => raw::write_step(path, step, attribute),
            Format::Npy => {
                let cols = 3 + step.attributes.len();
                let mut data = Vec::with_capacity(step.len() * cols);
                for (k, p) in step.positions.iter().enumerate() {
                    data.extend_from_slice(&p.to_array());
                    data.extend(step.attributes.iter().map(|a| a.values[k]));
                }
                npy::write_matrix(path, step.len(), cols, &data)
            }
            Format::Vtk | Format::Particles | Format::Hdf5 => unreachable!("handled above"),
        })
        .map_err(std::io::Error::other)?;
    }
    Ok(if steps.len() == 1 {
        dir.join(format!("{stem}_{:0width$}.{ext}", 0))
    } else {
        dir.join(format!("{stem}_*.{ext}"))
    })
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
    let ext = match format {
        Format::Particles => "particles",
        Format::VtkXml => "vtp",
        Format::Vtk => "vtk",
        Format::Csv => "csv",
        Format::Ply => "ply",
        Format::Raw => "raw",
        Format::Npy => "npy",
        Format::Hdf5 => "hdf5",
    };
    let path = dir.path().join(format!("input.{ext}"));
    let write = |p: &Path, bytes: &[u8]| {
        std::fs::write(p, bytes).map_err(|e| DataError::new(p, None, Problem::Io(e)))
    };
    let step = if format == Format::Particles {
        write(&path, b"0\n")?;
        write(&particles::step_path(&path, "0"), data)?;
        StepRef {
            path: particles::step_path(&path, "0"),
            format,
            name: "0".into(),
            read: ReadOptions::default(),
            time: None,
        }
    } else {
        write(&path, data)?;
        StepRef {
            path: path.clone(),
            format,
            name: "input".into(),
            read: ReadOptions::default(),
            time: None,
        }
    };
    read_step(&step, &AttributeSelection::All)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_finite_is_is_finite_on_every_kind_of_double() {
        let finite = [
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            f64::from_bits(1), // the smallest subnormal
            -f64::from_bits(0x000f_ffff_ffff_ffff),
            f64::MAX,
            f64::MIN,
            1e300,
            -3.5,
        ];
        let not_finite = [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
            f64::from_bits(0x7ff0_0000_0000_0001), // a signalling NaN
            f64::from_bits(0xffff_ffff_ffff_ffff),
        ];
        assert!(block_finite(&finite));
        assert!(block_finite(&[]));
        for bad in not_finite {
            assert!(!bad.is_finite());
            for at in 0..finite.len() {
                let mut values = finite.to_vec();
                values.insert(at, bad);
                assert!(!block_finite(&values), "{bad:?} at {at}");
            }
        }
        let mut long = vec![1.0; 3 * FINITE_BLOCK + 7];
        assert!(all_finite(&long));
        long[2 * FINITE_BLOCK + 3] = f64::NAN;
        assert!(!all_finite(&long));
    }
}
