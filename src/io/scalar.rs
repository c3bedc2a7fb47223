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
