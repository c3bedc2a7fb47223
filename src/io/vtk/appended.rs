//! VTK XML files whose arrays are appended data — what VTK and ParaView write by default, raw or
//! base64-encoded — read by offset: the XML before `<AppendedData>` is parsed for each array's
//! type, components and offset, and only the point coordinates and the selected point-data
//! arrays are read from the file (decoded, and decompressed: zlib, VTK's default, LZ4 or LZMA);
//! every other array is never read or decoded. A rank's part reads less still: only its rows
//! of each piece, and of each array the bytes that hold them (raw), the base64 groups that
//! hold them, or the compressed blocks that overlap them (one [`Codec`] a file). The same reader reads a part of inline
//! arrays ([`super::inline`] finds them: base64 arrays are the same runs as base64 appended
//! data; ascii ones are counted and parsed by [`super::tokens`]). A compressor VTK does not
//! write goes to vtkio ([`super`]), which refuses it, and a whole step of inline arrays is
//! vtkio's. (vtkio 0.7.0-rc2
//! panics on the base64 appended data VTK 9.7's writer makes of a million particles:
//! `benches/peers/vtk_read.py`.)

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;

use glam::DVec3;
use quick_xml::events::{BytesStart, Event};

use super::find;
use crate::io::scalar::Scalar;
use crate::io::{
    At, AttributeSelection, Columns, DataError, Part, array_attribute_names, split_components,
};

/// The most bytes of XML read while looking for `<AppendedData ... _` (a header describes
/// arrays; 64 MiB of it would be thousands of pieces).
const MAX_HEADER: usize = 64 << 20;

/// An array as the header describes it.
#[derive(Clone, Debug)]
pub(super) struct ArrayDesc {
    pub(super) name: String,
    pub(super) scalar: Scalar,
    pub(super) components: usize,
    /// Where its bytes are: see [`Stored`].
    pub(super) offset: u64,
    pub(super) stored: Stored,
}

/// How an array's values are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Stored {
    /// In the appended data, `offset` from its start (raw or base64 as the file says).
    Appended,
    /// Inline base64 (`format="binary"`): the same runs as base64 appended data (an
    /// uncompressed array's size and data; a compressed array's header, then its blocks),
    /// starting at byte `offset` of the file.
    Inline,
    /// Inline ascii: whitespace-separated values in the file's bytes `offset..end`.
    Ascii { end: u64 },
}

/// A VTK type name (the XML's and the legacy spellings) as a scalar.
pub(super) fn parse_scalar(text: &str) -> Option<Scalar> {
    Some(match text {
        "Int8" | "Char" => Scalar::I8,
        "UInt8" | "UnsignedChar" => Scalar::U8,
        "Int16" | "Short" => Scalar::I16,
        "UInt16" | "UnsignedShort" => Scalar::U16,
        "Int32" | "Int" => Scalar::I32,
        "UInt32" | "UnsignedInt" => Scalar::U32,
        "Int64" | "Long" | "LongLong" => Scalar::I64,
        "UInt64" | "UnsignedLong" | "UnsignedLongLong" => Scalar::U64,
        "Float32" | "Float" => Scalar::F32,
        "Float64" | "Double" => Scalar::F64,
        _ => return None,
    })
}

/// One piece: its point count, coordinates and point-data arrays.
#[derive(Default, Debug)]
pub(super) struct PieceDesc {
    pub(super) points: u64,
    pub(super) coordinates: Option<ArrayDesc>,
    pub(super) arrays: Vec<ArrayDesc>,
}

/// A VTK compressor: each array is the same header (block count, block size, last block's
/// size, each block's compressed size) and blocks that decompress one by one, each as the
/// codec's own format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Codec {
    /// `vtkZLibDataCompressor`: each block a zlib stream (VTK's default).
    ZLib,
    /// `vtkLZ4DataCompressor`: each block LZ4's raw block format (`LZ4_compress_default`, no
    /// frame).
    Lz4,
    /// `vtkLZMADataCompressor`: each block an .xz stream (`lzma_easy_buffer_encode`).
    Lzma,
}

