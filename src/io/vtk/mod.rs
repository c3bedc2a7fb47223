//! VTK point data through `vtkio`: XML poly data / unstructured / structured grids (`.vtp`,
//! `.vtu`, `.vts`; ascii, base64 binary, appended and compressed) and legacy `.vtk` files.
//! Every point-data array is an attribute; a 3-component array `v` becomes `v_x`, `v_y`, `v_z`
//! and `v_magnitude`.
//!
//! A rank's part is read by rows where the layout allows: appended data by offset
//! ([`appended`]), inline base64 and ascii arrays ([`inline`]: base64 by the groups and zlib
//! blocks that hold the rows; ascii by counting the values before the rows, [`tokens`]) and
//! legacy binary and ascii files ([`legacy`]: every section VTK writes). Compressed arrays are
//! read by their blocks whatever VTK's compressor (zlib, LZ4, LZMA). What remains (legacy files
//! outside the layout VTK writes, such as `bit` arrays or a POINT_DATA or FIELD count other
//! than the points'; XML of base64 holding whitespace, which vtkio refuses, or of a type name
//! these readers do not know) is parsed whole by vtkio and cut, with a warning. A file mixing
//! appended and inline arrays is read by parts ([`inline`] locates both kinds).

use std::path::Path;

use glam::DVec3;
use vtkio::model::{
    Attribute as VtkAttribute, Attributes, ByteOrder, DataArray, DataSet, ElementType, IOBuffer,
    Piece, PieceData, PolyDataPiece, Version, VertexNumbers, Vtk,
};

mod appended;
mod inline;
mod legacy;
mod tokens;

use super::{
    At, AttributeSelection, Columns, DataError, Format, Part, Problem, array_attribute_names,
    split_components,
};
use crate::values::{Attribute, Step};

/// Compression ratios above this are not believed: a header announcing more points than the
/// file could hold even compressed is refused before anything is allocated.
const MAX_COMPRESSION_RATIO: u64 = 1100;

/// Reads a VTK file (`legacy`: a legacy `.vtk` file, else XML `.vtp`, `.vtu` or `.vts`): its points
/// as positions, its point-data arrays as attributes (a 3-component array `v` as `v_x`, `v_y`,
/// `v_z` and `v_magnitude`; only the selected ones decoded).
///
/// Of that, `part`'s records, and how many were decoded: appended data is read by offset, only
/// the part's rows of each array ([`appended`]), and so is a part of inline arrays
/// ([`inline`]) and of a legacy binary or ascii file ([`legacy`]); other files are parsed
/// whole by vtkio and cut (with a warning once that each rank reads the whole step).
pub(super) fn read_step(
    at: At<'_>,
    legacy: bool,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    precheck_counts(at, legacy)?;
    // A part of a file of inline arrays (base64 or ascii) is read by rows; the whole step, by
    // vtkio as before.
    if !legacy
        && !part.is_whole()
        && let Some(read) = inline::read(at, selection, part)?
    {
        return Ok(read);
    }
    // Raw or base64 appended data (VTK's and ParaView's default) is read by offset, only the
    // arrays asked for and the part's rows of them.
    if !legacy && let Some(read) = appended::read(at, selection, part)? {
        return Ok(read);
    }
    // A part of a legacy file (binary or ascii) is read by rows; the whole step, by vtkio as
    // before.
    if legacy
        && !part.is_whole()
        && let Some(read) = legacy::read(at, selection, part)?
    {
        return Ok(read);
    }
    // What is left is parsed whole by vtkio (and a part cut from it).
    let why = if legacy {
        "legacy VTK outside the layout VTK writes (bit arrays, a POINT_DATA or FIELD count \
         other than the points', ...) is parsed whole by vtkio"
    } else {
        "XML of base64 text holding whitespace, or of a type name only vtkio knows, is parsed \
         whole by vtkio"
    };
    let columns = read_whole_file(at, legacy, selection)?;
    let format = if legacy { Format::Vtk } else { Format::VtkXml };
    Ok(super::part::read_whole(format, why, columns, part))
}

