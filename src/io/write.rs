//! Writing a series: one file a step, each written atomically.

use std::path::{Path, PathBuf};

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
    std::fs::create_dir_all(dir)?;
    if format == Format::Particles {
        let header = dir.join(format!("{stem}.particles"));
        particles::write_series(&header, steps, attribute)?;
        return Ok(header);
    }
    let width = steps.len().saturating_sub(1).to_string().len().max(4);
    if matches!(format, Format::Vtk | Format::Hdf5) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            format!(
                "writing {format} is not supported; use particles, vtk-xml, csv, ply, raw or npy"
            ),
        ));
    }
    let ext = format.extension();
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