impl Codec {
    /// The codec a `compressor` attribute names; `None` for one VTK does not write.
    pub(super) fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "vtkZLibDataCompressor" => Codec::ZLib,
            "vtkLZ4DataCompressor" => Codec::Lz4,
            "vtkLZMADataCompressor" => Codec::Lzma,
            _ => return None,
        })
    }

    /// Its name in messages.
    fn name(self) -> &'static str {
        match self {
            Codec::ZLib => "zlib",
            Codec::Lz4 => "LZ4",
            Codec::Lzma => "LZMA",
        }
    }

    /// What it does to a block, in messages (zlib's word is "inflate").
    fn verb(self) -> &'static str {
        match self {
            Codec::ZLib => "inflate",
            Codec::Lz4 | Codec::Lzma => "decompress",
        }
    }

    /// Decompresses one block, `packed`, into `target`, which it must fill exactly.
    fn unpack(self, packed: &[u8], target: &mut [u8]) -> Result<(), String> {
        match self {
            Codec::ZLib => flate2::read::ZlibDecoder::new(packed)
                .read_exact(target)
                .map_err(|e| e.to_string()),
            Codec::Lz4 => match lz4_flex::block::decompress_into(packed, target) {
                Ok(n) if n == target.len() => Ok(()),
                Ok(n) => Err(format!("it holds {n} bytes")),
                Err(e) => Err(e.to_string()),
            },
            Codec::Lzma => xz2::read::XzDecoder::new(packed)
                .read_exact(target)
                .map_err(|e| e.to_string()),
        }
    }
}

/// What the header says about the whole file.
pub(super) struct Header {
    pub(super) big_endian: bool,
    /// Bytes of each size integer in an array's header (UInt32 or UInt64).
    pub(super) int_bytes: usize,
    /// The compressor of every array's blocks (`compressor="vtk...DataCompressor"`), if any.
    pub(super) compressor: Option<Codec>,
    pub(super) pieces: Vec<PieceDesc>,
    /// Where the appended data starts (just after the `_`; 0 where there is none).
    pub(super) data_start: u64,
    /// The appended data is base64 text (VTK's writer's default where `EncodeAppendedData`
    /// is on): offsets count characters, and each run of bytes VTK wrote is encoded on its
    /// own (an uncompressed array's size and data together; a compressed array's header,
    /// then all its blocks).
    pub(super) base64: bool,
}

impl Header {
    /// Adds `desc` to the last piece: its points' coordinates where `points`, else a point-data
    /// array.
    pub(super) fn add_array(
        &mut self,
        at: At<'_>,
        points: bool,
        desc: ArrayDesc,
    ) -> Result<(), DataError> {
        let Some(piece) = self.pieces.last_mut() else {
            return Err(at.malformed("a DataArray lies outside any <Piece>"));
        };
        if points {
            piece.coordinates = Some(desc);
        } else {
            piece.arrays.push(desc);
        }
        Ok(())
    }
}

