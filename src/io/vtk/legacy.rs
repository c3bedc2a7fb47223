//! A part of a legacy VTK file (`# vtk DataFile Version x`, `BINARY` or `ASCII`, poly data or an
//! unstructured grid), read by rows. Binary: the ascii lines between the binary blocks are
//! scanned, each block stepped over by its size (computed from its line's counts and type),
//! and only the part's rows of the points and of the selected point-data arrays are decoded
//! (big-endian, as the format stores them); the pages of the file's other rows are never
//! touched. Ascii: a block is its line's count of values, any number a line, so each block is
//! stepped over by counting its values (each must start as a number: a keyword where a value
//! should be is an error naming the block), and a part counts its way to its rows and parses
//! only them ([`super::tokens`]): it scans the whole file, but parses and keeps its rows only.
//!
//! The sections are those vtkio reads: poly data, unstructured and structured grids; POINTS
//! of float or double and the METADATA block VTK 9 writes after them; the cell lists in either
//! layout and CELL_TYPES; POINT_DATA and a CELL_DATA before and after it, holding SCALARS
//! (with their LOOKUP_TABLE line), COLOR_SCALARS (ascii floats, binary unsigned char),
//! VECTORS, NORMALS, TENSORS (9 values a point), TEXTURE_COORDINATES, standalone LOOKUP_TABLEs
//! (4 values a colour, floats or unsigned char) and FIELD arrays, each followed or not by a
//! METADATA block (its lines up to an empty one, stepped over). Every point-data array is an
//! attribute, as in the whole read; a lookup table of another size than the points is refused
//! where selected, in the whole read's words. Cell data is stepped over. A block that runs past
//! the end of the file is an error naming it and where it starts. A file holding anything else
//! (`bit` arrays, a POINT_DATA or FIELD count other than the points', ...) is left to vtkio
//! (`None`), which reads it whole or reports what is wrong. A whole step is always read by
//! vtkio, so a part here is cut from the same records, attribute names and order as
//! [`super::read_whole_file`] gives.

use glam::DVec3;

use super::tokens::{self, Short};
use crate::io::mapped::Mapped;
use crate::io::scalar::Scalar;
use crate::io::{
    At, AttributeSelection, Columns, DataError, Part, array_attribute_names, split_components,
};
use crate::values::Attribute;

/// A binary block's place in the file: its first byte and what it holds.
#[derive(Clone, Debug)]
struct Block {
    name: String,
    scalar: Scalar,
    components: usize,
    offset: usize,
    /// Its tuples: the section's count, but a standalone LOOKUP_TABLE's own size.
    tuples: usize,
}

/// The header lines' findings: the points and the point-data arrays, in file order.
struct Layout {
    points: usize,
    coordinates: Block,
    arrays: Vec<Block>,
}