/// The whole file parsed by vtkio: every piece's points and the selected point-data arrays.
fn read_whole_file(
    at: At<'_>,
    legacy: bool,
    selection: &AttributeSelection,
) -> Result<Columns, DataError> {
    let pieces = point_pieces(at, parse(at, legacy)?)?;
    let mut positions = Vec::new();
    let mut attributes: Vec<Attribute> = Vec::new();
    let mut skipped: Vec<String> = Vec::new();
    for (index, (points, data)) in pieces.into_iter().enumerate() {
        let coords = points
            .cast_into::<f64>()
            .ok_or_else(|| at.malformed("point coordinates are not numbers"))?;
        if coords.len() % 3 != 0 {
            return Err(at.err(Problem::Dimensionality(format!(
                "{} point coordinates is not a multiple of 3",
                coords.len()
            ))));
        }
        let n = coords.len() / 3;
        let skipped = if index == 0 { Some(&mut skipped) } else { None };
        let piece_attributes = point_attributes(at, data, n, selection, skipped)?;
        append_piece(at, &mut attributes, piece_attributes, index)?;
        positions.extend(coords.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])));
    }
    Ok(Columns {
        positions,
        attributes,
        skipped,
        finite: false,
    })
}

/// The whole file parsed by vtkio (raw appended data re-encoded as base64 first, truncated and
/// over-inflating files refused before it allocates).
fn parse(at: At<'_>, legacy: bool) -> Result<Vtk, DataError> {
    let bytes = std::fs::read(at.file).map_err(|e| at.io(e))?;
    let xml = if legacy {
        None
    } else {
        Some(appended_raw_to_base64(&bytes).map_err(|e| at.malformed(e))?)
    };
    if let Some(text) = &xml {
        let text = text.as_deref().unwrap_or(&bytes);
        if let Some(cut) = where_xml_ends_early(text) {
            return Err(at.malformed(cut));
        }
        check_inflation(text, bytes.len()).map_err(|e| at.malformed(e))?;
    }
    // vtkio is not hardened against every hostile input; a panic inside it becomes an error.
    let parsed = std::panic::catch_unwind(|| match xml {
        None => Vtk::parse_legacy_be(&bytes[..]),
        Some(text) => {
            let text = text.as_deref().unwrap_or(&bytes);
            vtkio::xml::VTKFile::parse(text)
                .map_err(vtkio::Error::from)
                .and_then(|f| Ok(Vtk::try_from(f)?))
        }
    })
    .map_err(|_| {
        at.malformed("cannot parse the VTK file (the parser gave up on malformed content)")
    })?;
    let mut vtk = parsed.map_err(|e| at.malformed(format!("cannot parse the VTK file: {e}")))?;
    vtk.file_path = Some(at.file.to_path_buf());
    Ok(vtk)
}

/// Each piece's points and attributes, loaded; refused for data sets without particle
/// positions.
fn point_pieces(at: At<'_>, vtk: Vtk) -> Result<Vec<(IOBuffer, Attributes)>, DataError> {
    let source = vtk.file_path.as_deref();
    match vtk.data {
        DataSet::PolyData { pieces, .. } => load(at, pieces, source, |d| (d.points, d.data)),
        DataSet::UnstructuredGrid { pieces, .. } => {
            load(at, pieces, source, |d| (d.points, d.data))
        }
        DataSet::StructuredGrid { pieces, .. } => load(at, pieces, source, |d| (d.points, d.data)),
        DataSet::ImageData { .. } | DataSet::RectilinearGrid { .. } | DataSet::Field { .. } => {
            Err(at.err(Problem::Dimensionality(
                "this VTK data set (image, rectilinear grid or field) has no particle positions; \
                 particles come as poly data, unstructured or structured grids"
                    .into(),
            )))
        }
    }
}