/// Reads `part`'s records of the step by offset, and how many were decoded, or `None` where
/// the file is not appended data this reader handles (vtkio reads it instead). The step's
/// records are its pieces' points in order (pieces without points skipped): each piece gives
/// the rows of it that lie in the part, and only those rows of each array are read, decoded
/// and inflated. Every piece's arrays are checked against the first's from the header alone,
/// so each part has the same attributes in the same order as the whole step.
pub(super) fn read(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<Option<(Columns, usize)>, DataError> {
    let mut file = File::open(at.file).map_err(|e| at.io(e))?;
    let Some(header) = read_header(at, &mut file)? else {
        return Ok(None);
    };
    read_arrays(at, file, &header, None, selection, part).map(Some)
}

/// Reads `part`'s records of the step the header describes, and how many were decoded:
/// appended and inline base64 arrays from `file`, inline ascii ones from `text` (the file's
/// bytes, mapped). The step's records are its pieces' points in order (pieces without points
/// skipped): each piece gives the rows of it that lie in the part, and only those rows of
/// each array are read, decoded and inflated (ascii: parsed; the values before them are
/// counted). Every piece's arrays are checked against the first's from the header alone, so
/// each part has the same attributes in the same order as the whole step.
pub(super) fn read_arrays(
    at: At<'_>,
    file: File,
    header: &Header,
    text: Option<&[u8]>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let mut reader = ArrayReader::new(at, file, header, text)?;
    let mut positions = Vec::new();
    let mut attributes: Vec<crate::values::Attribute> = Vec::new();
    let mut skipped = Vec::new();
    // A piece without points (VTK writes them for idle MPI ranks) adds nothing.
    let pieces: Vec<&PieceDesc> = header.pieces.iter().filter(|p| p.points > 0).collect();
    let mut counts = Vec::with_capacity(pieces.len());
    for piece in &pieces {
        counts.push(
            usize::try_from(piece.points)
                .map_err(|_| at.malformed("a piece's NumberOfPoints overflows"))?,
        );
    }
    let records = counts
        .iter()
        .try_fold(0usize, |t, &n| t.checked_add(n))
        .ok_or_else(|| at.malformed("the pieces' NumberOfPoints overflow"))?;
    let wanted = part.range(records);
    let mut first_record = 0;
    for (index, (piece, &n)) in pieces.iter().zip(&counts).enumerate() {
        // This piece's rows that lie in the part (empty where it lies outside).
        let rows = wanted.start.clamp(first_record, first_record + n) - first_record
            ..wanted.end.clamp(first_record, first_record + n) - first_record;
        first_record += n;
        let Some(coordinates) = &piece.coordinates else {
            return Err(at.malformed(format!("piece {index} has no <Points> array")));
        };
        if coordinates.components != 3 {
            return Err(at.malformed(format!(
                "piece {index}'s points have {} components, not 3",
                coordinates.components
            )));
        }
        let coords = reader.values(coordinates, n, rows.clone())?;
        let mut piece_attributes = Vec::new();
        for array in &piece.arrays {
            let names = array_attribute_names(&array.name, array.components);
            if !names.iter().any(|name| selection.keeps(name)) {
                if index == 0 {
                    skipped.extend(names);
                }
                continue;
            }
            let values = reader.values(array, n, rows.clone())?;
            piece_attributes.extend(split_components(&array.name, &values, array.components));
        }
        super::append_piece(at, &mut attributes, piece_attributes, index)?;
        positions.extend(coords.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])));
    }
    let columns = Columns {
        positions,
        attributes,
        skipped,
        finite: false,
    };
    Ok((columns, wanted.len()))
}

/// The XML before the raw appended data, parsed; `None` when the file has no raw appended
/// data, or an array or encoding this reader leaves to vtkio.
fn read_header(at: At<'_>, file: &mut File) -> Result<Option<Header>, DataError> {
    let Some((head, tag, underscore)) = read_to_appended_data(at, file)? else {
        return Ok(None);
    };
    let tag_end = find(&head, b">", tag).unwrap_or(underscore);
    let tag_text = String::from_utf8_lossy(&head[tag..tag_end]);
    let base64 = if tag_text.contains("\"raw\"") {
        false
    } else if tag_text.contains("\"base64\"") {
        true
    } else {
        return Ok(None);
    };
    let mut header = Header {
        big_endian: false,
        int_bytes: 4,
        compressor: None,
        pieces: Vec::new(),
        data_start: underscore as u64 + 1,
        base64,
    };
    if read_pieces(at, &head[..tag], &mut header)?.is_none() || header.pieces.is_empty() {
        return Ok(None);
    }
    Ok(Some(header))
}

/// The file's bytes up to the '_' that starts the raw data, with where the `<AppendedData`
/// tag and that '_' stand in them; `None` where none is found in the first [`MAX_HEADER`]
/// bytes.
fn read_to_appended_data(
    at: At<'_>,
    file: &mut File,
) -> Result<Option<(Vec<u8>, usize, usize)>, DataError> {
    let mut head = Vec::new();
    let mut chunk = vec![0u8; 1 << 16];
    let mut tag = None;
    loop {
        let got = file.read(&mut chunk).map_err(|e| at.io(e))?;
        // A tag may straddle two reads: look again from a little before the new bytes.
        let from = head.len().saturating_sub(16);
        head.extend_from_slice(&chunk[..got]);
        if tag.is_none() {
            tag = find(&head, b"<AppendedData", from);
        }
        if let Some(t) = tag
            && let Some(end) = find(&head, b">", t)
            && let Some(u) = find(&head, b"_", end)
        {
            return Ok(Some((head, t, u)));
        }
        if got == 0 || head.len() > MAX_HEADER {
            return Ok(None);
        }
    }
}