/// `part`'s records and how many were decoded, or `None` where the file is not legacy VTK of
/// the sections this reader understands (vtkio reads it whole instead). Values of an ascii
/// file that are not numbers, or too few of them, are an error naming the array.
pub(super) fn read(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<Option<(Columns, usize)>, DataError> {
    let bytes = Mapped::open(at)?;
    let (layout, ascii) = match scan(&bytes) {
        Ok(Some(found)) => found,
        Ok(None) => return Ok(None),
        Err(message) => return Err(at.malformed(message)),
    };
    let rows = part.range(layout.points);
    let decode = |block: &Block| -> Result<Vec<f64>, DataError> {
        if ascii {
            return decode_ascii(at, &bytes, block, rows.clone());
        }
        let row = block.components * block.scalar.size();
        let from = block.offset + rows.start * row;
        Ok(bytes[from..from + rows.len() * row]
            .chunks_exact(block.scalar.size())
            .map(|b| block.scalar.value(b, true))
            .collect())
    };
    let coords = decode(&layout.coordinates)?;
    let positions = coords
        .chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    let mut attributes: Vec<Attribute> = Vec::new();
    let mut skipped = Vec::new();
    for array in &layout.arrays {
        let names = array_attribute_names(&array.name, array.components);
        if !names.iter().any(|n| selection.keeps(n)) {
            skipped.extend(names);
            continue;
        }
        if array.tuples != layout.points {
            // A lookup table of another size than the points: refused as the whole read
            // refuses it, in its words.
            return Err(at.malformed(format!(
                "point-data array '{}' has {} values for {} points of {} components",
                array.name,
                array.tuples * array.components,
                layout.points,
                array.components
            )));
        }
        attributes.extend(split_components(
            &array.name,
            &decode(array)?,
            array.components,
        ));
    }
    let columns = Columns {
        positions,
        attributes,
        skipped,
        finite: false,
    };
    Ok(Some((columns, rows.len())))
}

/// What a block holds, for messages.
fn label(block: &Block) -> String {
    if block.name.is_empty() {
        "the POINTS".to_owned()
    } else {
        format!("array '{}'", block.name)
    }
}

/// Rows `rows` of an ascii block: the values before them counted (the scan checked the block
/// holds all its values), only theirs parsed.
fn decode_ascii(
    at: At<'_>,
    bytes: &[u8],
    block: &Block,
    rows: std::ops::Range<usize>,
) -> Result<Vec<f64>, DataError> {
    let text = &bytes[block.offset..];
    let c = block.components;
    let first = tokens::skip(text, rows.start * c, true)
        .map_err(|_| at.malformed(format!("{} ends early", label(block))))?;
    tokens::parse(&text[first..], rows.len() * c, block.scalar, true).map_err(|bad| {
        at.malformed(format!(
            "{}: '{}' at byte {} is not a {:?} value",
            label(block),
            bad.token,
            block.offset + first + bad.at,
            block.scalar
        ))
    })
}

/// A scalar type as vtkio's legacy parser names it (`bit` is packed, not a scalar of bytes).
fn parse_scalar(word: &str) -> Option<Scalar> {
    let is = |name: &str| word.eq_ignore_ascii_case(name);
    Some(if is("int") || is("vtkIdType") {
        Scalar::I32
    } else if is("char") {
        Scalar::I8
    } else if is("long") {
        Scalar::I64
    } else if is("short") {
        Scalar::I16
    } else if is("float") {
        Scalar::F32
    } else if is("double") {
        Scalar::F64
    } else if is("unsigned_int") {
        Scalar::U32
    } else if is("unsigned_char") {
        Scalar::U8
    } else if is("unsigned_long") {
        Scalar::U64
    } else {
        return None;
    })
}

/// Walks the file's lines and blocks.
struct Scanner<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// An ascii file: a block is a number of values, whitespace-separated, counted.
    ascii: bool,
    /// Why an ascii block's values are not all there (the scan stops: an error, not vtkio's).
    error: Option<String>,
}

