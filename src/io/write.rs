//! Writing a series: one file a step, each written atomically.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use indicatif::ProgressBar;

use super::source::{SeriesSource, write_step_chunks};
use super::{Format, csv, npy, output, particles, ply, raw, vtk};
use crate::values::Step;

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
    write_series_from(dir, stem, steps, format, attribute)
}

/// [`write_series`] from a [`SeriesSource`]: `.particles`, `.raw` and `.npy` (fixed-size
/// records) are written a run of particles at a time, appended to the step's temporary file, so
/// only one run is in memory; the other formats take each step whole. Shows a progress bar over
/// the particles written.
pub fn write_series_from(
    dir: &Path,
    stem: &str,
    source: &(impl SeriesSource + ?Sized),
    format: Format,
    attribute: &str,
) -> std::io::Result<PathBuf> {
    if matches!(format, Format::Vtk | Format::Hdf5) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            format!(
                "writing {format} is not supported; use particles, vtk-xml, csv, ply, raw or npy"
            ),
        ));
    }
    std::fs::create_dir_all(dir)?;
    let steps = source.step_count();
    let total = (0..steps).map(|i| source.step_len(i) as u64).sum();
    let bar = crate::progress::bar(total, "writing");
    if format == Format::Particles {
        let header = dir.join(format!("{stem}.particles"));
        particles::write_series_from(&header, source, attribute, &bar)?;
        bar.finish_and_clear();
        return Ok(header);
    }
    let width = steps.saturating_sub(1).to_string().len().max(4);
    let ext = format.extension();
    for i in 0..steps {
        let path = dir.join(format!("{stem}_{i:0width$}.{ext}"));
        output::write_atomically(&path, true, |path| match format {
            Format::Raw => {
                let mut out = BufWriter::new(File::create(path)?);
                write_step_chunks(source, i, &bar, |chunk| {
                    out.write_all(&raw::xyzw_bytes(chunk, attribute)?)
                })?;
                out.flush()
            }
            Format::Npy => write_npy(path, source, i, &bar),
            Format::VtkXml | Format::Csv | Format::Ply => {
                let step = source.whole_step(i);
                match format {
                    Format::VtkXml => vtk::write_vtp(path, &step)?,
                    Format::Csv => csv::write_step(path, &step)?,
                    _ => ply::write_step(path, &step)?,
                }
                bar.inc(step.len() as u64);
                Ok(())
            }
            Format::Vtk | Format::Particles | Format::Hdf5 => unreachable!("handled above"),
        })
        .map_err(std::io::Error::other)?;
    }
    bar.finish_and_clear();
    Ok(if steps == 1 {
        dir.join(format!("{stem}_{:0width$}.{ext}", 0))
    } else {
        dir.join(format!("{stem}_*.{ext}"))
    })
}

/// Step `step` of `source` as an N x (3 + k) `.npy` array of f64: x, y, z, then every
/// attribute in order (the reader names them `col3`, `col4`, ...), a run of rows at a time.
fn write_npy(
    path: &Path,
    source: &(impl SeriesSource + ?Sized),
    step: usize,
    bar: &ProgressBar,
) -> std::io::Result<()> {
    let mut out: Option<npy::MatrixWriter<f64>> = None;
    let mut rows = Vec::new();
    write_step_chunks(source, step, bar, |chunk| {
        let cols = 3 + chunk.attributes.len();
        let writer = match &mut out {
            Some(writer) => writer,
            // The columns are known from the first run (every run has the same attributes).
            None => out.insert(npy::MatrixWriter::create(
                path,
                source.step_len(step),
                cols,
            )?),
        };
        rows.clear();
        rows.reserve(chunk.len() * cols);
        for (k, p) in chunk.positions.iter().enumerate() {
            rows.extend_from_slice(&p.to_array());
            rows.extend(chunk.attributes.iter().map(|a| a.values[k]));
        }
        writer.append(&rows)
    })?;
    match out {
        Some(writer) => writer.finish(),
        // No runs: an empty step (its columns unknown, x, y, z only).
        None => npy::MatrixWriter::<f64>::create(path, 0, 3)?.finish(),
    }
}
