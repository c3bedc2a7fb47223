//! NumPy `.npy` arrays: particles as an N x (3 + k) array (columns x, y, z, then k attributes
//! named `col3`, `col4`, ...), and the query points and results of `aarbf field`.

use std::fs::File;
use std::io::{BufWriter, Cursor, Read, Seek};
use std::ops::Range;
use std::path::Path;

use glam::DVec3;
use npyz::{DType, NpyFile, Order, WriterBuilder};
use rayon::prelude::*;

use super::mapped::Mapped;
use super::scalar::{InRecord, Scalar, decode_records, strided_column};
use super::{At, AttributeSelection, Columns, DataError, Part, Problem};
use crate::values::Attribute;

/// A 2-D array in row-major order.
#[derive(Clone, Debug, PartialEq)]
pub struct Matrix {
    /// Rows (M).
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// `rows · cols` values, row after row.
    pub data: Vec<f64>,
}

impl Matrix {
    /// Row `i`'s `cols` values.
    pub fn row(&self, i: usize) -> &[f64] {
        &self.data[i * self.cols..(i + 1) * self.cols]
    }
}

/// How deeply a .npy header's Python literal may nest brackets. Real headers nest two deep
/// (`{'shape': (n, 3)}`), structured dtypes a few more; npyz's literal parser backtracks
/// exponentially in the depth (a 235-byte header of `[[[[...` took over 10 s).
const MAX_HEADER_NESTING: usize = 6;