impl<'a> Scanner<'a> {
    /// A copy of this scanner past the whitespace at its cursor: to look at the next word
    /// without moving (take it by assigning it back).
    fn past_space(&self) -> Scanner<'a> {
        let mut probe = Scanner {
            bytes: self.bytes,
            pos: self.pos,
            ascii: self.ascii,
            error: None,
        };
        probe.skip_space();
        probe
    }

    /// Steps over spaces, tabs and line ends (what vtkio allows between sections).
    fn skip_space(&mut self) {
        while self
            .bytes
            .get(self.pos)
            .is_some_and(u8::is_ascii_whitespace)
        {
            self.pos += 1;
        }
    }

    /// The words of the line at the cursor, which moves to the next line's start; `None` at the
    /// end of the file, or for a line that is not text or does not end.
    fn line(&mut self) -> Option<Vec<&'a str>> {
        let rest = self.bytes.get(self.pos..)?;
        let end = rest.iter().position(|&c| c == b'\n')?;
        self.pos += end + 1;
        let text = std::str::from_utf8(&rest[..end]).ok()?;
        Some(text.split_ascii_whitespace().collect())
    }

    /// Whether the text at the cursor, after spaces and tabs, starts with `word` (any case).
    fn next_is(&self, word: &str) -> bool {
        let rest = &self.bytes[self.pos.min(self.bytes.len())..];
        let start = rest
            .iter()
            .position(|&c| c != b' ' && c != b'\t')
            .unwrap_or(rest.len());
        rest[start..]
            .get(..word.len())
            .is_some_and(|w| w.eq_ignore_ascii_case(word.as_bytes()))
    }

    /// Steps over a block of `count` values of `size` bytes (ascii: `count` values, counted,
    /// not parsed); where it starts. `None` where it does not fit in the file (ascii: where the
    /// file ends, or a word stands, before its last value: an error naming `what`).
    fn block(&mut self, count: usize, size: usize, what: &str) -> Option<usize> {
        let start = self.pos;
        if self.ascii {
            return match tokens::skip(&self.bytes[start..], count, true) {
                Ok(end) => {
                    self.pos = start + end;
                    Some(start)
                }
                Err(short) => {
                    let found = match short {
                        Short::Ends { found } => format!("the file ends after {found}"),
                        Short::Word { at } => {
                            let at = start + at;
                            let word: String = String::from_utf8_lossy(&self.bytes[at..])
                                .split_ascii_whitespace()
                                .next()
                                .unwrap_or_default()
                                .chars()
                                .take(40)
                                .collect();
                            format!("'{word}' at byte {at} is not a number")
                        }
                    };
                    self.error = Some(format!(
                        "{what} should hold {count} values from byte {start}, but {found}"
                    ));
                    None
                }
            };
        }
        let end = count
            .checked_mul(size)
            .and_then(|len| len.checked_add(start))
            .filter(|&end| end <= self.bytes.len());
        let Some(end) = end else {
            self.error = Some(format!(
                "{what} should hold {count} values of {size} bytes from byte {start}, but the \
                 file ends at byte {}",
                self.bytes.len()
            ));
            return None;
        };
        self.pos = end;
        Some(start)
    }

    /// Steps over a METADATA block at the cursor, if one stands there (after whitespace): its
    /// line, then lines up to an empty one or the file's end, as vtkio throws it away. `None`
    /// for a line that does not end.
    fn metadata(&mut self) -> Option<()> {
        let probe = self.past_space();
        if !probe.next_is("METADATA") {
            return Some(());
        }
        self.pos = probe.pos;
        if self.pos + "METADATA".len() == self.bytes.len() {
            self.pos = self.bytes.len();
            return Some(());
        }
        self.line()?;
        loop {
            let rest = &self.bytes[self.pos..];
            if rest.is_empty() {
                return Some(());
            }
            for end in [&b"\n"[..], b"\r\n"] {
                if rest.starts_with(end) {
                    self.pos += end.len();
                    return Some(());
                }
            }
            self.line()?;
        }
    }

    /// A cell list's `n size` counts and its blocks: VTK 5's OFFSETS and CONNECTIVITY of
    /// 64-bit integers, or the older one list of `size` 32-bit integers.
    fn cells(&mut self, words: &[&str]) -> Option<()> {
        let [_, n, size] = words else { return None };
        let (n, size): (usize, usize) = (n.parse().ok()?, size.parse().ok()?);
        let probe = self.past_space();
        if !probe.next_is("OFFSETS") {
            self.block(size, 4, &format!("{}'s cell list", words[0]))?;
            return Some(());
        }
        *self = probe;
        for (tag, count) in [("OFFSETS", n), ("CONNECTIVITY", size)] {
            self.skip_space();
            let line = self.line()?;
            let [word, kind] = line.as_slice() else {
                return None;
            };
            if !word.eq_ignore_ascii_case(tag) || !kind.eq_ignore_ascii_case("vtktypeint64") {
                return None;
            }
            self.block(count, 8, tag)?;
        }
        Some(())
    }

    /// One attribute of `n` elements at the cursor (its keyword's line in `words`), into
    /// `arrays`: SCALARS (with its optional lookup table line), COLOR_SCALARS, VECTORS,
    /// NORMALS, TENSORS, TEXTURE_COORDINATES, a LOOKUP_TABLE or FIELD, each array with the
    /// METADATA block that may follow it.
    fn attribute(&mut self, words: &[&str], n: usize, arrays: &mut Vec<Block>) -> Option<()> {
        let keyword = words.first()?.to_ascii_uppercase();
        // An array of `tuples` tuples, and the METADATA block vtkio allows after it.
        let mut add_of =
            |scanner: &mut Self, name: &str, scalar: Scalar, components: usize, tuples: usize| {
                let what = format!("array '{name}'");
                let offset =
                    scanner.block(tuples.checked_mul(components)?, scalar.size(), &what)?;
                arrays.push(Block {
                    name: name.to_owned(),
                    scalar,
                    components,
                    offset,
                    tuples,
                });
                scanner.metadata()
            };
        // Colours and lookup tables: floats in ascii, bytes in binary.
        let colour = if self.ascii { Scalar::F32 } else { Scalar::U8 };
        let positive = |text: &str| text.parse::<usize>().ok().filter(|&c| c > 0);
        match (keyword.as_str(), &words[1..]) {
            ("SCALARS", [name, kind, rest @ ..]) if rest.len() <= 1 => {
                let components = match rest {
                    [c] => c.parse::<usize>().ok().filter(|&c| c > 0)?,
                    _ => 1,
                };
                if self.next_is("LOOKUP_TABLE") {
                    let table = self.line()?;
                    if table.len() != 2 {
                        return None;
                    }
                }
                add_of(self, name, parse_scalar(kind)?, components, n)
            }
            ("VECTORS" | "NORMALS", [name, kind]) => add_of(self, name, parse_scalar(kind)?, 3, n),
            ("TENSORS", [name, kind]) => add_of(self, name, parse_scalar(kind)?, 9, n),
            ("COLOR_SCALARS", [name, components]) => {
                add_of(self, name, colour, positive(components)?, n)
            }
            ("TEXTURE_COORDINATES", [name, dim, kind]) => {
                add_of(self, name, parse_scalar(kind)?, positive(dim)?, n)
            }
            // A lookup table standing alone: `size` colours of 4 values, whatever the count.
            ("LOOKUP_TABLE", [name, size]) => add_of(self, name, colour, 4, size.parse().ok()?),
            ("FIELD", [_, count]) => {
                for _ in 0..count.parse::<usize>().ok()? {
                    self.skip_space();
                    let line = self.line()?;
                    let [name, components, tuples, kind] = line.as_slice() else {
                        return None;
                    };
                    let components = components.parse::<usize>().ok().filter(|&c| c > 0)?;
                    // vtkio checks an array's tuples against the points, in its words.
                    if tuples.parse::<usize>().ok()? != n || name.eq_ignore_ascii_case("METADATA") {
                        return None;
                    }
                    add_of(self, name, parse_scalar(kind)?, components, n)?;
                }
                Some(())
            }
            _ => None,
        }
    }
}