/// The value of an XML element's attribute `key`.
pub(super) fn attribute(e: &BytesStart<'_>, key: &[u8]) -> Option<String> {
    e.attributes()
        .flatten()
        .find(|a| a.key.as_ref() == key)
        .and_then(|a| a.unescape_value().ok().map(|v| v.into_owned()))
}

/// Where an XML reader stands in a piece: its points, its point data, or elsewhere (cells'
/// and field arrays, which are not the particles' and are skipped).
#[derive(PartialEq)]
pub(super) enum In {
    Other,
    Points,
    PointData,
}

/// A `<Piece>` of `NumberOfPoints` points, its arrays to come.
pub(super) fn piece(at: At<'_>, e: &BytesStart<'_>) -> Result<PieceDesc, DataError> {
    let points = attribute(e, b"NumberOfPoints")
        .and_then(|v| v.trim().parse::<u64>().ok())
        .ok_or_else(|| at.malformed("a <Piece> lacks a valid NumberOfPoints"))?;
    Ok(PieceDesc {
        points,
        ..PieceDesc::default()
    })
}

/// Parses the XML before `<AppendedData>` into `header`'s file settings and pieces; `None`
/// where it holds what this reader leaves to vtkio.
fn read_pieces(at: At<'_>, xml: &[u8], header: &mut Header) -> Result<Option<()>, DataError> {
    let mut xml = quick_xml::Reader::from_reader(xml);
    xml.config_mut().check_end_names = false;
    // Where we are: in <Points> or <PointData> of the current piece (other arrays, such as
    // cells', are not particles' and are skipped).
    let mut inside = In::Other;
    let mut buffer = Vec::new();
    loop {
        let event = match xml.read_event_into(&mut buffer) {
            Ok(e) => e,
            // Malformed XML is vtkio's to report, in its words.
            Err(_) => return Ok(None),
        };
        match event {
            Event::Eof => break,
            Event::Start(e) | Event::Empty(e) => match e.name().as_ref() {
                b"VTKFile" => {
                    let Some(()) = read_file_settings(&e, header) else {
                        return Ok(None);
                    };
                }
                b"Piece" => header.pieces.push(piece(at, &e)?),
                b"Points" => inside = In::Points,
                b"PointData" => inside = In::PointData,
                b"CellData" | b"FieldData" | b"Verts" | b"Lines" | b"Strips" | b"Polys"
                | b"Cells" => inside = In::Other,
                b"DataArray" if inside != In::Other => {
                    let Some(desc) = read_array(at, &e)? else {
                        return Ok(None);
                    };
                    header.add_array(at, inside == In::Points, desc)?;
                }
                _ => {}
            },
            Event::End(e) => {
                if matches!(e.name().as_ref(), b"Points" | b"PointData") {
                    inside = In::Other;
                }
            }
            _ => {}
        }
        buffer.clear();
    }
    Ok(Some(()))
}

/// The `<VTKFile>` tag's byte order, size integers and compressor, into `header`; `None` where
/// they are for vtkio.
pub(super) fn read_file_settings(e: &BytesStart<'_>, header: &mut Header) -> Option<()> {
    // Image data and rectilinear grids have no particle positions: vtkio's path says so.
    if !matches!(
        attribute(e, b"type").as_deref(),
        Some("PolyData" | "UnstructuredGrid" | "StructuredGrid")
    ) {
        return None;
    }
    header.big_endian = attribute(e, b"byte_order").as_deref() == Some("BigEndian");
    header.int_bytes = match attribute(e, b"header_type").as_deref() {
        Some("UInt64") => 8,
        Some("UInt32") | None => 4,
        Some(_) => return None,
    };
    header.compressor = match attribute(e, b"compressor").as_deref() {
        None | Some("") => None,
        // Another name: vtkio refuses it in its words.
        Some(name) => Some(Codec::parse(name)?),
    };
    Some(())
}