/// Refuses a header longer than the file before npyz allocates a buffer of that length (a
/// version 2/3 header declares it as a u32: a hostile 10-byte file could ask for 4 GiB), and
/// one nested deeper than [`MAX_HEADER_NESTING`] before npyz parses it.
fn check_header(at: At<'_>, reader: &mut (impl Read + Seek), size: u64) -> Result<(), DataError> {
    let mut prefix = Vec::with_capacity(12);
    reader
        .by_ref()
        .take(12)
        .read_to_end(&mut prefix)
        .map_err(|e| at.io(e))?;
    reader.rewind().map_err(|e| at.io(e))?;
    let got = prefix.len();
    if got < 10 || &prefix[..6] != b"\x93NUMPY" {
        // npyz reports a short or foreign file itself.
        return Ok(());
    }
    let (len, prefix_len) = match prefix[6] {
        1 => (u64::from(u16::from_le_bytes([prefix[8], prefix[9]])), 10),
        _ if got >= 12 => (
            u64::from(u32::from_le_bytes([
                prefix[8], prefix[9], prefix[10], prefix[11],
            ])),
            12,
        ),
        _ => return Ok(()),
    };
    if prefix_len + len > size {
        return Err(at.malformed(format!(
            "the .npy header claims {len} bytes but the file holds {size}"
        )));
    }
    let mut header = Vec::with_capacity(len as usize);
    reader
        .seek(std::io::SeekFrom::Start(prefix_len))
        .map_err(|e| at.io(e))?;
    reader
        .by_ref()
        .take(len)
        .read_to_end(&mut header)
        .map_err(|e| at.io(e))?;
    reader.rewind().map_err(|e| at.io(e))?;
    let mut depth = 0usize;
    for &c in &header {
        match c {
            b'(' | b'[' | b'{' => {
                depth += 1;
                if depth > MAX_HEADER_NESTING {
                    return Err(at.malformed(format!(
                        "the .npy header nests brackets more than {MAX_HEADER_NESTING} deep"
                    )));
                }
            }
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    // npyz multiplies the shape's dimensions unchecked (a panic with debug assertions, a
    // wrapped count without): a shape whose element count overflows is refused here.
    let text = String::from_utf8_lossy(&header);
    if let Some(dims) = text
        .split("'shape'")
        .nth(1)
        .and_then(|r| r.split('(').nth(1))
        .and_then(|r| r.split(')').next())
    {
        let product = dims
            .split(',')
            .map(str::trim)
            .filter(|d| !d.is_empty())
            .try_fold(1u64, |acc, d| {
                d.parse::<u64>()
                    .ok()
                    .map_or(Some(acc), |v| acc.checked_mul(v))
            });
        if product.is_none() {
            return Err(at.malformed(format!(
                "the .npy shape ({dims}) has more elements than a 64-bit count holds"
            )));
        }
    }
    Ok(())
}

/// A 2-D array in a mapped `.npy` file: its shape, element type and layout. Values are
/// decoded from the map only for the columns asked for.
struct MappedArray {
    bytes: Mapped,
    data_start: usize,
    rows: usize,
    cols: usize,
    scalar: Scalar,
    big_endian: bool,
    fortran: bool,
}

/// The element type a NumPy type string (`<f8`, `|u1`, `>i4`, `|b1`) names; `None` for
/// types that are not plain real numbers (complex, half floats, dates, strings, objects).
fn scalar_of(descr: &str) -> Option<(Scalar, bool)> {
    let mut chars = descr.chars();
    let big_endian = match chars.next()? {
        '>' | '!' => true,
        '<' | '|' => false,
        '=' => cfg!(target_endian = "big"),
        _ => return None,
    };
    let kind = chars.next()?;
    let size: usize = chars.as_str().parse().ok()?;
    let scalar = match (kind, size) {
        ('f', 4) => Scalar::F32,
        ('f', 8) => Scalar::F64,
        ('i', 1) => Scalar::I8,
        ('i', 2) => Scalar::I16,
        ('i', 4) => Scalar::I32,
        ('i', 8) => Scalar::I64,
        ('u' | 'b', 1) => Scalar::U8,
        ('u', 2) => Scalar::U16,
        ('u', 4) => Scalar::U32,
        ('u', 8) => Scalar::U64,
        _ => return None,
    };
    Some((scalar, big_endian))
}

impl MappedArray {
    fn open(at: At<'_>) -> Result<MappedArray, DataError> {
        let bytes = Mapped::open(at)?;
        let size = bytes.len() as u64;
        let mut reader = Cursor::new(&bytes[..]);
        check_header(at, &mut reader, size)?;
        let header = npyz::NpyHeader::from_reader(&mut reader)
            .map_err(|e| at.malformed(format!("not a valid .npy file: {e}")))?;
        let data_start = reader.position();
        let npy = NpyFile::with_header(header, reader);
        let shape = npy.shape().to_vec();
        let (rows, cols) = match shape.as_slice() {
            [r, c] => (*r, *c),
            [n] if *n == 3 => (1, 3),
            other => {
                return Err(at.err(Problem::Dimensionality(format!(
                    "expected a 2-D array (N rows x columns), found shape {other:?}"
                ))));
            }
        };
        let (scalar, big_endian) = match npy.dtype() {
            DType::Plain(t) => scalar_of(&t.to_string()).ok_or_else(|| {
                at.malformed(format!(
                    "unsupported element type {t} (expected real numbers: float32/64, \
                     (u)int8 to (u)int64 or bool)"
                ))
            })?,
            other => {
                return Err(at.malformed(format!(
                    "expected a plain numeric array, found dtype {}",
                    other.descr()
                )));
            }
        };
        let elements = rows
            .checked_mul(cols)
            .ok_or_else(|| at.malformed(format!("shape {shape:?} overflows")))?;
        let item = scalar.size() as u64;
        let available = size.saturating_sub(data_start);
        at.check_count("array element", elements, item, available)?;
        if elements * item > available {
            return Err(at.err(Problem::Truncated {
                what: format!("a {rows} x {cols} array"),
                needed: elements * item,
                available,
            }));
        }
        let fortran = npy.order() == Order::Fortran;
        Ok(MappedArray {
            bytes,
            data_start: data_start as usize,
            rows: rows as usize,
            cols: cols as usize,
            scalar,
            big_endian,
            fortran,
        })
    }

    /// The positions (columns 0, 1, 2) and the columns `attributes` of the rows `rows`,
    /// decoded in parallel straight from the map: in C order a row at a time (one pass over
    /// the rows' bytes), in Fortran order a column at a time (each a contiguous run).
    fn columns(
        &self,
        attributes: impl Iterator<Item = usize>,
        rows: Range<usize>,
    ) -> (Vec<DVec3>, Vec<Vec<f64>>) {
        let attributes: Vec<usize> = attributes.collect();
        if self.fortran {
            let [x, y, z] = [0, 1, 2].map(|c| self.column(c, rows.clone()));
            let positions = (x, y, z)
                .into_par_iter()
                .map(|(x, y, z)| DVec3::new(x, y, z))
                .collect();
            return (
                positions,
                attributes
                    .iter()
                    .map(|&c| self.column(c, rows.clone()))
                    .collect(),
            );
        }
        let item = self.scalar.size();
        let at = |c: usize| InRecord {
            offset: c * item,
            scalar: self.scalar,
        };
        let wanted: Vec<InRecord> = attributes.iter().map(|&c| at(c)).collect();
        decode_records(
            &self.bytes[self.data_start + rows.start * self.cols * item..],
            rows.len(),
            self.cols * item,
            self.big_endian,
            [at(0), at(1), at(2)],
            &wanted,
        )
    }

    /// Column `c` of the rows `rows`, decoded in parallel straight from the map.
    fn column(&self, c: usize, rows: Range<usize>) -> Vec<f64> {
        let item = self.scalar.size();
        let (stride, offset) = if self.fortran {
            (item, (c * self.rows + rows.start) * item)
        } else {
            (self.cols * item, (rows.start * self.cols + c) * item)
        };
        strided_column(
            &self.bytes[self.data_start..],
            rows.len(),
            stride,
            offset,
            self.scalar,
            self.big_endian,
        )
    }
}

/// Reads a 2-D numeric array of any real element type as f64 (a 1-D array of length 3 is
/// one row), C or Fortran order, either byte order.
pub fn read_matrix(at: At<'_>) -> Result<Matrix, DataError> {
    let array = MappedArray::open(at)?;
    let (rows, cols) = (array.rows, array.cols);
    if !array.fortran {
        // Row-major already: every element in file order, one pass.
        let item = array.scalar.size();
        let data = strided_column(
            &array.bytes[array.data_start..],
            rows * cols,
            item,
            0,
            array.scalar,
            array.big_endian,
        );
        return Ok(Matrix { rows, cols, data });
    }
    let columns: Vec<Vec<f64>> = (0..cols).map(|c| array.column(c, 0..rows)).collect();
    let mut data = vec![0.0; rows * cols];
    if cols > 0 {
        data.par_chunks_mut(cols).enumerate().for_each(|(i, row)| {
            for (v, column) in row.iter_mut().zip(&columns) {
                *v = column[i];
            }
        });
    }
    Ok(Matrix { rows, cols, data })
}

/// Reads a particle step from an N x (3 + k) `.npy` array: columns x, y, z, then the attributes
/// `col3`, `col4`, ... (only the selected ones decoded).
///
/// Of that, `part`'s rows only (their bytes alone are decoded, in Fortran order each
/// column's run of them), and how many.
pub(super) fn read_step(
    at: At<'_>,
    selection: &AttributeSelection,
    part: Part,
) -> Result<(Columns, usize), DataError> {
    let array = MappedArray::open(at)?;
    if array.cols < 3 {
        return Err(at.err(Problem::Dimensionality(format!(
            "a particle array needs at least 3 columns (x, y, z), found {}",
            array.cols
        ))));
    }
    // Only the columns the scene keeps are decoded.
    let (kept, skipped): (Vec<usize>, Vec<usize>) =
        (3..array.cols).partition(|c| selection.keeps(&format!("col{c}")));
    let rows = part.range(array.rows);
    let decoded = rows.len();
    let (positions, values) = array.columns(kept.iter().copied(), rows);
    let attributes = kept
        .into_iter()
        .zip(values)
        .map(|(c, values)| Attribute {
            name: format!("col{c}"),
            values,
        })
        .collect();
    let columns = Columns {
        positions,
        attributes,
        skipped: skipped.into_iter().map(|c| format!("col{c}")).collect(),
        finite: false,
    };
    Ok((columns, decoded))
}

/// Writes a row-major `rows x cols` array of f64 or f32 (the dtype follows the element type).
pub fn write_matrix<T: npyz::AutoSerialize + Copy>(
    path: &Path,
    rows: usize,
    cols: usize,
    data: &[T],
) -> std::io::Result<()> {
    assert_eq!(data.len(), rows * cols);
    let mut writer = MatrixWriter::create(path, rows, cols)?;
    writer.append(data)?;
    writer.finish()
}

/// A row-major `rows x cols` `.npy` array written a run of rows at a time, so the whole array
/// need never be in memory (the shape is in the header, so it is known from the start).
pub struct MatrixWriter<T: npyz::AutoSerialize + Copy> {
    writer: npyz::NpyWriter<T, BufWriter<File>>,
}

impl<T: npyz::AutoSerialize + Copy> MatrixWriter<T> {
    /// Creates `path` with the header of a `rows x cols` array of `T`.
    pub fn create(path: &Path, rows: usize, cols: usize) -> std::io::Result<Self> {
        let writer = npyz::WriteOptions::new()
            .default_dtype()
            .shape(&[rows as u64, cols as u64])
            .writer(BufWriter::new(File::create(path)?))
            .begin_nd()?;
        Ok(MatrixWriter { writer })
    }

    /// Appends elements, row-major (whole rows or not: rows are only a view of the sequence).
    pub fn append(&mut self, data: &[T]) -> std::io::Result<()> {
        self.writer.extend(data.iter().copied())
    }

    /// Flushes the file; an error if fewer or more than `rows x cols` elements were appended.
    pub fn finish(self) -> std::io::Result<()> {
        self.writer.finish()
    }
}