/// A piece's point-data arrays of `n` points as attributes, those with no selected attribute
/// not converted (their names go to `skipped`, where given).
fn point_attributes(
    at: At<'_>,
    data: Attributes,
    n: usize,
    selection: &AttributeSelection,
    mut skipped: Option<&mut Vec<String>>,
) -> Result<Vec<Attribute>, DataError> {
    let mut piece_attributes = Vec::new();
    for attribute in data.point {
        let arrays: Vec<(String, u32, IOBuffer)> = match attribute {
            VtkAttribute::DataArray(DataArray { name, elem, data }) => {
                vec![(name, elem.num_comp(), data)]
            }
            VtkAttribute::Field { data_array, .. } => data_array
                .into_iter()
                .map(|a| (a.name, a.elem, a.data))
                .collect(),
        };
        for (name, components, data) in arrays {
            let components = components.max(1) as usize;
            let names = array_attribute_names(&name, components);
            if !names.iter().any(|n| selection.keeps(n)) {
                if let Some(skipped) = skipped.as_deref_mut() {
                    skipped.extend(names);
                }
                continue;
            }
            let values = data
                .cast_into::<f64>()
                .ok_or_else(|| at.malformed(format!("point-data array '{name}' is not numeric")))?;
            if values.len() != n * components {
                return Err(at.malformed(format!(
                    "point-data array '{name}' has {} values for {n} points of {components} components",
                    values.len()
                )));
            }
            piece_attributes.extend(split_components(&name, &values, components));
        }
    }
    Ok(piece_attributes)
}

/// Where `needle` first stands in `hay` at or after `from`.
fn find(hay: &[u8], needle: &[u8], from: usize) -> Option<usize> {
    hay.get(from..)?
        .windows(needle.len())
        .position(|w| w == needle)
        .map(|p| p + from)
}

/// Appends piece `index`'s attributes to the first pieces' (the first piece's become them);
/// every later piece must have each of the first piece's arrays.
pub(super) fn append_piece(
    at: At<'_>,
    attributes: &mut Vec<Attribute>,
    mut piece: Vec<Attribute>,
    index: usize,
) -> Result<(), DataError> {
    if index == 0 {
        *attributes = piece;
        return Ok(());
    }
    for a in attributes {
        let p = piece.iter_mut().find(|p| p.name == a.name).ok_or_else(|| {
            at.malformed(format!(
                "piece {index} lacks the point-data array '{}'",
                a.name
            ))
        })?;
        a.values.append(&mut p.values);
    }
    Ok(())
}

/// The most a compressed VTK array may inflate: zlib (VTK's default) tops out near 1032:1 and
/// LZ4 near 255:1; LZMA on constant data goes further, so this leaves it room.
pub(super) const MAX_INFLATION: usize = 4096;