/// A `<DataArray>` of points or point data; `None` where it is not appended, or of a type this
/// reader leaves to vtkio.
fn read_array(at: At<'_>, e: &BytesStart<'_>) -> Result<Option<ArrayDesc>, DataError> {
    if attribute(e, b"format").as_deref() != Some("appended") {
        return Ok(None);
    }
    let Some(mut desc) = array_desc(at, e, 0, Stored::Appended)? else {
        return Ok(None);
    };
    desc.offset = attribute(e, b"offset")
        .and_then(|v| v.trim().parse::<u64>().ok())
        .ok_or_else(|| at.malformed(format!("array '{}': bad offset", desc.name)))?;
    Ok(Some(desc))
}

/// A `<DataArray>`'s name, type and components, its values at `offset` stored as `stored`;
/// `None` for a type this reader leaves to vtkio.
pub(super) fn array_desc(
    at: At<'_>,
    e: &BytesStart<'_>,
    offset: u64,
    stored: Stored,
) -> Result<Option<ArrayDesc>, DataError> {
    let Some(scalar) = attribute(e, b"type").as_deref().and_then(parse_scalar) else {
        return Ok(None);
    };
    let name = attribute(e, b"Name").unwrap_or_default();
    let components = attribute(e, b"NumberOfComponents")
        .map(|v| v.trim().parse::<usize>())
        .transpose()
        .map_err(|_| at.malformed(format!("array '{name}': bad NumberOfComponents")))?
        .unwrap_or(1);
    if components == 0 {
        return Err(at.malformed(format!("array '{name}' has 0 components")));
    }
    Ok(Some(ArrayDesc {
        name,
        scalar,
        components,
        offset,
        stored,
    }))
}

/// Reads arrays out of the appended data, or inline in the XML.
pub(super) struct ArrayReader<'a> {
    at: At<'a>,
    file: File,
    file_len: u64,
    header: &'a Header,
    /// The file's bytes (mapped) where it has inline ascii arrays.
    text: Option<&'a [u8]>,
    /// Where the runs of the array being read count their offsets from, and whether they are
    /// base64: the appended data's, or (an inline array) the file's start and base64.
    data_start: u64,
    base64: bool,
}

impl<'a> ArrayReader<'a> {
    /// A reader of `file`'s arrays as `header` describes them (`text`: its bytes, mapped,
    /// where it has inline ascii arrays).
    pub(super) fn new(
        at: At<'a>,
        file: File,
        header: &'a Header,
        text: Option<&'a [u8]>,
    ) -> Result<Self, DataError> {
        Ok(ArrayReader {
            at,
            file_len: crate::io::file_len(at, &file)?,
            file,
            header,
            text,
            data_start: header.data_start,
            base64: header.base64,
        })
    }

    /// Where `len` bytes at `pos` of the appended data start in the file, refused when they
    /// lie past the file's end (checked before allocating: a hostile offset or size cannot make
    /// us allocate, and a part checks the whole array lies in the file without reading it).
    fn span(&self, pos: u64, len: u64, what: &str) -> Result<u64, DataError> {
        let start = self.data_start.checked_add(pos);
        let end = start.and_then(|s| s.checked_add(len));
        let (Some(start), Some(end)) = (start, end) else {
            return Err(self
                .at
                .malformed(format!("{what} lies past the end of the file")));
        };
        if end > self.file_len {
            return Err(self.at.malformed(format!(
                "{what} lies past the end of the file (appended data is truncated: it ends at \
                 byte {}, the data would end at {end})",
                self.file_len
            )));
        }
        Ok(start)
    }

    /// `len` bytes at `pos` of the appended data (see [`Self::span`]).
    fn bytes(&mut self, pos: u64, len: u64, what: &str) -> Result<Vec<u8>, DataError> {
        let start = self.span(pos, len, what)?;
        self.file
            .seek(SeekFrom::Start(start))
            .map_err(|e| self.at.io(e))?;
        let mut out = vec![0u8; len as usize];
        self.file.read_exact(&mut out).map_err(|e| self.at.io(e))?;
        Ok(out)
    }

    /// How many bytes of the appended data a run of `len` bytes VTK wrote takes: raw, `len`;
    /// base64, 4 characters per 3 bytes (the last group padded).
    fn encoded_len(&self, len: u64, what: &str) -> Result<u64, DataError> {
        if !self.base64 {
            return Ok(len);
        }
        len.div_ceil(3)
            .checked_mul(4)
            .ok_or_else(|| self.at.malformed(format!("{what} overflows")))
    }