/// The points and point-data arrays of a legacy file, found by its lines, and whether it is
/// ascii; `None` for anything else, an error where an ascii block's values are not all there.
fn scan(bytes: &[u8]) -> Result<Option<(Layout, bool)>, String> {
    let mut s = Scanner {
        bytes,
        pos: 0,
        ascii: false,
        error: None,
    };
    let layout = scan_lines(&mut s);
    match s.error {
        Some(error) => Err(error),
        None => Ok(layout.map(|l| (l, s.ascii))),
    }
}

/// [`scan`]'s walk.
fn scan_lines(s: &mut Scanner<'_>) -> Option<Layout> {
    let bytes = s.bytes;
    s.skip_space();
    let version = s.line()?;
    let is = |w: &str, word: &str| w.eq_ignore_ascii_case(word);
    let number = |text: &str| text.parse::<u32>().is_ok();
    if !matches!(version.as_slice(), ["#", vtk, datafile, v, x]
        if is(vtk, "vtk") && is(datafile, "DataFile") && is(v, "Version")
            && x.split_once('.').is_some_and(|(a, b)| number(a) && number(b)))
    {
        return None;
    }
    s.line()?.first()?; // the title: not empty
    s.ascii = match s.line()?.as_slice() {
        [kind] if is(kind, "BINARY") => false,
        [kind] if is(kind, "ASCII") => true,
        _ => return None,
    };
    s.skip_space();
    // Poly data, an unstructured grid (`grid`), or a structured grid (`structured`: its
    // DIMENSIONS line, then the points and the data, without cells).
    let (grid, structured) = match s.line()?.as_slice() {
        [dataset, kind] if is(dataset, "DATASET") && is(kind, "POLYDATA") => (false, false),
        [dataset, kind] if is(dataset, "DATASET") && is(kind, "UNSTRUCTURED_GRID") => (true, false),
        [dataset, kind] if is(dataset, "DATASET") && is(kind, "STRUCTURED_GRID") => (false, true),
        _ => return None,
    };
    s.skip_space();
    if structured {
        match s.line()?.as_slice() {
            [word, dims @ ..]
                if is(word, "DIMENSIONS") && dims.len() == 3 && dims.iter().all(|d| number(d)) => {}
            _ => return None,
        }
        s.skip_space();
    }
    let line = s.line()?;
    let [word, count, kind] = line.as_slice() else {
        return None;
    };
    let points: usize = count.parse().ok()?;
    let scalar = parse_scalar(kind).filter(|t| matches!(t, Scalar::F32 | Scalar::F64))?;
    if !is(word, "POINTS") {
        return None;
    }
    let coordinates = Block {
        name: String::new(),
        scalar,
        components: 3,
        offset: s.block(points.checked_mul(3)?, scalar.size(), "the POINTS")?,
        tuples: points,
    };
    // VTK 9 writes a METADATA block after the points (vtkio throws it away).
    s.metadata()?;
    // What vtkio reads after the points: cell lists (an unstructured grid's CELLS, then its
    // CELL_TYPES), then one CELL_DATA and one POINT_DATA in either order.
    let mut arrays = Vec::new();
    let mut cell_arrays = Vec::new();
    // The section the cursor is in: its element count, and whether it is the points'.
    let mut section: Option<(usize, bool)> = None;
    let (mut cells, mut cell_types, mut point_data) = (false, false, false);
    // vtkio reads one CELL_DATA before POINT_DATA and one after (keeping the first's).
    let (mut cell_data_before, mut cell_data_after) = (false, false);
    loop {
        s.skip_space();
        if s.pos == bytes.len() {
            break;
        }
        let line = s.line()?;
        let keyword = line.first()?.to_ascii_uppercase();
        match keyword.as_str() {
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS"
                if !grid && !structured && section.is_none() =>
            {
                s.cells(&line)?
            }
            "CELLS" if grid && !cells => {
                s.cells(&line)?;
                cells = true;
            }
            "CELL_TYPES" if grid && cells && !cell_types => {
                let [_, n] = line.as_slice() else { return None };
                s.block(n.parse().ok()?, 4, "CELL_TYPES")?;
                cell_types = true;
            }
            "POINT_DATA" | "CELL_DATA" => {
                let [_, n] = line.as_slice() else { return None };
                let n: usize = n.parse().ok()?;
                let is_points = keyword == "POINT_DATA";
                let seen = if is_points {
                    &mut point_data
                } else if point_data {
                    &mut cell_data_after
                } else {
                    &mut cell_data_before
                };
                // vtkio checks point data's count against the points, in its words.
                if *seen || (grid && !cell_types) || (is_points && n != points) {
                    return None;
                }
                *seen = true;
                section = Some((n, is_points));
            }
            _ => {
                let (n, is_points) = section?;
                let into = if is_points {
                    &mut arrays
                } else {
                    &mut cell_arrays
                };
                s.attribute(&line, n, into)?;
            }
        }
    }
    if grid && !cell_types {
        return None;
    }
    Some(Layout {
        points,
        coordinates,
        arrays,
    })
}
