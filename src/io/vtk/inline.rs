//! A part of a VTK XML file whose arrays are inline in the XML: meshio's writer, VTK's
//! `SetDataModeToBinary` or `SetDataModeToAscii`, our own [`super::write_vtp`]; and of a file
//! mixing inline point arrays with appended ones (`format="appended"`, read by offset from the
//! `<AppendedData>` that ends the XML, raw or base64, as [`super::appended`] reads them).
//!
//! The file is mapped and its XML walked for the pieces and their arrays; an array's values
//! are then read as a part needs them:
//! - `format="binary"` (base64 of VTK's runs: an uncompressed array's size and data together;
//!   a zlib-compressed array's header, then its blocks, each run encoded on its own): the same
//!   runs as base64 appended data, read by [`super::appended`]'s reader: a part decodes only
//!   the base64 groups, or inflates only the zlib blocks, that hold its rows. The walk steps
//!   over an array by the length its header gives, without reading its text. An array whose
//!   text does not end there because whitespace stands inside its base64 (a writer that
//!   wraps lines) is left to vtkio, whole (vtkio 0.7.0-rc2 refuses such base64: the whole
//!   step and every part give its error).
//! - `format="ascii"`: values separated by any whitespace, any number a line. The walk finds
//!   the array's end tag (a scan for `<`); every value of the array is counted (not parsed)
//!   to check their number, as a whole read does; the values before the part's rows are
//!   skipped by counting, and only the part's own values are parsed. So a part scans the
//!   bytes of every ascii array, but parses and keeps only its rows.
//!
//! Memory is the part's rows (and the blocks that hold them), not the file's.

use std::fs::File;

use quick_xml::events::Event;
use quick_xml::name::QName;

use super::appended::{self, ArrayReader, Header, In, Stored};
use crate::io::mapped::Mapped;
use crate::io::{At, AttributeSelection, Columns, DataError, Part};