/// Refuses compressed arrays whose headers declare more uncompressed bytes than the file could
/// inflate to, before vtkio allocates the declared size (a 1 KB file could ask for 4 GB).
/// Reads the first three header integers (blocks, block size, last block size) of every
/// binary or appended DataArray; the data must already be base64 (see
/// [`appended_raw_to_base64`]).
fn check_inflation(text: &[u8], file_len: usize) -> Result<(), String> {
    use base64::Engine;
    let Some(root) = find(text, b"<VTKFile", 0) else {
        return Ok(());
    };
    let root_end = find(text, b">", root).unwrap_or(text.len());
    let root_tag = &text[root..root_end];
    if find(root_tag, b"compressor=\"vtk", 0).is_none() {
        return Ok(());
    }
    let header_bytes = if find(root_tag, b"header_type=\"UInt64\"", 0).is_some() {
        8
    } else {
        4
    };
    let limit = file_len
        .saturating_mul(MAX_INFLATION)
        .saturating_add(1 << 20);
    let appended = find(text, b"<AppendedData", 0)
        .and_then(|t| find(text, b"_", t))
        .map(|u| &text[u + 1..]);
    let mut at = 0;
    while let Some(tag) = find(text, b"<DataArray", at) {
        let tag_end = find(text, b">", tag).unwrap_or(text.len());
        at = tag_end;
        let tag_text = String::from_utf8_lossy(&text[tag..tag_end]);
        let data: &[u8] = if tag_text.contains("format=\"binary\"") {
            &text[(tag_end + 1).min(text.len())..]
        } else if tag_text.contains("format=\"appended\"") {
            let offset = tag_text
                .split("offset=\"")
                .nth(1)
                .and_then(|r| r.split('"').next())
                .and_then(|v| v.trim().parse::<usize>().ok());
            match (appended, offset) {
                (Some(a), Some(o)) if o <= a.len() => &a[o..],
                _ => continue,
            }
        } else {
            continue;
        };
        let chars: Vec<u8> = data
            .iter()
            .copied()
            .filter(|c| !c.is_ascii_whitespace())
            .take(4 * header_bytes)
            .collect();
        let Ok(head) = base64::engine::general_purpose::STANDARD.decode(&chars) else {
            continue; // vtkio reports bad base64 itself
        };
        if head.len() < 3 * header_bytes {
            continue;
        }
        let int = |i: usize| -> u64 {
            let b = &head[i * header_bytes..(i + 1) * header_bytes];
            if header_bytes == 8 {
                u64::from_le_bytes(b.try_into().unwrap_or_default())
            } else {
                u64::from(u32::from_le_bytes(b.try_into().unwrap_or_default()))
            }
        };
        let (blocks, block_size, last) = (int(0), int(1), int(2));
        let declared = block_size
            .checked_mul(blocks.saturating_sub(1))
            .and_then(|v| v.checked_add(last));
        if declared.is_none_or(|d| d > limit as u64) {
            return Err(format!(
                "a compressed DataArray declares {} uncompressed bytes ({blocks} blocks of \
                 {block_size}), more than this {file_len}-byte file can inflate to",
                declared.map_or_else(|| "overflowing".to_owned(), |d| d.to_string())
            ));
        }
    }
    Ok(())
}

