//! Stanford PLY (ascii, binary little- and big-endian): the `vertex` element's `x, y, z` are
//! positions, its other scalar properties attributes. Other elements (faces, ...) are skipped.

use std::io::Write;
use std::path::Path;

use glam::DVec3;

use super::scalar::{InRecord, Scalar, decode_records};
use super::{At, AttributeSelection, Columns, DataError, Format, Part, Problem};
use crate::values::{Attribute, Step};

/// Largest header we accept: real headers are a few hundred bytes.
const MAX_HEADER_BYTES: usize = 1 << 20;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Encoding {
    Ascii,
    LittleEndian,
    BigEndian,
}

/// A PLY type name as a scalar.
fn parse_scalar(s: &str) -> Option<Scalar> {
    Some(match s {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

#[derive(Debug)]
enum Property {
    Scalar(String, Scalar),
    /// A list property (count type, item type): skipped.
    List(Scalar, Scalar),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: u64,
    properties: Vec<Property>,
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    body_start: usize,
}

fn parse_header(at: At<'_>, bytes: &[u8]) -> Result<Header, DataError> {
    if !bytes.starts_with(b"ply") {
        return Err(at.malformed("not a PLY file (it does not start with 'ply')"));
    }
    let search = &bytes[..bytes.len().min(MAX_HEADER_BYTES)];
    let end = search
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or_else(|| at.malformed("the PLY header has no 'end_header' line"))?;
    let mut body_start = end + 10;
    // The header ends with "end_header" and one line break (\n or \r\n).
    if bytes.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if bytes.get(body_start) == Some(&b'\n') {
        body_start += 1;
    }
    let text = std::str::from_utf8(&bytes[..end])
        .map_err(|_| at.malformed("the PLY header is not text"))?;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    for (number, line) in text.lines().enumerate().skip(1) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let bad =
            |what: &str| at.malformed(format!("PLY header line {}: {what}: '{line}'", number + 1));
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", f, _version] => {
                encoding = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::LittleEndian,
                    "binary_big_endian" => Encoding::BigEndian,
                    _ => return Err(bad("unknown format")),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: (*name).to_owned(),
                count: count.parse().map_err(|_| bad("bad element count"))?,
                properties: Vec::new(),
            }),
            ["property", "list", count_type, item_type, _name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element"))?;
                let c = parse_scalar(count_type).ok_or_else(|| bad("unknown type"))?;
                let i = parse_scalar(item_type).ok_or_else(|| bad("unknown type"))?;
                e.properties.push(Property::List(c, i));
            }
            ["property", ty, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element"))?;
                let t = parse_scalar(ty).ok_or_else(|| bad("unknown type"))?;
                e.properties.push(Property::Scalar((*name).to_owned(), t));
            }
            _ => return Err(bad("not understood")),
        }
    }
    let encoding = encoding.ok_or_else(|| at.malformed("the PLY header has no 'format' line"))?;
    Ok(Header {
        encoding,
        elements,
        body_start,
    })
}

/// Reads values one at a time from the body, ascii or binary.
struct Body<'a> {
    bytes: &'a [u8],
    /// Where `bytes` start in the file.
    start: usize,
    pos: usize,
    encoding: Encoding,
}