    /// Refuses a run of `len` bytes at `pos` that lies past the file's end; where the next run
    /// starts.
    fn check_run(&self, pos: u64, len: u64, what: &str) -> Result<u64, DataError> {
        let encoded = self.encoded_len(len, what)?;
        self.span(pos, encoded, what)?;
        Ok(pos + encoded)
    }

    /// The `len` bytes VTK wrote as one run at `pos` of the appended data, and where the next
    /// run starts: raw, the bytes themselves; base64, the run's own encoding (4 characters per
    /// 3 bytes, padded at its end). A prefix of a run may be asked for (its first groups
    /// decode alone).
    fn run(&mut self, pos: u64, len: u64, what: &str) -> Result<(Vec<u8>, u64), DataError> {
        let next = pos
            .checked_add(self.encoded_len(len, what)?)
            .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
        Ok((self.run_bytes(pos, 0..len, what)?, next))
    }

    /// Bytes `range` of the run VTK wrote at `pos` of the appended data, reading only them:
    /// raw, their own bytes; base64, the 4-character groups that hold them (byte `b` of a run
    /// lies in group `b / 3`: every group decodes alone, and only the run's last is padded).
    fn run_bytes(&mut self, pos: u64, range: Range<u64>, what: &str) -> Result<Vec<u8>, DataError> {
        let len = range.end - range.start;
        if !self.base64 {
            let from = pos
                .checked_add(range.start)
                .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
            return self.bytes(from, len, what);
        }
        use base64::Engine;
        let (first_group, end_group) = (range.start / 3, range.end.div_ceil(3));
        let from = first_group
            .checked_mul(4)
            .and_then(|c| pos.checked_add(c))
            .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
        let text = self.bytes(from, (end_group - first_group) * 4, what)?;
        // Decoded in parallel: every 4-character group decodes alone, and only the last may
        // be padded.
        use rayon::prelude::*;
        let pieces: Vec<Vec<u8>> = text
            .par_chunks(1 << 20)
            .map(|chunk| base64::engine::general_purpose::STANDARD.decode(chunk))
            .collect::<Result<_, _>>()
            .map_err(|e| self.at.malformed(format!("{what}: bad base64: {e}")))?;
        let mut decoded = pieces.concat();
        let skip = (range.start - first_group * 3) as usize;
        if (decoded.len() as u64) < range.end - first_group * 3 {
            return Err(self.at.malformed(format!(
                "{what}: its base64 holds {} bytes, not {}",
                first_group * 3 + decoded.len() as u64,
                range.end
            )));
        }
        decoded.truncate(skip + len as usize);
        decoded.drain(..skip);
        Ok(decoded)
    }

    /// The size integers in `bytes` (the file's integer width and byte order).
    fn ints(&self, bytes: &[u8]) -> Vec<u64> {
        let w = self.header.int_bytes;
        bytes
            .chunks_exact(w)
            .map(|b| {
                let mut le = [0u8; 8];
                le[..w].copy_from_slice(b);
                if self.header.big_endian {
                    le[..w].reverse();
                }
                u64::from_le_bytes(le)
            })
            .collect()
    }

