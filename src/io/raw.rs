//! Knoll et al.'s `.raw` particle files: records of four little-endian f32 (x, y, z, w), no
//! header; `w` is the attribute.

use std::path::Path;

use glam::DVec3;

use super::{At, AttributeSelection, Columns, DataError, Part, Problem};
use crate::values::{Attribute, Step};

/// The name the format's fourth value, w, gets as an attribute.
pub const ATTRIBUTE_NAME: &str = "w";

/// Reads a `.raw` file: records of four little-endian f32 (x, y, z, w), w as the attribute
/// [`ATTRIBUTE_NAME`]; a size that is not a multiple of 16 bytes is a truncated file.
///
/// Of that, `part`'s records only (their bytes alone are decoded), and how many.
pub(super) fn read_step(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let bytes = super::mapped::Mapped::open(at)?;
    if bytes.len() % 16 != 0 {
        let n = bytes.len() / 16;
        return Err(at.err(Problem::Truncated {
            what: format!("{} records of 16 bytes (x, y, z, w as f32)", n + 1),
            needed: (n as u64 + 1) * 16,
            available: bytes.len() as u64,
        }));
    }
    let range = part.range(bytes.len() / 16);
    Ok((
        xyzw_columns(
            &bytes[range.start * 16..range.end * 16],
            ATTRIBUTE_NAME,
            selection,
        ),
        range.len(),
    ))
}

/// Columns from little-endian records of four f32 (x, y, z, attribute): the body of both
/// `.raw` files and `.particles` step files.
pub(crate) fn xyzw_columns(
    bytes: &[u8],
    attribute: &str,
    selection: &AttributeSelection,
) -> Columns {
    let f = |record: &[u8], i: usize| {
        f64::from(f32::from_le_bytes(
            record[i * 4..i * 4 + 4].try_into().unwrap(),
        ))
    };
    use rayon::prelude::*;
    let records = bytes.par_chunks_exact(16);
    let positions = records
        .clone()
        .map(|r| DVec3::new(f(r, 0), f(r, 1), f(r, 2)))
        .collect();
    let (attributes, skipped) = if selection.keeps(attribute) {
        let values = records.map(|r| f(r, 3)).collect();
        (
            vec![Attribute {
                name: attribute.into(),
                values,
            }],
            Vec::new(),
        )
    } else {
        (Vec::new(), vec![attribute.to_owned()])
    };
    Columns {
        positions,
        attributes,
        skipped,
        finite: false,
    }
}

/// Records of four little-endian f32 (x, y, z, `attribute`) for a step: the format holds f32,
/// so double-precision values are rounded to it.
pub(crate) fn xyzw_bytes(step: &Step, attribute: &str) -> std::io::Result<Vec<u8>> {
    let values = &step
        .attribute(attribute)
        .ok_or_else(|| {
            std::io::Error::other(format!(
                "step '{}' has no attribute '{attribute}'",
                step.name
            ))
        })?
        .values;
    let mut bytes = Vec::with_capacity(step.len() * 16);
    for (p, v) in step.positions.iter().zip(values) {
        for x in [p.x, p.y, p.z, *v] {
            bytes.extend_from_slice(&(x as f32).to_le_bytes());
        }
    }
    Ok(bytes)
}

/// Writes `step` as `.raw`: each particle's x, y, z and its value of the attribute `attribute`, as
/// f32 (rounded from f64); an error when the step has no such attribute.
pub fn write_step(path: &Path, step: &Step, attribute: &str) -> std::io::Result<()> {
    std::fs::write(path, xyzw_bytes(step, attribute)?)
}
