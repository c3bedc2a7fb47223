//! Binary scalars as files store them (PLY properties, VTK arrays): their sizes, and their
//! values as f64 in either byte order. Each format names them its own way and maps its names
//! here.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    /// The value of the first [`size`](Self::size) bytes of `b`. 64-bit integers beyond 2^53
    /// round to the nearest f64.
    pub(crate) fn value(self, b: &[u8], big_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty) => {{
                let a = b[..std::mem::size_of::<$t>()].try_into().unwrap();
                (if big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => num!(i16),
            Scalar::U16 => num!(u16),
            Scalar::I32 => num!(i32),
            Scalar::U32 => num!(u32),
            Scalar::I64 => num!(i64),
            Scalar::U64 => num!(u64),
            Scalar::F32 => num!(f32),
            Scalar::F64 => num!(f64),
        }
    }
}

/// Values `n` records of `stride` bytes hold at `offset` within each record, from `bytes`
/// (which must hold them: the caller checked `bytes.len()` against the records' extent):
/// one column of a table of fixed-size records (PLY's vertex rows, a C-order NumPy array), or
/// of a run of consecutive scalars (`stride` = the scalar's size). Decoded in parallel.
pub(crate) fn strided_column(
    bytes: &[u8],
    n: usize,
    stride: usize,
    offset: usize,
    scalar: Scalar,
    big_endian: bool,
) -> Vec<f64> {
    use rayon::prelude::*;
    debug_assert!(n == 0 || (n - 1) * stride + offset + scalar.size() <= bytes.len());
    // Enough values per task that rayon's bookkeeping is noise beside the decode.
    const CHUNK: usize = 1 << 15;
    let mut out = vec![0.0; n];
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(chunk, values)| {
            let first = chunk * CHUNK;
            for (k, v) in values.iter_mut().enumerate() {
                let at = (first + k) * stride + offset;
                *v = scalar.value(&bytes[at..], big_endian);
            }
        });
    out
}

/// Where a value sits in a fixed-size record, and its type.
#[derive(Clone, Copy, Debug)]
pub(crate) struct InRecord {
    pub offset: usize,
    pub scalar: Scalar,
}

/// The positions (`xyz`) and the columns `attributes` name, from `n` records of `stride`
/// bytes at the start of `bytes` (which must hold them: the caller checked): one parallel pass
/// over the records, each record's values decoded together while its cache line is loaded
/// (a column at a time would read the whole table once per column).
pub(crate) fn decode_records(
    bytes: &[u8],
    n: usize,
    stride: usize,
    big_endian: bool,
    xyz: [InRecord; 3],
    attributes: &[InRecord],
) -> (Vec<glam::DVec3>, Vec<Vec<f64>>) {
    use rayon::prelude::*;
    debug_assert!(n * stride <= bytes.len());
    const CHUNK: usize = 1 << 14;
    let mut positions = vec![glam::DVec3::ZERO; n];
    let mut columns: Vec<Vec<f64>> = attributes.iter().map(|_| vec![0.0; n]).collect();
    // Chunk c of every column, together.
    let mut chunks: Vec<Vec<&mut [f64]>> = (0..n.div_ceil(CHUNK)).map(|_| Vec::new()).collect();
    for column in &mut columns {
        for (c, part) in column.chunks_mut(CHUNK).enumerate() {
            chunks[c].push(part);
        }
    }
    positions
        .par_chunks_mut(CHUNK)
        .zip(chunks.into_par_iter())
        .enumerate()
        .for_each(|(c, (points, mut parts))| {
            let first = c * CHUNK;
            for (k, point) in points.iter_mut().enumerate() {
                let record = &bytes[(first + k) * stride..(first + k + 1) * stride];
                let [x, y, z] = xyz.map(|f| f.scalar.value(&record[f.offset..], big_endian));
                *point = glam::DVec3::new(x, y, z);
                for (part, f) in parts.iter_mut().zip(attributes) {
                    part[k] = f.scalar.value(&record[f.offset..], big_endian);
                }
            }
        });
    (positions, columns)
}