    /// The values of rows `rows` of `array` (of `n` points), as f64: only those rows' bytes
    /// are read, decoded and inflated (for zlib, the blocks that hold them; ascii, parsed).
    fn values(
        &mut self,
        array: &ArrayDesc,
        n: usize,
        rows: Range<usize>,
    ) -> Result<Vec<f64>, DataError> {
        let name = &array.name;
        (self.data_start, self.base64) = match array.stored {
            Stored::Appended => (self.header.data_start, self.header.base64),
            Stored::Inline => (0, true),
            Stored::Ascii { end } => return self.ascii_values(array, end, n, rows),
        };
        let row_bytes = (array.components as u64)
            .checked_mul(array.scalar.size() as u64)
            .ok_or_else(|| self.at.malformed(format!("array '{name}' overflows")))?;
        let expected = (n as u64)
            .checked_mul(row_bytes)
            .ok_or_else(|| self.at.malformed(format!("array '{name}' overflows")))?;
        // Checked before anything is allocated: a hostile header could declare terabytes.
        let limit = if self.header.compressor.is_some() {
            self.file_len
                .saturating_mul(super::MAX_INFLATION as u64)
                .saturating_add(1 << 20)
        } else {
            self.file_len
        };
        if expected > limit {
            return Err(self.at.malformed(format!(
                "array '{name}' would hold {expected} bytes ({n} points of {} {:?}), more than \
                 this {}-byte file can hold",
                array.components, array.scalar, self.file_len
            )));
        }
        let w = self.header.int_bytes as u64;
        if rows.is_empty() {
            // Another part's rows: only checked to lie in the file, from the header (a
            // compressed array's block sizes are not read, so only its header's start).
            let extent = if self.header.compressor.is_some() {
                3 * w
            } else {
                w + expected
            };
            self.check_run(array.offset, extent, &format!("array '{name}'"))?;
            return Ok(Vec::new());
        }
        // The rows' bytes in the uncompressed array (within `expected`: rows lie in 0..n).
        let wanted = rows.start as u64 * row_bytes..rows.end as u64 * row_bytes;
        let data = if let Some(codec) = self.header.compressor {
            self.inflated(array, codec, n, expected, wanted)?
        } else {
            let what = format!("array '{name}'s size");
            let (head, _) = self.run(array.offset, w, &what)?;
            let size = self.ints(&head)[0];
            if size != expected {
                return Err(self.at.malformed(format!(
                    "array '{name}' holds {size} bytes; {n} points of {} {:?} need {expected}",
                    array.components, array.scalar
                )));
            }
            // The size and the data are one run: the whole must lie in the file.
            let what = format!("array '{name}'");
            self.check_run(array.offset, w + size, &what)?;
            self.run_bytes(array.offset, w + wanted.start..w + wanted.end, &what)?
        };
        let big_endian = self.header.big_endian;
        use rayon::prelude::*;
        Ok(data
            .par_chunks_exact(array.scalar.size())
            .map(|b| array.scalar.value(b, big_endian))
            .collect())
    }

    /// Rows `rows` of an inline ascii array of `n` points whose text ends at byte `end`: every
    /// value of the array counted (their number checked, as a whole read checks it), the
    /// values before the rows skipped by counting, only the rows' own parsed.
    fn ascii_values(
        &self,
        array: &ArrayDesc,
        end: u64,
        n: usize,
        rows: Range<usize>,
    ) -> Result<Vec<f64>, DataError> {
        let name = &array.name;
        let Some(text) = self
            .text
            .and_then(|t| t.get(array.offset as usize..end as usize))
        else {
            return Err(self
                .at
                .malformed(format!("array '{name}' lies past the end of the file")));
        };
        let c = array.components;
        let expected = n.checked_mul(c);
        let found = super::tokens::count(text);
        if expected != Some(found) {
            return Err(self.at.malformed(format!(
                "array '{name}' holds {found} values (bytes {}..{end}); {n} points of {c} \
                 components need {}",
                array.offset,
                expected.map_or_else(|| "overflowing".into(), |e| e.to_string())
            )));
        }
        if rows.is_empty() {
            return Ok(Vec::new());
        }
        let first = super::tokens::skip(text, rows.start * c, false)
            .map_err(|_| self.at.malformed(format!("array '{name}' ends early")))?;
        super::tokens::parse(&text[first..], rows.len() * c, array.scalar, false).map_err(|bad| {
            self.at.malformed(format!(
                "array '{name}': '{}' at byte {} is not a {:?} value",
                bad.token,
                array.offset as usize + first + bad.at,
                array.scalar
            ))
        })
    }