impl Body<'_> {
    fn next(&mut self, at: At<'_>, t: Scalar, element: &str, row: u64) -> Result<f64, DataError> {
        if self.encoding == Encoding::Ascii {
            let rest = &self.bytes[self.pos..];
            let start = rest
                .iter()
                .position(|c| !c.is_ascii_whitespace())
                .ok_or_else(|| self.truncated(at, element, row))?;
            let len = rest[start..]
                .iter()
                .position(|c| c.is_ascii_whitespace())
                .unwrap_or(rest.len() - start);
            let word = &rest[start..start + len];
            self.pos += start + len;
            std::str::from_utf8(word)
                .ok()
                .and_then(|w| w.parse::<f64>().ok())
                .ok_or_else(|| {
                    at.malformed(format!(
                        "PLY element '{element}' row {row}: '{}' is not a number",
                        String::from_utf8_lossy(word)
                    ))
                })
        } else {
            let n = t.size();
            if self.pos + n > self.bytes.len() {
                return Err(self.truncated(at, element, row));
            }
            let v = t.value(
                &self.bytes[self.pos..],
                self.encoding == Encoding::BigEndian,
            );
            self.pos += n;
            Ok(v)
        }
    }

    fn truncated(&self, at: At<'_>, element: &str, row: u64) -> DataError {
        at.malformed(format!(
            "file is truncated: PLY element '{element}' ends at row {row}"
        ))
    }

    /// Reads one row of `element`: each scalar is handed to `scalar` with its index among the
    /// scalars; list properties are stepped over.
    fn row(
        &mut self,
        at: At<'_>,
        element: &Element,
        row: u64,
        mut scalar: impl FnMut(usize, f64),
    ) -> Result<(), DataError> {
        let mut k = 0;
        for p in &element.properties {
            match p {
                Property::Scalar(_, t) => {
                    scalar(k, self.next(at, *t, &element.name, row)?);
                    k += 1;
                }
                Property::List(c, i) => {
                    let len = self.next(at, *c, &element.name, row)?;
                    for _ in 0..(len.max(0.0) as u64) {
                        self.next(at, *i, &element.name, row)?;
                    }
                }
            }
        }
        Ok(())
    }
}

/// Reads a PLY file: the `vertex` element's `x, y, z` as positions, its other scalar properties as
/// attributes (the selected ones).
///
/// Of that, `part`'s vertices, and how many vertices were decoded: binary rows of
/// scalars only are of one size, so only the part's rows are decoded; ascii rows of scalars
/// only, of a vertex element that ends the file (what plyfile, NumPy and MeshLab write for
/// point clouds), one a line, are split by bytes as CSV is ([`decode_ascii_lines`]); other
/// ascii rows, and rows with lists, are read whole (each row must be parsed to find the next)
/// and sliced.
pub(super) fn read_step(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let bytes = super::mapped::Mapped::open(at)?;
    let header = parse_header(at, &bytes)?;
    let body_len = (bytes.len() - header.body_start) as u64;
    let mut body = Body {
        bytes: &bytes[header.body_start..],
        start: header.body_start,
        pos: 0,
        encoding: header.encoding,
    };
    for element in &header.elements {
        // The smallest a row can be: in binary, its scalars' sizes; in ascii, one character and
        // one separator per value. Checked before allocating anything from the count.
        let min_row = element
            .properties
            .iter()
            .map(|p| match (header.encoding, p) {
                (Encoding::Ascii, _) => 2,
                (_, Property::Scalar(_, t)) => t.size() as u64,
                (_, Property::List(c, _)) => c.size() as u64,
            })
            .sum::<u64>();
        let n = at.check_count(
            &format!("PLY element '{}'", element.name),
            element.count,
            min_row,
            body_len,
        )?;
        if element.name == "vertex" {
            let last = header
                .elements
                .last()
                .is_some_and(|e| std::ptr::eq(e, element));
            return read_vertices(at, &mut body, element, n, last, selection, part);
        }
        for row in 0..element.count {
            body.row(at, element, row, |_, _| {})?;
        }
    }
    Err(at.err(Problem::Dimensionality(
        "the PLY file has no 'vertex' element".into(),
    )))
}

/// The vertex element's scalar properties, where x, y and z stand among them, and which of
/// them are stored (positions and the selected attributes; the others are stepped over).
struct VertexLayout<'a> {
    scalars: Vec<(&'a str, Scalar)>,
    xyz: [usize; 3],
    stored: Vec<bool>,
}

impl<'a> VertexLayout<'a> {
    fn new(
        at: At<'_>,
        element: &'a Element,
        selection: &AttributeSelection,
    ) -> Result<Self, DataError> {
        let scalars: Vec<(&str, Scalar)> = element
            .properties
            .iter()
            .filter_map(|p| match p {
                Property::Scalar(name, t) => Some((name.as_str(), *t)),
                Property::List(..) => None,
            })
            .collect();
        let find = |name: &str| scalars.iter().position(|(n, _)| *n == name);
        let (Some(ix), Some(iy), Some(iz)) = (find("x"), find("y"), find("z")) else {
            return Err(at.err(Problem::Dimensionality(
                "the PLY vertex element needs properties x, y and z".into(),
            )));
        };
        let stored = scalars
            .iter()
            .enumerate()
            .map(|(k, (name, _))| [ix, iy, iz].contains(&k) || selection.keeps(name))
            .collect();
        Ok(VertexLayout {
            scalars,
            xyz: [ix, iy, iz],
            stored,
        })
    }