/// vtkio reads appended data only base64-encoded, while VTK and ParaView write it raw by
/// default. This re-encodes a file's raw appended block as base64 (each array's header and data
/// as VTK itself would write them) and rewrites the arrays' offsets; `None` when the file has
/// no raw appended data.
fn appended_raw_to_base64(bytes: &[u8]) -> Result<Option<Vec<u8>>, String> {
    use base64::Engine;
    let b64 = |b: &[u8]| base64::engine::general_purpose::STANDARD.encode(b);
    let Some(tag) = find(bytes, b"<AppendedData", 0) else {
        return Ok(None);
    };
    let tag_end = find(bytes, b">", tag).ok_or("unterminated <AppendedData> tag")?;
    let tag_text = String::from_utf8_lossy(&bytes[tag..tag_end]);
    if !tag_text.contains("\"raw\"") {
        return Ok(None);
    }
    let underscore = find(bytes, b"_", tag_end).ok_or("raw appended data lacks its '_' marker")?;
    let raw = &bytes[underscore + 1..];
    let head = std::str::from_utf8(&bytes[..tag])
        .map_err(|_| "the XML before the appended data is not UTF-8")?;
    let header_bytes = if head.contains("header_type=\"UInt64\"") {
        8
    } else {
        4
    };
    let compressed = head.contains("compressor=\"vtk");
    // Every offset and length below comes from the file: all arithmetic on them is checked
    // (a hostile offset near usize::MAX must be "truncated", not an overflow).
    let span = |start: usize, len: usize, what: &str| -> Result<&[u8], String> {
        start
            .checked_add(len)
            .and_then(|end| raw.get(start..end))
            .ok_or_else(|| format!("appended data is truncated ({what} lies past the end)"))
    };
    let int_at = |pos: usize| -> Result<usize, String> {
        let b = span(pos, header_bytes, "an array header")?;
        let v = if header_bytes == 8 {
            u64::from_le_bytes(b.try_into().unwrap())
        } else {
            u64::from(u32::from_le_bytes(b.try_into().unwrap()))
        };
        usize::try_from(v).map_err(|_| "an appended array size overflows".to_owned())
    };

    // Every `offset="N"` before the appended block belongs to an appended DataArray.
    let mut pieces = Vec::new(); // (start, end) of each number in `head`
    let mut search = 0;
    while let Some(i) = head[search..].find("offset=\"") {
        let start = search + i + 8;
        let end = start
            + head[start..]
                .find('"')
                .ok_or("unterminated offset attribute")?;
        pieces.push((start, end));
        search = end;
    }
    let mut offsets: Vec<usize> = pieces
        .iter()
        .map(|&(a, b)| {
            head[a..b]
                .trim()
                .parse::<usize>()
                .map_err(|_| format!("bad offset '{}'", &head[a..b]))
        })
        .collect::<Result<_, _>>()?;
    offsets.sort_unstable();
    offsets.dedup();
    let mut encoded = String::new();
    let mut new_offset = std::collections::HashMap::new();
    for &off in &offsets {
        new_offset.insert(off, encoded.len());
        if compressed {
            let blocks = int_at(off)?;
            let header_len = blocks
                .checked_add(3)
                .and_then(|n| n.checked_mul(header_bytes))
                .ok_or("an appended array header overflows")?;
            // The header (and so the block count) must lie inside the file before its block
            // sizes are read one by one.
            let header = span(off, header_len, "a compressed array header")?;
            let mut data_len = 0usize;
            for b in 0..blocks {
                data_len = data_len
                    .checked_add(int_at(off + (3 + b) * header_bytes)?)
                    .ok_or("appended block sizes overflow")?;
            }
            let data = span(off + header_len, data_len, "compressed blocks")?;
            encoded.push_str(&b64(header));
            encoded.push_str(&b64(data));
        } else {
            let len = int_at(off)?;
            let total = len
                .checked_add(header_bytes)
                .ok_or("an appended array size overflows")?;
            let block = span(off, total, "an array")?;
            encoded.push_str(&b64(block));
        }
    }
    let mut out = String::with_capacity(head.len() + encoded.len() + 64);
    let mut last = 0;
    for &(a, b) in &pieces {
        out.push_str(&head[last..a]);
        let old: usize = head[a..b].trim().parse().unwrap_or(0);
        out.push_str(&new_offset[&old].to_string());
        last = b;
    }
    out.push_str(&head[last..]);
    out.push_str("<AppendedData encoding=\"base64\">\n_");
    out.push_str(&encoded);
    out.push_str("\n</AppendedData>\n</VTKFile>\n");
    Ok(Some(out.into_bytes()))
}

/// If the XML document stops before its elements close (a copy cut short, a file still being
/// written), where: the byte, the line and the element it stops in. `None` for a complete
/// document, and for malformed ones the parser reports itself.
fn where_xml_ends_early(text: &[u8]) -> Option<String> {
    use quick_xml::events::Event;
    // A complete VTK file ends with its root's closing tag; only files without one are walked.
    let tail = &text[text.len().saturating_sub(4096)..];
    if tail.windows(10).any(|w| w == b"</VTKFile>") {
        return None;
    }
    let mut reader = quick_xml::Reader::from_reader(text);
    let mut open: Vec<String> = Vec::new();
    let mut buf = Vec::new();
    loop {
        match reader.read_event_into(&mut buf) {
            Ok(Event::Start(e)) => {
                let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                let label = e
                    .try_get_attribute("Name")
                    .ok()
                    .flatten()
                    .map(|a| String::from_utf8_lossy(&a.value).into_owned());
                open.push(match label {
                    Some(l) => format!("<{name} Name=\"{l}\">"),
                    None => format!("<{name}>"),
                });
            }
            Ok(Event::End(_)) => {
                open.pop();
            }
            Ok(Event::Eof) => break,
            Ok(_) => {}
            // A truncated element (`<DataArr`) or text cut inside a tag: still truncation.
            Err(_) if reader.buffer_position() as usize + 1 >= text.len() => break,
            Err(_) => return None,
        }
        buf.clear();
    }
    let inside = open.last()?;
    let line = 1 + text.iter().filter(|&&c| c == b'\n').count();
    Some(format!(
        "the file ends early, at byte {} (line {line}), inside {inside} ({} elements left \
         open): the copy was cut short or the file is still being written",
        text.len(),
        open.len()
    ))
}