    /// How many bytes of the file the inline base64 array at byte `pos` takes (its runs, as
    /// their headers size them), refused where they lie past the file's end.
    pub(super) fn inline_extent(&mut self, pos: u64, what: &str) -> Result<u64, DataError> {
        (self.data_start, self.base64) = (0, true);
        let w = self.header.int_bytes as u64;
        let end = if self.header.compressor.is_some() {
            let (head, _) = self.run(pos, 3 * w, what)?;
            let blocks = self.ints(&head)[0];
            let header_len = blocks
                .checked_add(3)
                .and_then(|b| b.checked_mul(w))
                .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
            let (header, data_pos) = self.run(pos, header_len, what)?;
            let total = self
                .ints(&header[(3 * w) as usize..])
                .into_iter()
                .try_fold(0u64, u64::checked_add)
                .ok_or_else(|| self.at.malformed(format!("{what}: block sizes overflow")))?;
            self.check_run(data_pos, total, what)?
        } else {
            let (head, _) = self.run(pos, w, what)?;
            let size = self.ints(&head)[0];
            let total = size
                .checked_add(w)
                .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
            self.check_run(pos, total, what)?
        };
        Ok(end - pos)
    }

    /// Bytes `wanted` of an array of `expected` bytes compressed by `codec`: its header read
    /// whole (block count, block size, last block's size, each block's compressed size), then
    /// only the blocks that overlap `wanted` read and decompressed.
    fn inflated(
        &mut self,
        array: &ArrayDesc,
        codec: Codec,
        n: usize,
        expected: u64,
        wanted: Range<u64>,
    ) -> Result<Vec<u8>, DataError> {
        let name = &array.name;
        let w = self.header.int_bytes as u64;
        let what = format!("array '{name}'s compressed header");
        let (head, _) = self.run(array.offset, 3 * w, &what)?;
        let head = self.ints(&head);
        // The last block's size is 0 when it is full (VTK's format).
        let (blocks, block_size) = (head[0], head[1]);
        let last = if head[2] == 0 { block_size } else { head[2] };
        let declared = block_size
            .checked_mul(blocks.saturating_sub(1))
            .and_then(|v| v.checked_add(if blocks == 0 { 0 } else { last }));
        if declared != Some(expected) || last > block_size {
            return Err(self.at.malformed(format!(
                "array '{name}' declares {} uncompressed bytes ({blocks} blocks of \
                 {block_size}, the last {last}); {n} points of {} {:?} need {expected}",
                declared.map_or_else(|| "overflowing".into(), |d| d.to_string()),
                array.components,
                array.scalar
            )));
        }
        let header_len = blocks
            .checked_add(3)
            .and_then(|b| b.checked_mul(w))
            .ok_or_else(|| self.at.malformed(format!("{what} overflows")))?;
        let (header, data_pos) = self.run(array.offset, header_len, &what)?;
        let sizes = self.ints(&header[(3 * w) as usize..]);
        // Where each block starts among the compressed bytes, and where they end.
        let mut starts = Vec::with_capacity(sizes.len() + 1);
        let mut total = 0u64;
        for &size in &sizes {
            starts.push(total);
            total = total.checked_add(size).ok_or_else(|| {
                self.at
                    .malformed(format!("array '{name}': block sizes overflow"))
            })?;
        }
        starts.push(total);
        let what = format!("array '{name}'s blocks");
        // Every block must lie in the file, as when the whole array is read.
        self.check_run(data_pos, total, &what)?;
        // The blocks that overlap the wanted bytes (`expected` > 0 here, so block_size > 0).
        let first = (wanted.start / block_size) as usize;
        let end = wanted.end.div_ceil(block_size) as usize;
        let packed = self.run_bytes(data_pos, starts[first]..starts[end], &what)?;
        let base = starts[first];
        let unpacked_start = first as u64 * block_size;
        let unpacked_end = (end as u64 * block_size).min(expected);
        let mut out = vec![0u8; (unpacked_end - unpacked_start) as usize];
        // The blocks inflate independently: in parallel, each into its place.
        use rayon::prelude::*;
        let at = self.at;
        out.par_chunks_mut(block_size as usize)
            .enumerate()
            .try_for_each(|(k, target)| {
                let b = first + k;
                let from = (starts[b] - base) as usize;
                let to = (starts[b + 1] - base) as usize;
                let len = target.len();
                codec.unpack(&packed[from..to], target).map_err(|e| {
                    at.malformed(format!(
                        "array '{name}' block {b}: cannot {} its {} data to {len} bytes: {e}",
                        codec.verb(),
                        codec.name()
                    ))
                })
            })?;
        let skip = (wanted.start - unpacked_start) as usize;
        out.truncate(skip + (wanted.end - wanted.start) as usize);
        out.drain(..skip);
        Ok(out)
    }
}