    fn is_position(&self, k: usize) -> bool {
        self.xyz.contains(&k)
    }
}

/// Reads the vertex element (`last`: the file's last element): its positions, the selected
/// properties as attributes, the others' names as skipped.
fn read_vertices(
    at: At<'_>,
    body: &mut Body<'_>,
    element: &Element,
    n: usize,
    last: bool,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let layout = VertexLayout::new(at, element, selection)?;
    let scalars_only = layout.scalars.len() == element.properties.len();
    let fixed = body.encoding != Encoding::Ascii && scalars_only;
    // A part of ascii lines: its rows end where the file ends, so the bytes split without
    // parsing what comes before. One process reads the whole step value by value, which checks
    // the rows against the header's count (a part cannot: it does not know how many rows
    // precede it).
    let lines = body.encoding == Encoding::Ascii && scalars_only && last && !part.is_whole();
    if lines {
        let (positions, columns) = decode_ascii_lines(at, body, &layout, part)?;
        let decoded = positions.len();
        return Ok((vertex_columns(&layout, positions, columns), decoded));
    }
    let rows = if fixed { part.range(n) } else { 0..n };
    let (positions, columns) = if fixed {
        decode_fixed_rows(at, body, &layout, n, rows.clone())?
    } else {
        decode_row_by_row(at, body, element, &layout, n)?
    };
    let columns = vertex_columns(&layout, positions, columns);
    if fixed {
        Ok((columns, rows.len()))
    } else {
        let why = if body.encoding == Encoding::Ascii && scalars_only {
            "ascii rows followed by another element: where they end is found by parsing them"
        } else if body.encoding == Encoding::Ascii {
            "ascii rows with list properties"
        } else {
            "rows with list properties"
        };
        Ok(super::part::read_whole(Format::Ply, why, columns, part))
    }
}

/// The vertex element's positions and decoded columns as a reader's columns: the stored
/// properties as attributes, the others' names as skipped.
fn vertex_columns(
    layout: &VertexLayout<'_>,
    positions: Vec<DVec3>,
    columns: Vec<Vec<f64>>,
) -> Columns {
    let mut attributes = Vec::new();
    let mut skipped = Vec::new();
    for (k, ((name, _), values)) in layout.scalars.iter().zip(columns).enumerate() {
        if layout.is_position(k) {
            continue;
        }
        if layout.stored[k] {
            attributes.push(Attribute {
                name: (*name).to_owned(),
                values,
            });
        } else {
            skipped.push((*name).to_owned());
        }
    }
    Columns {
        positions,
        attributes,
        skipped,
        finite: false,
    }
}

/// `part`'s ascii vertex rows, one a line, to the end of the file: the rows' bytes split
/// evenly and each share's ends moved forward to the start of a line, as CSV's are (a row
/// belongs to the part whose share holds its first byte; the parts together are every row, in
/// order). Each row must hold exactly the element's values; blank lines are not rows. Only the
/// share's bytes (of the memory map) are touched. Columns not stored are empty.
fn decode_ascii_lines(
    at: At<'_>,
    body: &Body<'_>,
    layout: &VertexLayout<'_>,
    part: Part,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let rows = &body.bytes[body.pos..];
    let share = part.range(rows.len());
    let line_start = |from: usize| -> usize {
        if from == 0 {
            return 0;
        }
        // A line starts after a newline: look from the byte before.
        rows[from - 1..]
            .iter()
            .position(|&c| c == b'\n')
            .map_or(rows.len(), |i| from + i)
    };
    let (start, end) = (line_start(share.start), line_start(share.end));
    // Byte offsets in the file, for errors: a part does not know its rows' numbers.
    let file_offset = body.start + body.pos;
    let mut columns: Vec<Vec<f64>> = vec![Vec::new(); layout.scalars.len()];
    let mut positions = Vec::new();
    let mut line_at = start;
    for line in rows[start..end].split_inclusive(|&c| c == b'\n') {
        let offset = file_offset + line_at;
        line_at += line.len();
        let mut words = line
            .split(|c| c.is_ascii_whitespace())
            .filter(|w| !w.is_empty());
        let mut values = [0.0; 3];
        let mut count = 0;
        for (k, word) in words.by_ref().take(layout.scalars.len()).enumerate() {
            count += 1;
            if !layout.stored[k] {
                continue;
            }
            let value = std::str::from_utf8(word)
                .ok()
                .and_then(|w| w.parse::<f64>().ok())
                .ok_or_else(|| {
                    at.malformed(format!(
                        "PLY element 'vertex', the row at byte {offset}: '{}' (property '{}') is \
                         not a number",
                        String::from_utf8_lossy(word),
                        layout.scalars[k].0
                    ))
                })?;
            match layout.xyz.iter().position(|&p| p == k) {
                Some(axis) => values[axis] = value,
                None => columns[k].push(value),
            }
        }
        if count == 0 {
            continue;
        }
        let extra = words.count();
        if count != layout.scalars.len() || extra > 0 {
            return Err(at.malformed(format!(
                "PLY element 'vertex', the row at byte {offset}: {} values, but the element has \
                 {} properties (a part reads ascii rows one a line)",
                count + extra,
                layout.scalars.len()
            )));
        }
        positions.push(DVec3::from_array(values));
    }
    Ok((positions, columns))
}

