//! NumPy `.npy` arrays: particles as an N x (3 + k) array (columns x, y, z, then k attributes
//! named `col3`, `col4`, ...), and the query points and results of `aarbf field`.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek};
use std::path::Path;

use glam::DVec3;
use npyz::{DType, NpyFile, Order, WriterBuilder};

use super::{At, AttributeSelection, Columns, DataError, Problem, file_len};
use crate::values::Attribute;

/// A 2-D array in row-major order.
#[derive(Clone, Debug, PartialEq)]
pub struct Matrix {
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
}

impl Matrix {
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

/// Reads a 2-D numeric array of any element type as f64 (a 1-D array of length 3 is one row).
pub fn read_matrix(at: At<'_>) -> Result<Matrix, DataError> {
    let file = File::open(at.file).map_err(|e| at.io(e))?;
    let size = file_len(at, &file)?;
    let mut reader = BufReader::new(file);
    check_header(at, &mut reader, size)?;
    let header = npyz::NpyHeader::from_reader(&mut reader)
        .map_err(|e| at.malformed(format!("not a valid .npy file: {e}")))?;
    let data_start = reader.stream_position().map_err(|e| at.io(e))?;
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
    let item = match npy.dtype() {
        DType::Plain(t) => t.size_field(),
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
    let data = read_as_f64(npy).map_err(|e| at.malformed(e))?;
    let (rows, cols) = (rows as usize, cols as usize);
    let data = if fortran && rows > 1 && cols > 1 {
        let mut c = vec![0.0; data.len()];
        for i in 0..rows {
            for j in 0..cols {
                c[i * cols + j] = data[j * rows + i];
            }
        }
        c
    } else {
        data
    };
    Ok(Matrix { rows, cols, data })
}

fn read_as_f64<R: Read>(npy: NpyFile<R>) -> Result<Vec<f64>, String> {
    fn all<T: npyz::Deserialize + Into<f64>, R: Read>(
        npy: NpyFile<R>,
    ) -> Result<Result<Vec<f64>, String>, NpyFile<R>> {
        npy.try_data::<T>().map(|data| {
            data.map(|v| v.map(Into::into))
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|e| format!("cannot read the array data: {e}"))
        })
    }
    macro_rules! try_types {
        ($npy:expr, $($t:ty),*) => {{
            let npy = $npy;
            $(let npy = match all::<$t, _>(npy) { Ok(r) => return r, Err(npy) => npy };)*
            Err(format!("unsupported element type {}", npy.dtype().descr()))
        }};
    }
    try_types!(npy, f64, f32, i32, u32, i16, u16, i8, u8)
}

pub fn read_step(at: At<'_>, selection: &AttributeSelection) -> Result<Columns, DataError> {
    let m = read_matrix(at)?;
    if m.cols < 3 {
        return Err(at.err(Problem::Dimensionality(format!(
            "a particle array needs at least 3 columns (x, y, z), found {}",
            m.cols
        ))));
    }
    let positions = (0..m.rows)
        .map(|i| {
            let r = m.row(i);
            DVec3::new(r[0], r[1], r[2])
        })
        .collect();
    let (kept, skipped): (Vec<usize>, Vec<usize>) =
        (3..m.cols).partition(|c| selection.keeps(&format!("col{c}")));
    let attributes = kept
        .into_iter()
        .map(|c| Attribute {
            name: format!("col{c}"),
            values: (0..m.rows).map(|i| m.data[i * m.cols + c]).collect(),
        })
        .collect();
    Ok(Columns {
        positions,
        attributes,
        skipped: skipped.into_iter().map(|c| format!("col{c}")).collect(),
    })
}

/// Writes a row-major `rows x cols` array of f64 or f32 (the dtype follows the element type).
pub fn write_matrix<T: npyz::AutoSerialize + Copy>(
    path: &Path,
    rows: usize,
    cols: usize,
    data: &[T],
) -> std::io::Result<()> {
    assert_eq!(data.len(), rows * cols);
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[rows as u64, cols as u64])
        .writer(BufWriter::new(File::create(path)?))
        .begin_nd()?;
    writer.extend(data.iter().copied())?;
    writer.finish()
}
