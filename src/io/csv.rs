//! CSV with a header row: position columns `x, y, z` (or ParaView's `Points:0..2`), every
//! other numeric column an attribute. Lines starting with `#` are comments.

use std::path::Path;

use glam::DVec3;

use super::{At, AttributeSelection, Columns, DataError, Problem};
use crate::values::{Attribute, Step};

const POSITION_NAMES: [[&str; 3]; 2] = [["x", "y", "z"], ["points:0", "points:1", "points:2"]];

/// Reads a CSV step: positions from the `x, y, z` (or `Points:0..2`) columns, the selected other
/// columns as attributes.
pub fn read_step(at: At<'_>, selection: &AttributeSelection) -> Result<Columns, DataError> {
    let mut reader = ::csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(::csv::Trim::All)
        .comment(Some(b'#'))
        .flexible(false)
        .from_path(at.file)
        .map_err(|e| csv_error(at, e))?;
    let headers: Vec<String> = reader
        .headers()
        .map_err(|e| csv_error(at, e))?
        .iter()
        .map(str::to_owned)
        .collect();
    let lower: Vec<String> = headers.iter().map(|h| h.to_ascii_lowercase()).collect();
    let position_columns = POSITION_NAMES
        .iter()
        .find_map(|names| {
            let idx: Option<Vec<usize>> = names
                .iter()
                .map(|n| lower.iter().position(|h| h == n))
                .collect();
            idx
        })
        .ok_or_else(|| {
            at.err(Problem::Dimensionality(format!(
                "the header row needs position columns x, y, z (or Points:0, Points:1, Points:2); it has: {}",
                headers.join(", ")
            )))
        })?;
    // Only the selected columns are parsed (the text of the others is not looked at).
    let (mut attribute_columns, skipped): (Vec<usize>, Vec<usize>) = (0..headers.len())
        .filter(|c| !position_columns.contains(c))
        .partition(|&c| selection.keeps(&headers[c]));

    let mut positions = Vec::new();
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); attribute_columns.len()];
    let mut record = ::csv::StringRecord::new();
    let mut first = true;
    while reader
        .read_record(&mut record)
        .map_err(|e| csv_error(at, e))?
    {
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        if first {
            // Columns that are not numbers in the first row (labels, names) are not attributes.
            let (numeric, text): (Vec<usize>, Vec<usize>) = attribute_columns
                .iter()
                .partition(|&&c| parse(&record[c]).is_some());
            if !text.is_empty() {
                let names: Vec<_> = text.iter().map(|&c| headers[c].as_str()).collect();
                tracing::warn!(
                    "{}: non-numeric columns skipped: {}",
                    at.location(),
                    names.join(", ")
                );
            }
            attribute_columns = numeric;
            values.truncate(attribute_columns.len());
            first = false;
        }
        let field = |c: usize| {
            parse(&record[c]).ok_or_else(|| {
                at.malformed(format!(
                    "line {line}, column '{}': '{}' is not a number",
                    headers[c], &record[c]
                ))
            })
        };
        positions.push(DVec3::new(
            field(position_columns[0])?,
            field(position_columns[1])?,
            field(position_columns[2])?,
        ));
        for (k, &c) in attribute_columns.iter().enumerate() {
            values[k].push(field(c)?);
        }
    }
    let attributes = attribute_columns
        .iter()
        .zip(values)
        .map(|(&c, values)| Attribute {
            name: headers[c].clone(),
            values,
        })
        .collect();
    Ok(Columns {
        positions,
        attributes,
        skipped: skipped.into_iter().map(|c| headers[c].clone()).collect(),
        finite: false,
    })
}

/// A number (parsed to the nearest f64, so 17-digit text keeps every digit), or NaN for an
/// empty field (a missing value, dropped later with a warning).
fn parse(s: &str) -> Option<f64> {
    if s.is_empty() {
        return Some(f64::NAN);
    }
    s.parse::<f64>().ok()
}

fn csv_error(at: At<'_>, e: ::csv::Error) -> DataError {
    let line = e.position().map(|p| format!("line {}: ", p.line()));
    match e.into_kind() {
        ::csv::ErrorKind::Io(e) => at.io(e),
        ::csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => at.malformed(format!(
            "{}a row has {len} fields but the header has {expected_len}",
            line.unwrap_or_default()
        )),
        ::csv::ErrorKind::Utf8 { .. } => {
            at.malformed(format!("{}not UTF-8 text", line.unwrap_or_default()))
        }
        other => at.malformed(format!("{}{other:?}", line.unwrap_or_default())),
    }
}

/// Writes `step` as CSV: a header row `x, y, z` and the attribute names, then one row per particle,
/// each value in the shortest text that reads back as the same f64.
pub fn write_step(path: &Path, step: &Step) -> std::io::Result<()> {
    let mut w = ::csv::Writer::from_path(path)?;
    let mut header = vec!["x".to_owned(), "y".into(), "z".into()];
    header.extend(step.attributes.iter().map(|a| a.name.clone()));
    w.write_record(&header)?;
    // Rust's shortest round-trip formatting: reading the file back gives the same f64s.
    for (i, p) in step.positions.iter().enumerate() {
        let mut row = vec![p.x.to_string(), p.y.to_string(), p.z.to_string()];
        row.extend(step.attributes.iter().map(|a| a.values[i].to_string()));
        w.write_record(&row)?;
    }
    w.flush()
}