/// Rows of scalars only have a fixed size: the positions and the stored properties are decoded
/// by their offsets in one parallel pass; the others are never decoded. Columns not decoded
/// are empty.
fn decode_fixed_rows(
    at: At<'_>,
    body: &Body<'_>,
    layout: &VertexLayout<'_>,
    n: usize,
    rows: std::ops::Range<usize>,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let mut offsets = Vec::with_capacity(layout.scalars.len());
    let mut stride = 0;
    for (_, t) in &layout.scalars {
        offsets.push(InRecord {
            offset: stride,
            scalar: *t,
        });
        stride += t.size();
    }
    let rest = &body.bytes[body.pos..];
    if n * stride > rest.len() {
        let complete = (rest.len() / stride) as u64;
        return Err(body.truncated(at, "vertex", complete));
    }
    let decoded: Vec<usize> = (0..layout.scalars.len())
        .filter(|k| layout.stored[*k] && !layout.is_position(*k))
        .collect();
    let wanted: Vec<InRecord> = decoded.iter().map(|&k| offsets[k]).collect();
    let (positions, values) = decode_records(
        &rest[rows.start * stride..],
        rows.len(),
        stride,
        body.encoding == Encoding::BigEndian,
        layout.xyz.map(|k| offsets[k]),
        &wanted,
    );
    let mut columns = vec![Vec::new(); layout.scalars.len()];
    for (k, v) in decoded.into_iter().zip(values) {
        columns[k] = v;
    }
    Ok((positions, columns))
}

/// Ascii rows, or rows with lists: value by value. Columns not stored are empty.
fn decode_row_by_row(
    at: At<'_>,
    body: &mut Body<'_>,
    element: &Element,
    layout: &VertexLayout<'_>,
    n: usize,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let mut columns: Vec<Vec<f64>> = layout
        .stored
        .iter()
        .map(|&s| Vec::with_capacity(if s { n } else { 0 }))
        .collect();
    for row in 0..element.count {
        body.row(at, element, row, |k, v| {
            if layout.stored[k] {
                columns[k].push(v);
            }
        })?;
    }
    let [ix, iy, iz] = layout.xyz;
    let positions = (0..n)
        .map(|i| DVec3::new(columns[ix][i], columns[iy][i], columns[iz][i]))
        .collect();
    Ok((positions, columns))
}

/// Writes a step as binary little-endian PLY with double properties (the precision a step
/// holds).
pub fn write_step(path: &Path, step: &Step) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(out, "ply\nformat binary_little_endian 1.0")?;
    writeln!(out, "element vertex {}", step.len())?;
    writeln!(
        out,
        "property double x\nproperty double y\nproperty double z"
    )?;
    for a in &step.attributes {
        writeln!(out, "property double {}", a.name)?;
    }
    writeln!(out, "end_header")?;
    for (i, p) in step.positions.iter().enumerate() {
        for v in [p.x, p.y, p.z] {
            out.write_all(&v.to_le_bytes())?;
        }
        for a in &step.attributes {
            out.write_all(&a.values[i].to_le_bytes())?;
        }
    }
    out.flush()
}
