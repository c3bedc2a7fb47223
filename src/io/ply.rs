//! Stanford PLY (ascii, binary little- and big-endian): the `vertex` element's `x, y, z` are
//! positions, its other scalar properties attributes. Other elements (faces, ...) and list
//! properties are skipped.
//!
//! One rank's part ([`Part`]) decodes only its own vertex rows ([`read_step`]): binary rows of
//! scalars at their offset; binary rows with lists after stepping over the rows before them
//! (and the elements before the vertex element) by their list counts; ascii rows, one a line,
//! by byte ranges where the vertex element ends the file and has scalars only, else by
//! counting the lines before them. One process reading the whole step reads value by value
//! and checks the rows against the header's count.

use std::io::Write;
use std::path::Path;

use glam::DVec3;

use super::scalar::{InRecord, Scalar, decode_records};
use super::{At, AttributeSelection, Columns, DataError, Part, Problem};
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
    /// A list property (name, count type, item type): stepped over, never an attribute.
    List(String, Scalar, Scalar),
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
            ["property", "list", count_type, item_type, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| bad("property before any element"))?;
                let c = parse_scalar(count_type).ok_or_else(|| bad("unknown type"))?;
                let i = parse_scalar(item_type).ok_or_else(|| bad("unknown type"))?;
                e.properties.push(Property::List((*name).to_owned(), c, i));
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
                Property::List(_, c, i) => {
                    let len = self.next(at, *c, &element.name, row)?;
                    for _ in 0..(len.max(0.0) as u64) {
                        self.next(at, *i, &element.name, row)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Binary: one row of `element` from `pos`, each scalar's bytes handed to `scalar` with its
    /// index among the scalars and its type (to decode or not); a list's count is decoded and
    /// its items stepped over by their size. Nothing is read past the file's end.
    fn binary_row(
        &mut self,
        at: At<'_>,
        element: &Element,
        row: u64,
        mut scalar: impl FnMut(usize, Scalar, &[u8]),
    ) -> Result<(), DataError> {
        let big = self.encoding == Encoding::BigEndian;
        let mut k = 0;
        for p in &element.properties {
            let left = self.bytes.len() - self.pos;
            match p {
                Property::Scalar(name, t) => {
                    if t.size() > left {
                        return Err(self.past_end(at, element, row, name, "its value"));
                    }
                    scalar(k, *t, &self.bytes[self.pos..]);
                    self.pos += t.size();
                    k += 1;
                }
                Property::List(name, c, i) => {
                    if c.size() > left {
                        return Err(self.past_end(at, element, row, name, "its list count"));
                    }
                    let count = c.value(&self.bytes[self.pos..], big).max(0.0) as u64;
                    let items = count
                        .checked_mul(i.size() as u64)
                        .filter(|&b| b <= (left - c.size()) as u64)
                        .ok_or_else(|| {
                            self.past_end(
                                at,
                                element,
                                row,
                                name,
                                &format!("its list of {count} items"),
                            )
                        })?;
                    self.pos += c.size() + items as usize;
                }
            }
        }
        Ok(())
    }

    /// Binary: steps over rows `first..first + rows` of `element` from `pos` without decoding
    /// them: rows of scalars only by their size at once, rows with lists one by one, reading
    /// only the lists' counts.
    fn step_binary_rows(
        &mut self,
        at: At<'_>,
        element: &Element,
        first: u64,
        rows: u64,
    ) -> Result<(), DataError> {
        let mut sizes = Vec::with_capacity(element.properties.len());
        for p in &element.properties {
            match p {
                Property::Scalar(_, t) => sizes.push(t.size()),
                Property::List(..) => {
                    for row in first..first + rows {
                        self.binary_row(at, element, row, |_, _, _| {})?;
                    }
                    return Ok(());
                }
            }
        }
        let stride = sizes.iter().sum::<usize>();
        let left = self.bytes.len() - self.pos;
        match rows.checked_mul(stride as u64) {
            Some(b) if b <= left as u64 => {
                self.pos += b as usize;
                Ok(())
            }
            _ => {
                // The first row that does not fit, and the property that runs past the end.
                let complete = left / stride;
                let mut within = left % stride;
                let k = sizes
                    .iter()
                    .position(|&s| {
                        let past = s > within;
                        within = within.saturating_sub(s);
                        past
                    })
                    .unwrap_or(0);
                self.pos += complete * stride + sizes[..k].iter().sum::<usize>();
                let Property::Scalar(name, _) = &element.properties[k] else {
                    unreachable!("scalars only")
                };
                Err(self.past_end(at, element, first + complete as u64, name, "its value"))
            }
        }
    }

    /// Binary: property `property` of `element`'s row `row`, at `pos`, runs past the end.
    fn past_end(
        &self,
        at: At<'_>,
        element: &Element,
        row: u64,
        property: &str,
        what: &str,
    ) -> DataError {
        at.malformed(format!(
            "file is truncated: PLY element '{}' row {row}, property '{property}': {what} at \
             byte {} runs past the end of the file ({} bytes)",
            element.name,
            self.start + self.pos,
            self.start + self.bytes.len()
        ))
    }
}

/// Reads a PLY file: the `vertex` element's `x, y, z` as positions, its other scalar properties as
/// attributes (the selected ones).
///
/// Of that, `part`'s vertices, and how many vertices were decoded (a part decodes only its
/// own rows; the elements and rows before them are stepped over, never decoded):
/// - binary rows of scalars only are of one size: the part's rows are decoded at their offset;
/// - binary rows with lists: the rows before the part's are stepped over by reading only their
///   list counts (a list's items are stepped over by their size), and so are the rows of the
///   elements before the vertex element;
/// - ascii rows of scalars only, of a vertex element that ends the file (what plyfile, NumPy
///   and MeshLab write for point clouds), one a line, are split by bytes as CSV is
///   ([`decode_ascii_lines`]);
/// - other ascii rows (a vertex element followed by faces or edges, or with lists), one a
///   line: the lines before the part's rows are counted (the elements before the vertex
///   element's rows too), not parsed, and the part parses exactly its rows `part.range(n)`
///   ([`decode_counted_lines`]).
///
/// One process (`part` whole) reads the rows value by value, as it always has.
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
    for (index, element) in header.elements.iter().enumerate() {
        // The smallest a row can be: in binary, its scalars' sizes; in ascii, one character and
        // one separator per value. Checked before allocating anything from the count.
        let min_row = element
            .properties
            .iter()
            .map(|p| match (header.encoding, p) {
                (Encoding::Ascii, _) => 2,
                (_, Property::Scalar(_, t)) => t.size() as u64,
                (_, Property::List(_, c, _)) => c.size() as u64,
            })
            .sum::<u64>();
        let n = at.check_count(
            &format!("PLY element '{}'", element.name),
            element.count,
            min_row,
            body_len,
        )?;
        if element.name == "vertex" {
            if part.is_whole() {
                return read_vertices(at, &mut body, element, n, selection);
            }
            let before = &header.elements[..index];
            let last = index + 1 == header.elements.len();
            let first_line = 1 + bytes[..header.body_start]
                .iter()
                .filter(|&&c| c == b'\n')
                .count() as u64;
            return read_vertex_part(
                at, &mut body, first_line, before, element, n, last, selection, part,
            );
        }
        if part.is_whole() {
            for row in 0..element.count {
                body.row(at, element, row, |_, _| {})?;
            }
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
    /// Empty columns for `rows` rows of each property: room in those kept as attributes (the
    /// stored ones that are not a position), none in the others.
    fn attribute_columns(&self, rows: usize) -> Vec<Vec<f64>> {
        (0..self.scalars.len())
            .map(|k| {
                let kept = self.stored[k] && !self.is_position(k);
                Vec::with_capacity(if kept { rows } else { 0 })
            })
            .collect()
    }

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

/// Reads the whole vertex element: its positions, the selected properties as attributes, the
/// others' names as skipped; and the rows decoded (all of them).
fn read_vertices(
    at: At<'_>,
    body: &mut Body<'_>,
    element: &Element,
    n: usize,
    selection: &AttributeSelection,
) -> Result<(Columns, usize), DataError> {
    let layout = VertexLayout::new(at, element, selection)?;
    let fixed =
        body.encoding != Encoding::Ascii && layout.scalars.len() == element.properties.len();
    let (positions, columns) = if fixed {
        decode_fixed_rows(at, body, &layout, n, 0..n)?
    } else {
        decode_row_by_row(at, body, element, &layout, n)?
    };
    Ok((vertex_columns(&layout, positions, columns), n))
}

/// `part`'s rows of the vertex element (`last`: the file's last element; `before`: the elements
/// the body holds before it, whose rows are stepped over; `first_line`: the body's first line's
/// number in the file), and the rows decoded (the part's own).
#[allow(clippy::too_many_arguments)]
fn read_vertex_part(
    at: At<'_>,
    body: &mut Body<'_>,
    first_line: u64,
    before: &[Element],
    element: &Element,
    n: usize,
    last: bool,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let layout = VertexLayout::new(at, element, selection)?;
    let scalars_only = layout.scalars.len() == element.properties.len();
    let rows = part.range(n);
    let (positions, columns) = if body.encoding == Encoding::Ascii {
        let mut lines = Lines {
            bytes: body.bytes,
            start: body.start,
            pos: 0,
            line: first_line,
        };
        for e in before {
            lines.skip_rows(at, e, 0, e.count)?;
        }
        if scalars_only && last {
            // Its rows end where the file ends, so the bytes split without counting lines.
            body.pos = lines.pos;
            let (positions, columns) = decode_ascii_lines(at, body, &layout, element, part)?;
            let decoded = positions.len();
            return Ok((vertex_columns(&layout, positions, columns), decoded));
        }
        lines.skip_rows(at, element, 0, rows.start as u64)?;
        decode_counted_lines(at, &mut lines, element, &layout, rows.clone())?
    } else {
        for e in before {
            body.step_binary_rows(at, e, 0, e.count)?;
        }
        if scalars_only {
            decode_fixed_rows(at, body, &layout, n, rows.clone())?
        } else {
            body.step_binary_rows(at, element, 0, rows.start as u64)?;
            decode_binary_rows(at, body, element, &layout, rows.clone())?
        }
    };
    Ok((vertex_columns(&layout, positions, columns), rows.len()))
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
/// order). Each row must hold exactly the element's values ([`parse_line`]); blank lines are
/// not rows. Only the share's bytes (of the memory map) are touched. Columns not stored are
/// empty.
fn decode_ascii_lines(
    at: At<'_>,
    body: &Body<'_>,
    layout: &VertexLayout<'_>,
    element: &Element,
    part: Part,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let rows = &body.bytes[body.pos..];
    let share = part.range(rows.len());
    let line_start = |from: usize| -> usize {
        if from == 0 {
            return 0;
        }
        // A line starts after a newline: look from the byte before.
        memchr::memchr(b'\n', &rows[from - 1..]).map_or(rows.len(), |i| from + i)
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
        let mut xyz = [0.0; 3];
        let row = parse_line(line, element, layout, &mut xyz, &mut columns).map_err(|what| {
            at.malformed(format!(
                "PLY element '{}', the row at byte {offset}: {what} (a part reads ascii rows \
                 one a line)",
                element.name
            ))
        })?;
        if row {
            positions.push(DVec3::from_array(xyz));
        }
    }
    Ok((positions, columns))
}

/// Ascii rows, one a line, from `pos` on: lines are found by their line breaks (memchr), not
/// parsed. Blank lines are not rows.
struct Lines<'a> {
    /// The body.
    bytes: &'a [u8],
    /// Where `bytes` start in the file.
    start: usize,
    pos: usize,
    /// The number in the file of the line at `pos` (the first is 1).
    line: u64,
}

impl<'a> Lines<'a> {
    /// The next line that is not blank: its number, its byte offset in the file and its bytes
    /// (its line break included); `None` where the file ends first.
    fn next_row(&mut self) -> Option<(u64, usize, &'a [u8])> {
        while self.pos < self.bytes.len() {
            let rest = &self.bytes[self.pos..];
            let len = memchr::memchr(b'\n', rest).map_or(rest.len(), |i| i + 1);
            let (line, number, offset) = (&rest[..len], self.line, self.start + self.pos);
            self.pos += len;
            self.line += 1;
            let blank = match line.first() {
                Some(c) if !c.is_ascii_whitespace() => false,
                _ => line.iter().all(u8::is_ascii_whitespace),
            };
            if !blank {
                return Some((number, offset, line));
            }
        }
        None
    }

    /// Steps over rows `first..first + rows` of `element`, counting lines.
    fn skip_rows(
        &mut self,
        at: At<'_>,
        element: &Element,
        first: u64,
        rows: u64,
    ) -> Result<(), DataError> {
        for row in first..first + rows {
            if self.next_row().is_none() {
                return Err(self.ended(at, element, row));
            }
        }
        Ok(())
    }

    /// The file ended where `element`'s row `row` should have started.
    fn ended(&self, at: At<'_>, element: &Element, row: u64) -> DataError {
        at.malformed(format!(
            "file is truncated: PLY element '{}' has {} rows in the header, but the file ends \
             after line {} (byte {}) with {row} of them (ascii rows are read one a line)",
            element.name,
            element.count,
            self.line - 1,
            self.start + self.pos
        ))
    }
}

/// One ascii row of `element` on one line (`Ok(false)`: a blank line): its stored scalars
/// parsed, x, y and z into `xyz` and the others onto `columns` (indexed as the layout's
/// scalars); each list's count parsed and its items checked to be numbers. `Err`: what is
/// wrong with the row.
fn parse_line(
    line: &[u8],
    element: &Element,
    layout: &VertexLayout<'_>,
    xyz: &mut [f64; 3],
    columns: &mut [Vec<f64>],
) -> Result<bool, String> {
    let mut words = line
        .split(|c| c.is_ascii_whitespace())
        .filter(|w| !w.is_empty());
    let number = |word: &[u8], name: &str| {
        std::str::from_utf8(word)
            .ok()
            .and_then(|w| w.parse::<f64>().ok())
            .ok_or_else(|| {
                format!(
                    "'{}' (property '{name}') is not a number",
                    String::from_utf8_lossy(word)
                )
            })
    };
    let scalars = layout.scalars.len();
    let lists = scalars != element.properties.len();
    let short = |found: usize, name: &str| {
        if lists {
            format!("{found} values: the row ends before property '{name}'")
        } else {
            format!("{found} values, but the element has {scalars} properties")
        }
    };
    let mut found = 0;
    let mut k = 0;
    for p in &element.properties {
        match p {
            Property::Scalar(name, _) => {
                let Some(word) = words.next() else {
                    return if found == 0 {
                        Ok(false)
                    } else {
                        Err(short(found, name))
                    };
                };
                found += 1;
                if layout.stored[k] {
                    let value = number(word, name)?;
                    match layout.xyz.iter().position(|&p| p == k) {
                        Some(axis) => xyz[axis] = value,
                        None => columns[k].push(value),
                    }
                }
                k += 1;
            }
            Property::List(name, ..) => {
                let Some(word) = words.next() else {
                    return if found == 0 {
                        Ok(false)
                    } else {
                        Err(short(found, name))
                    };
                };
                found += 1;
                let count = number(word, name)?.max(0.0) as u64;
                for item in 0..count {
                    let Some(word) = words.next() else {
                        return Err(format!(
                            "{found} values: the row ends at item {item} of the {count} of list \
                             '{name}'"
                        ));
                    };
                    found += 1;
                    number(word, name)?;
                }
            }
        }
    }
    let extra = words.count();
    if extra > 0 {
        return Err(if lists {
            format!(
                "{} values, but its properties and list counts make {found}",
                found + extra
            )
        } else {
            format!(
                "{} values, but the element has {scalars} properties",
                found + extra
            )
        });
    }
    Ok(true)
}

/// Rows `rows` of the vertex element, one a line from `lines`' position (its row
/// `rows.start`): each parsed ([`parse_line`]). Columns not stored are empty.
fn decode_counted_lines(
    at: At<'_>,
    lines: &mut Lines<'_>,
    element: &Element,
    layout: &VertexLayout<'_>,
    rows: std::ops::Range<usize>,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let mut columns = layout.attribute_columns(rows.len());
    let mut positions = Vec::with_capacity(rows.len());
    for row in rows {
        let Some((line, offset, bytes)) = lines.next_row() else {
            return Err(lines.ended(at, element, row as u64));
        };
        let mut xyz = [0.0; 3];
        parse_line(bytes, element, layout, &mut xyz, &mut columns).map_err(|what| {
            at.malformed(format!(
                "PLY element '{}' row {row}, line {line} (byte {offset}): {what} (a part reads \
                 ascii rows one a line)",
                element.name
            ))
        })?;
        positions.push(DVec3::from_array(xyz));
    }
    Ok((positions, columns))
}

/// Binary rows `rows` with lists, from the body's position (its row `rows.start`): the
/// positions and the stored scalars decoded, lists stepped over. Columns not stored are empty.
fn decode_binary_rows(
    at: At<'_>,
    body: &mut Body<'_>,
    element: &Element,
    layout: &VertexLayout<'_>,
    rows: std::ops::Range<usize>,
) -> Result<(Vec<DVec3>, Vec<Vec<f64>>), DataError> {
    let big = body.encoding == Encoding::BigEndian;
    let mut columns = layout.attribute_columns(rows.len());
    let axis: Vec<Option<usize>> = (0..layout.scalars.len())
        .map(|k| layout.xyz.iter().position(|&p| p == k))
        .collect();
    let mut positions = Vec::with_capacity(rows.len());
    for row in rows {
        let mut xyz = [0.0; 3];
        body.binary_row(at, element, row as u64, |k, t, bytes| {
            if layout.stored[k] {
                let value = t.value(bytes, big);
                match axis[k] {
                    Some(a) => xyz[a] = value,
                    None => columns[k].push(value),
                }
            }
        })?;
        positions.push(DVec3::from_array(xyz));
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
