//! A series on disk as its steps: the files a path, directory or glob names, of one format and
//! one name pattern, in natural order; and what each step's file says of its box and time.

use std::path::{Path, PathBuf};

use super::{
    At, DataError, Format, Problem, ReadOptions, hdf5_gate, natural, particles, pvd, stems,
};

/// One step of a series on disk: the file it lives in, and its name.
#[derive(Clone, Debug, PartialEq)]
pub struct StepRef {
    /// The step's file (of a snapshot split over several files, the first).
    pub path: PathBuf,
    /// The step's file format.
    pub format: Format,
    /// The step's name for messages: a `.particles` header's step name, a split snapshot's name,
    /// else the file name without its extension.
    pub name: String,
    /// What to read from files that hold a choice (HDF5 snapshots' particle types).
    pub read: ReadOptions,
    /// The step's time where the listing gives it (a `.pvd`'s `timestep`); see [`step_time`].
    pub time: Option<f64>,
}

impl StepRef {
    pub(super) fn at(&self) -> At<'_> {
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
    let files = candidate_files(at, path)?;
    let mut typed = with_formats(at, path, files, format)?;
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

/// The files `path` names: the glob's matches, the directory's files, or the file itself.
fn candidate_files(at: At<'_>, path: &Path) -> Result<Vec<PathBuf>, DataError> {
    let text = path.to_string_lossy();
    if text.contains(['*', '?', '[']) && !path.exists() {
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
        Ok(files)
    } else if path.is_dir() {
        let mut files = Vec::new();
        for entry in std::fs::read_dir(path).map_err(|e| at.io(e))? {
            let p = entry.map_err(|e| at.io(e))?.path();
            if p.is_file() {
                files.push(p);
            }
        }
        Ok(files)
    } else if path.is_file() {
        Ok(vec![path.to_path_buf()])
    } else {
        Err(at.err(Problem::Io(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "no such file or directory",
        ))))
    }
}

/// The particle files among `files`, each with its format: `format` where given (a single
/// file is taken as it whatever its extension), else the one its extension names.
fn with_formats(
    at: At<'_>,
    path: &Path,
    files: Vec<PathBuf>,
    format: Option<Format>,
) -> Result<Vec<(PathBuf, Format)>, DataError> {
    let single_file = files.len() == 1 && path.is_file();
    let typed: Vec<(PathBuf, Format)> = files
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
    Ok(typed)
}

/// The simulation box a step's file states: an HDF5 snapshot's `BoxSize` (in the units the
/// positions are read in) and whether its run is periodic, with what in the file says so.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulationBox {
    /// The box is `[0, size)` on each axis.
    pub size: [f64; 3],
    /// Whether the run's box is periodic (opposite faces are one).
    pub periodic: bool,
    /// What in the file says so (as "/Config PERIODIC"), for messages.
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