/// `part`'s records and how many were decoded, or `None` where the file is not XML of inline
/// arrays this reader handles (appended data alone, base64 holding whitespace, malformed XML:
/// the appended reader or vtkio read it).
pub(super) fn read(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<Option<(Columns, usize)>, DataError> {
    let map = Mapped::open(at)?;
    let file = File::open(at.file).map_err(|e| at.io(e))?;
    let Some(header) = walk(at, &map, &file)? else {
        return Ok(None);
    };
    appended::read_arrays(at, file, &header, Some(&map), selection, part).map(Some)
}

/// Where whitespace after `from` ends.
fn after_space(bytes: &[u8], from: usize) -> usize {
    bytes[from.min(bytes.len())..]
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .map_or(bytes.len(), |p| from + p)
}

/// The message for a file that ends before its XML closes.
fn ends_early(bytes: &[u8]) -> String {
    super::where_xml_ends_early(bytes).unwrap_or_else(|| {
        format!(
            "the file ends early, at byte {}, before </VTKFile>: the copy was cut short or the \
             file is still being written",
            bytes.len()
        )
    })
}

/// The file's settings and pieces, each array's values located; `None` where the file is for
/// another reader.
fn walk(at: At<'_>, bytes: &[u8], file: &File) -> Result<Option<Header>, DataError> {
    let mut header = Header {
        big_endian: false,
        int_bytes: 4,
        compressor: None,
        pieces: Vec::new(),
        data_start: 0,
        base64: true,
    };
    // The <VTKFile> tag first: its settings size the inline arrays' runs.
    let mut xml = quick_xml::Reader::from_reader(bytes);
    let mut base = loop {
        match xml.read_event() {
            Ok(Event::Start(e)) if e.name().as_ref() == b"VTKFile" => {
                if appended::read_file_settings(&e, &mut header).is_none() {
                    return Ok(None);
                }
                break xml.buffer_position() as usize;
            }
            Ok(Event::Eof) | Err(_) => return Ok(None),
            Ok(_) => {}
        }
    };
    let settings = Header {
        pieces: Vec::new(),
        ..header
    };
    let file = file.try_clone().map_err(|e| at.io(e))?;
    let mut extents = ArrayReader::new(at, file, &settings, None)?;
    let mut inside = In::Other;
    let mut closed = false;
    // Arrays of the appended data seen (a file mixing them with inline arrays), and inline ones.
    let mut inline_arrays = false;
    // The XML is read from `base`; after a base64 array the walk starts again at its end tag.
    'walk: loop {
        let mut xml = quick_xml::Reader::from_reader(&bytes[base..]);
        let config = xml.config_mut();
        config.check_end_names = false;
        // A restart begins at the end tag of the array stepped over.
        config.allow_unmatched_ends = true;
        loop {
            let event = match xml.read_event() {
                Ok(e) => e,
                // Malformed XML is vtkio's to report, in its words.
                Err(_) => return Ok(None),
            };
            let here = base + xml.buffer_position() as usize;
            match event {
                Event::Eof => break 'walk,
                Event::Start(ref e) | Event::Empty(ref e) => match e.name().as_ref() {
                    b"AppendedData" => {
                        // Only appended arrays: the appended reader's. Mixed with inline ones:
                        // the appended arrays are read from the data after its '_'.
                        if !inline_arrays {
                            return Ok(None);
                        }
                        header.base64 = match appended::attribute(e, b"encoding").as_deref() {
                            Some("raw") => false,
                            Some("base64") => true,
                            _ => return Ok(None),
                        };
                        let Some(underscore) = super::find(bytes, b"_", here) else {
                            return Ok(None);
                        };
                        header.data_start = underscore as u64 + 1;
                        // The raw data that follows is no XML: what the header sizes is
                        // checked to lie in the file as each array is read.
                        closed = true;
                        break 'walk;
                    }
                    b"Piece" => header.pieces.push(appended::piece(at, e)?),
                    b"Points" => inside = In::Points,
                    b"PointData" => inside = In::PointData,
                    b"CellData" | b"FieldData" | b"Verts" | b"Lines" | b"Strips" | b"Polys"
                    | b"Cells" => inside = In::Other,
                    b"DataArray" => {
                        let name = appended::attribute(e, b"Name").unwrap_or_default();
                        let what = format!("array '{name}'");
                        let format = appended::attribute(e, b"format");
                        let mut resume = None;
                        let empty = matches!(event, Event::Empty(_))
                            || bytes.get(after_space(bytes, here)) == Some(&b'<');
                        let appended = format.as_deref() == Some("appended");
                        inline_arrays |= inside != In::Other && !appended;
                        let (offset, stored) = if appended {
                            let offset = appended::attribute(e, b"offset")
                                .and_then(|v| v.trim().parse::<usize>().ok())
                                .ok_or_else(|| at.malformed(format!("{what}: bad offset")))?;
                            (offset, Stored::Appended)
                        } else if empty {
                            // No values at all: an array of none.
                            (here, Stored::Ascii { end: here as u64 })
                        } else {
                            match format.as_deref() {
                                Some("binary") => {
                                    let start = after_space(bytes, here);
                                    let len = extents.inline_extent(start as u64, &what)?;
                                    let close = after_space(bytes, start + len as usize);
                                    if !bytes[close..].starts_with(b"</DataArray") {
                                        let stop =
                                            super::find(bytes, b"<", start).unwrap_or(bytes.len());
                                        let text = bytes[start..stop].trim_ascii_end();
                                        if text.iter().any(u8::is_ascii_whitespace) {
                                            return Ok(None);
                                        }
                                        return Err(at.malformed(format!(
                                            "{what}: its base64 text is {} characters (from \
                                             byte {start}), its header sizes it {len}",
                                            text.len()
                                        )));
                                    }
                                    resume = Some(close);
                                    (start, Stored::Inline)
                                }
                                Some("ascii") => {
                                    let span =
                                        xml.read_to_end(QName(b"DataArray")).map_err(|_| {
                                            at.malformed(format!(
                                                "{what}: no </DataArray> closes it: {}",
                                                ends_early(bytes)
                                            ))
                                        })?;
                                    let end = base as u64 + span.end;
                                    (base + span.start as usize, Stored::Ascii { end })
                                }
                                _ => return Ok(None),
                            }
                        };
                        if inside != In::Other {
                            let Some(desc) = appended::array_desc(at, e, offset as u64, stored)?
                            else {
                                return Ok(None);
                            };
                            header.add_array(at, inside == In::Points, desc)?;
                        }
                        if let Some(close) = resume {
                            base = close;
                            continue 'walk;
                        }
                    }
                    _ => {}
                },
                Event::End(e) => match e.name().as_ref() {
                    b"Points" | b"PointData" => inside = In::Other,
                    b"VTKFile" => closed = true,
                    _ => {}
                },
                _ => {}
            }
        }
    }
    if !closed {
        return Err(at.malformed(ends_early(bytes)));
    }
    if header.pieces.is_empty() {
        return Ok(None);
    }
    Ok(Some(header))
}
