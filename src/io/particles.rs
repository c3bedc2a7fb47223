//! The AA-RBF sample code's `.particles` format.
//!
//! A text header lists step names, one per line. Step `name` lives in the file
//! `<header path>_<name>`: a little-endian u64 particle count, then count records of four
//! little-endian f32 (x, y, z, attribute).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use indicatif::ProgressBar;

use super::mapped::Mapped;
use super::source::{SeriesSource, write_step_chunks};
use super::{At, AttributeSelection, Columns, DataError, Part, Problem};
use crate::values::Step;

/// The name the format's single unnamed attribute gets.
pub const ATTRIBUTE_NAME: &str = "attribute";
const RECORD_BYTES: u64 = 16;

/// The step names a header lists (blank lines skipped).
pub fn read_header(header: &Path) -> Result<Vec<String>, DataError> {
    let at = At::new(header, None);
    let bytes = std::fs::read(header).map_err(|e| at.io(e))?;
    let text = String::from_utf8(bytes).map_err(|_| {
        at.malformed(
            "the header is not UTF-8 text (a .particles header lists step names, one per line)",
        )
    })?;
    let names: Vec<String> = text
        .lines()
        .map(|l| l.trim())
        .filter(|l| !l.is_empty())
        .map(str::to_owned)
        .collect();
    if names.is_empty() {
        return Err(at.malformed("the header lists no steps"));
    }
    Ok(names)
}

/// The file holding step `name` of the series whose header is `header`.
pub fn step_path(header: &Path, name: &str) -> PathBuf {
    let mut s = header.as_os_str().to_owned();
    s.push("_");
    s.push(name);
    PathBuf::from(s)
}

/// Reads one `.particles` step file: a little-endian u64 count, then count records of four f32 (x,
/// y, z, [`ATTRIBUTE_NAME`]).
///
/// Of that, `part`'s records only (their bytes alone are decoded), and how many.
pub(super) fn read_step(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let bytes = Mapped::open(at)?;
    let size = bytes.len() as u64;
    if size < 8 {
        return Err(at.err(Problem::Truncated {
            what: "the u64 particle count".into(),
            needed: 8,
            available: size,
        }));
    }
    let count = u64::from_le_bytes(bytes[..8].try_into().unwrap());
    let n = at.check_count("particle", count, RECORD_BYTES, size - 8)?;
    let expected = 8 + n as u64 * RECORD_BYTES;
    if size > expected {
        tracing::warn!(
            "{}: {} bytes after the {n} particles are ignored",
            at.location(),
            size - expected
        );
    }
    let range = part.range(n);
    let bytes =
        &bytes[8 + range.start * RECORD_BYTES as usize..8 + range.end * RECORD_BYTES as usize];
    Ok((
        super::raw::xyzw_columns(bytes, ATTRIBUTE_NAME, selection),
        range.len(),
    ))
}

/// Writes a series as a `.particles` header and one file per step, carrying `attribute`.
/// Step names are the zero-padded step indices.
pub fn write_series(header: &Path, steps: &[Step], attribute: &str) -> std::io::Result<()> {
    write_series_from(header, steps, attribute, &ProgressBar::hidden())
}

/// [`write_series`] from a [`SeriesSource`]: each step file is written a run of particles at a
/// time (the count first, then the run's records appended), atomically, advancing `bar`.
pub(super) fn write_series_from(
    header: &Path,
    source: &(impl SeriesSource + ?Sized),
    attribute: &str,
    bar: &ProgressBar,
) -> std::io::Result<()> {
    let steps = source.step_count();
    let width = steps.saturating_sub(1).to_string().len().max(4);
    let mut names = String::new();
    for i in 0..steps {
        let name = format!("{i:0width$}");
        super::output::write_atomically(&step_path(header, &name), true, |tmp| {
            let mut out = BufWriter::new(File::create(tmp)?);
            out.write_all(&(source.step_len(i) as u64).to_le_bytes())?;
            write_step_chunks(source, i, bar, |chunk| {
                out.write_all(&super::raw::xyzw_bytes(chunk, attribute)?)
            })?;
            out.flush()
        })
        .map_err(std::io::Error::other)?;
        names.push_str(&name);
        names.push('\n');
    }
    // The header last: a series is complete once its header exists.
    super::output::write_atomically(header, true, |tmp| std::fs::write(tmp, &names))
        .map_err(std::io::Error::other)
}