/// Loads every piece (from files beside `source` where they are stored there), each as its
/// points and attributes.
fn load<P: PieceData>(
    at: At<'_>,
    pieces: Vec<Piece<P>>,
    source: Option<&Path>,
    parts: impl Fn(P) -> (IOBuffer, Attributes),
) -> Result<Vec<(IOBuffer, Attributes)>, DataError> {
    pieces
        .into_iter()
        .map(|piece| {
            piece
                .into_loaded_piece_data(source)
                .map(&parts)
                .map_err(|e| at.malformed(format!("cannot load a VTK piece: {e}")))
        })
        .collect()
}

/// Refuses point counts the file cannot hold, before the parser allocates for them.
fn precheck_counts(at: At<'_>, legacy: bool) -> Result<(), DataError> {
    use std::io::Read;
    let mut head = Vec::new();
    let file = std::fs::File::open(at.file).map_err(|e| at.io(e))?;
    let size = super::file_len(at, &file)?;
    file.take(1 << 16)
        .read_to_end(&mut head)
        .map_err(|e| at.io(e))?;
    let head = String::from_utf8_lossy(&head);
    let counts: Vec<u64> = if legacy {
        head.lines()
            .filter_map(|l| {
                let mut w = l.split_whitespace();
                (w.next()? == "POINTS").then(|| w.next()?.parse().ok())?
            })
            .collect()
    } else {
        head.match_indices("NumberOfPoints=\"")
            .filter_map(|(i, m)| {
                let rest = &head[i + m.len()..];
                rest[..rest.find('"')?].parse().ok()
            })
            .collect()
    };
    let compressed = head.contains("compressor=");
    // The fewest bytes a point can take: 3 f32, or in ascii three one-digit numbers.
    let per_point = if legacy && !head.contains("BINARY") {
        6
    } else {
        12
    };
    let budget = if compressed {
        size.saturating_mul(MAX_COMPRESSION_RATIO)
    } else {
        size
    };
    for count in counts {
        at.check_count("VTK point", count, per_point, budget)?;
    }
    Ok(())
}

/// Writes a step as VTK XML poly data (`.vtp`, base64 binary, zlib-compressed) with every
/// attribute as a point-data array and one vertex cell per particle, so ParaView shows points.
/// Points and arrays are Float64: what was read in double precision is written in it.
pub fn write_vtp(path: &Path, step: &Step) -> std::io::Result<()> {
    let n = step.len() as u64;
    let points: Vec<f64> = step.positions.iter().flat_map(|p| p.to_array()).collect();
    let piece = PolyDataPiece {
        points: points.into(),
        verts: Some(VertexNumbers::XML {
            connectivity: (0..n).collect(),
            offsets: (1..=n).collect(),
        }),
        lines: None,
        polys: None,
        strips: None,
        data: Attributes {
            point: step
                .attributes
                .iter()
                .map(|a| {
                    VtkAttribute::DataArray(DataArray {
                        name: a.name.clone(),
                        elem: ElementType::Scalars {
                            num_comp: 1,
                            lookup_table: None,
                        },
                        data: a.values.clone().into(),
                    })
                })
                .collect(),
            cell: Vec::new(),
        },
    };
    let vtk = Vtk {
        version: Version::new_xml(1, 0),
        title: step.name.clone(),
        byte_order: ByteOrder::LittleEndian,
        data: DataSet::inline(piece),
        file_path: None,
    };
    let xml = vtk
        .try_into_xml_format(vtkio::xml::Compressor::ZLib, 5)
        .map_err(std::io::Error::other)?;
    xml.export(path).map_err(std::io::Error::other)
}
