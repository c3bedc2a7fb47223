//! CSV with a header row: position columns `x, y, z` (or ParaView's `Points:0..2`), every
//! other numeric column an attribute. Lines starting with `#` are comments.

use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;

use glam::DVec3;

use super::{At, AttributeSelection, Columns, DataError, Part, Problem};
use crate::values::{Attribute, Step};

const POSITION_NAMES: [[&str; 3]; 2] = [["x", "y", "z"], ["points:0", "points:1", "points:2"]];

/// The header row's columns, which are positions and which attributes, and where the records
/// start.
struct Layout {
    headers: Vec<String>,
    position_columns: Vec<usize>,
    /// The selected columns that are numbers in the first record.
    attribute_columns: Vec<usize>,
    skipped: Vec<usize>,
    /// The byte offset of the first record (after the header row and any comments).
    body_start: u64,
}

fn reader_builder() -> ::csv::ReaderBuilder {
    let mut builder = ::csv::ReaderBuilder::new();
    builder
        .trim(::csv::Trim::All)
        .comment(Some(b'#'))
        .flexible(false);
    builder
}

impl Layout {
    /// The header row and the first record (whose non-numeric columns are not attributes).
    fn read(at: At<'_>, selection: &AttributeSelection) -> Result<Layout, DataError> {
        let mut reader = reader_builder()
            .has_headers(true)
            .from_path(at.file)
            .map_err(|e| csv_error(at, e))?;
        let headers: Vec<String> = reader
            .headers()
            .map_err(|e| csv_error(at, e))?
            .iter()
            .map(str::to_owned)
            .collect();
        let body_start = reader.position().byte();
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
        let mut record = ::csv::StringRecord::new();
        if reader
            .read_record(&mut record)
            .map_err(|e| csv_error(at, e))?
        {
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
        }
        Ok(Layout {
            headers,
            position_columns,
            attribute_columns,
            skipped,
            body_start,
        })
    }
}

/// Reads a CSV step: positions from the `x, y, z` (or `Points:0..2`) columns, the selected other
/// columns as attributes.
///
/// [`read_step`] of the records whose first byte lies in `part`'s share of the body's bytes
/// (each share's ends moved forward to the start of a line), and how many: only those bytes
/// are read. A record's place in an error is its line for the whole file, its byte offset for
/// a part.
pub(super) fn read_step(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let layout = Layout::read(at, selection)?;
    let mut file = File::open(at.file).map_err(|e| at.io(e))?;
    let len = super::file_len(at, &file)?;
    let body = layout.body_start.min(len)..len;
    let shares = part.range(usize::try_from(body.end - body.start).unwrap_or(usize::MAX));
    let start = line_start(at, &file, &body, body.start + shares.start as u64)?;
    let end = line_start(at, &file, &body, body.start + shares.end as u64)?;
    // The first part reads from the top of the file (so errors name lines), the others from
    // their first record.
    let first = start == body.start;
    let from = if first { 0 } else { start };
    file.seek(SeekFrom::Start(from)).map_err(|e| at.io(e))?;
    let mut reader = reader_builder()
        .has_headers(first)
        .from_reader(BufReader::new(file.take(end - from)));
    let Layout {
        headers,
        position_columns,
        attribute_columns,
        skipped,
        ..
    } = layout;
    let mut positions = Vec::new();
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); attribute_columns.len()];
    let mut record = ::csv::StringRecord::new();
    while reader
        .read_record(&mut record)
        .map_err(|e| csv_error(at, e))?
    {
        if record.len() != headers.len() {
            return Err(at.malformed(format!(
                "{}a row has {} fields but the header has {}",
                place(first, start, record.position()),
                record.len(),
                headers.len()
            )));
        }
        let field = |c: usize| {
            parse(&record[c]).ok_or_else(|| {
                at.malformed(format!(
                    "{}column '{}': '{}' is not a number",
                    place(first, start, record.position()),
                    headers[c],
                    &record[c]
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
    let decoded = positions.len();
    let attributes = attribute_columns
        .iter()
        .zip(values)
        .map(|(&c, values)| Attribute {
            name: headers[c].clone(),
            values,
        })
        .collect();
    let columns = Columns {
        positions,
        attributes,
        skipped: skipped.into_iter().map(|c| headers[c].clone()).collect(),
        finite: false,
    };
    Ok((columns, decoded))
}

/// Where a record is, for an error: its line in the file (read from the top), or its byte
/// offset (a part that starts further on has not read the lines before its own).
fn place(from_top: bool, start: u64, position: Option<&::csv::Position>) -> String {
    match position {
        Some(p) if from_top => format!("line {}, ", p.line()),
        Some(p) => format!("byte {}, ", start + p.byte()),
        None => String::new(),
    }
}

/// The first byte at or after `at_or_after` that starts a line of `body` (its end if none).
fn line_start(
    at: At<'_>,
    file: &File,
    body: &Range<u64>,
    at_or_after: u64,
) -> Result<u64, DataError> {
    if at_or_after <= body.start {
        return Ok(body.start);
    }
    // A line starts after a newline: look from the byte before.
    let mut offset = at_or_after - 1;
    let mut buf = [0u8; 4096];
    while offset < body.end {
        let want = buf.len().min((body.end - offset) as usize);
        let got = read_at(file, &mut buf[..want], offset).map_err(|e| at.io(e))?;
        if got == 0 {
            break;
        }
        if let Some(i) = buf[..got].iter().position(|&b| b == b'\n') {
            return Ok(offset + i as u64 + 1);
        }
        offset += got as u64;
    }
    Ok(body.end)
}

#[cfg(unix)]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
    std::os::unix::fs::FileExt::read_at(file, buf, offset)
}

#[cfg(windows)]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<usize> {
    std::os::windows::fs::FileExt::seek_read(file, buf, offset)
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
