//! The blue-noise mask type, its lookup and its asset format.
//!
//! Asset format (all little-endian):
//!
//! ```text
//! offset  size        field
//! 0       4           magic b"STBN"
//! 4       4           width  (u32, 1..=4096)
//! 8       4           height (u32, 1..=4096)
//! 12      4           depth  (u32, 1..=4096)
//! 16      2·W·H·D     values (u16), slice-major then row-major: index ((z·H) + y)·W + x
//! ```
//!
//! A value v stands for the number v / 65536 in [0, 1). The same order and two values per u32
//! word (even index in the low half) is what the GPU reads (`shaders_glsl/shared/noise.glsl`).

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use super::white::lowbias32;

/// The magic bytes that open a mask file.
pub const MAGIC: [u8; 4] = *b"STBN";
/// Bytes before the values.
pub const HEADER_LEN: u64 = 16;
/// The largest width, height or depth a mask file may declare.
pub const MAX_DIM: u32 = 4096;

/// The shipped 128 x 128 x 64 mask (seed 1, sigma 1.9); see the module docs of
/// [`crate::noise`] for how it is regenerated.
static BUILTIN_BYTES: &[u8] = include_bytes!("../../assets/stbn_128x128x64.bin");

/// Why a mask file cannot be read or written. Every variant names the file (or "built-in
/// mask") and what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum NoiseError {
    /// Opening, reading, creating or writing the file failed.
    #[error("{origin}: cannot read or write: {error}")]
    Io {
        /// The file's path as displayed, or "built-in mask".
        origin: String,
        /// The I/O error, quoted in the message.
        // Not a `#[source]`: the message includes it.
        error: std::io::Error,
    },
    /// The first four bytes are not [`MAGIC`].
    #[error("{origin}: not a blue-noise mask: the magic is {found:?}, expected \"STBN\"")]
    BadMagic {
        /// The file's path as displayed, or "built-in mask".
        origin: String,
        /// The first four bytes as found.
        found: [u8; 4],
    },
    /// The file is shorter than the [`HEADER_LEN`]-byte header.
    #[error("{origin}: file is truncated: the header needs 16 bytes but the file has {size}")]
    TruncatedHeader {
        /// The file's path as displayed, or "built-in mask".
        origin: String,
        /// Bytes the file has (fewer than 16).
        size: u64,
    },
    /// A declared width, height or depth is 0 or above [`MAX_DIM`].
    #[error("{origin}: bad dimensions {width} x {height} x {depth}: each must be in 1..={MAX_DIM}")]
    BadDimensions {
        /// The file's path as displayed, or "built-in mask".
        origin: String,
        /// Declared width (the header's bytes 4..8).
        width: u32,
        /// Declared height (bytes 8..12).
        height: u32,
        /// Declared depth (bytes 12..16).
        depth: u32,
    },
    /// The file size is not the header plus two bytes per value of the declared dimensions.
    #[error(
        "{origin}: size mismatch: a {width} x {height} x {depth} mask needs {expected} bytes \
         but the file has {size} ({problem})"
    )]
    SizeMismatch {
        /// The file's path as displayed, or "built-in mask".
        origin: String,
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Declared depth.
        depth: u32,
        /// Bytes a file of these dimensions has: 16 + 2·W·H·D.
        expected: u64,
        /// Bytes the file has.
        size: u64,
        /// "truncated" (too few bytes) or "trailing bytes" (too many).
        problem: &'static str,
    },
    /// A mask about to be written holds more or fewer values than W·H·D.
    #[error("{origin}: the mask holds {values} values but its dimensions need {expected}")]
    ValueCount {
        /// The destination path as displayed.
        origin: String,
        /// Values the mask holds.
        values: usize,
        /// W·H·D.
        expected: u64,
    },
}

/// A W x H x D spatiotemporal blue-noise mask: slice `z` is the mask for frame `z` (mod D).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BlueNoiseMask {
    /// Pixels per row (W), 1..=[`MAX_DIM`].
    pub width: u32,
    /// Rows per slice (H), 1..=[`MAX_DIM`].
    pub height: u32,
    /// Slices (D): frames before the mask repeats, 1..=[`MAX_DIM`].
    pub depth: u32,
    /// W·H·D values, slice-major then row-major; value v stands for v / 65536.
    pub values: Vec<u16>,
}

impl BlueNoiseMask {
    /// The shipped 128 x 128 x 64 mask, decoded once.
    pub fn builtin() -> &'static BlueNoiseMask {
        static MASK: OnceLock<BlueNoiseMask> = OnceLock::new();
        MASK.get_or_init(|| {
            BlueNoiseMask::from_bytes(BUILTIN_BYTES, "built-in mask")
                .expect("the shipped assets/stbn_128x128x64.bin is a valid mask")
        })
    }

    /// The index of (x, y, frame) in [`values`](Self::values), all three wrapped (toroidal).
    #[inline]
    pub fn index(&self, x: u32, y: u32, frame: u32) -> usize {
        let (w, h, d) = (
            self.width as usize,
            self.height as usize,
            self.depth as usize,
        );
        ((frame as usize % d) * h + (y as usize % h)) * w + (x as usize % w)
    }

    /// The toroidal shift of the mask for the cycle of `depth` frames that `frame` lies in: a
    /// new one every cycle, drawn from the seed and the cycle's index. A pixel's numbers in
    /// the next cycle are then another pixel's column of the mask (as stratified over [0, 1)
    /// as its own), so accumulation keeps converging past one cycle, while each cycle keeps the
    /// mask's spatiotemporal structure. The GLSL twin is `stbn_shift` in
    /// `shaders_glsl/shared/noise.glsl`.
    pub fn cycle_shift(seed: u32, frame: u32, depth: u32) -> [u32; 2] {
        let h = lowbias32(lowbias32(seed) ^ (frame / depth));
        [h & 0xffff, h >> 16]
    }

    /// The mask's number at pixel (x, y) of frame `frame`, in [0, 1); all coordinates wrap.
    #[inline]
    pub fn get(&self, x: u32, y: u32, frame: u32) -> f32 {
        f32::from(self.values[self.index(x, y, frame)]) * (1.0 / 65536.0)
    }

    /// The values packed two per little-endian u32 (value i in word i / 2, the low half for
    /// even i; an odd count is padded with a zero half), as the GPU buffer `stbn_words` holds
    /// them.
    pub fn packed_words(&self) -> Vec<u32> {
        self.values
            .chunks(2)
            .map(|pair| u32::from(pair[0]) | (u32::from(pair.get(1).copied().unwrap_or(0)) << 16))
            .collect()
    }

    /// The file image: header then values.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(HEADER_LEN as usize + 2 * self.values.len());
        bytes.extend_from_slice(&MAGIC);
        for dim in [self.width, self.height, self.depth] {
            bytes.extend_from_slice(&dim.to_le_bytes());
        }
        for v in &self.values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes
    }

    /// Decodes a file image; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<BlueNoiseMask, NoiseError> {
        let header = bytes
            .get(..HEADER_LEN as usize)
            .ok_or(NoiseError::TruncatedHeader {
                origin: origin.to_owned(),
                size: bytes.len() as u64,
            })?;
        let dims = parse_header(header, bytes.len() as u64, origin)?;
        Ok(BlueNoiseMask::from_values(
            dims,
            &bytes[HEADER_LEN as usize..],
        ))
    }

    /// A mask of `(width, height, depth)` from its values' little-endian bytes (checked
    /// against the dimensions by the caller).
    fn from_values((width, height, depth): (u32, u32, u32), bytes: &[u8]) -> BlueNoiseMask {
        BlueNoiseMask {
            width,
            height,
            depth,
            values: bytes
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]))
                .collect(),
        }
    }

    /// Writes the mask to `path` in the asset format.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), NoiseError> {
        let path = path.as_ref();
        self.check_len(&path.display().to_string())?;
        let io = |error| NoiseError::Io {
            origin: path.display().to_string(),
            error,
        };
        let mut file = std::io::BufWriter::new(File::create(path).map_err(io)?);
        file.write_all(&self.to_bytes()).map_err(io)?;
        file.flush().map_err(io)
    }

    /// Reads a mask written by [`write`](Self::write). The header and the file size are
    /// checked before the values are allocated.
    pub fn read(path: impl AsRef<Path>) -> Result<BlueNoiseMask, NoiseError> {
        let path: PathBuf = path.as_ref().to_owned();
        let origin = path.display().to_string();
        let io = |error| NoiseError::Io {
            origin: origin.clone(),
            error,
        };
        let mut file = File::open(&path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len();
        if size < HEADER_LEN {
            return Err(NoiseError::TruncatedHeader { origin, size });
        }
        let mut header = [0u8; HEADER_LEN as usize];
        file.read_exact(&mut header).map_err(io)?;
        let dims = parse_header(&header, size, &origin)?;
        let mut bytes = vec![0u8; (size - HEADER_LEN) as usize];
        file.read_exact(&mut bytes).map_err(io)?;
        Ok(BlueNoiseMask::from_values(dims, &bytes))
    }

    fn check_len(&self, origin: &str) -> Result<(), NoiseError> {
        let expected = u64::from(self.width) * u64::from(self.height) * u64::from(self.depth);
        if !dims_ok(self.width, self.height, self.depth) {
            return Err(NoiseError::BadDimensions {
                origin: origin.to_owned(),
                width: self.width,
                height: self.height,
                depth: self.depth,
            });
        }
        if self.values.len() as u64 != expected {
            return Err(NoiseError::ValueCount {
                origin: origin.to_owned(),
                values: self.values.len(),
                expected,
            });
        }
        Ok(())
    }
}

fn dims_ok(width: u32, height: u32, depth: u32) -> bool {
    [width, height, depth]
        .iter()
        .all(|&d| (1..=MAX_DIM).contains(&d))
}

/// Checks the 16-byte header against the total size; returns (width, height, depth).
fn parse_header(header: &[u8], size: u64, origin: &str) -> Result<(u32, u32, u32), NoiseError> {
    let word = |i: usize| u32::from_le_bytes(header[i..i + 4].try_into().expect("4 bytes"));
    let found: [u8; 4] = header[..4].try_into().expect("4 bytes");
    if found != MAGIC {
        return Err(NoiseError::BadMagic {
            origin: origin.to_owned(),
            found,
        });
    }
    let (width, height, depth) = (word(4), word(8), word(12));
    if !dims_ok(width, height, depth) {
        return Err(NoiseError::BadDimensions {
            origin: origin.to_owned(),
            width,
            height,
            depth,
        });
    }
    let expected = HEADER_LEN + 2 * u64::from(width) * u64::from(height) * u64::from(depth);
    if size != expected {
        return Err(NoiseError::SizeMismatch {
            origin: origin.to_owned(),
            width,
            height,
            depth,
            expected,
            size,
            problem: if size < expected {
                "truncated"
            } else {
                "trailing bytes"
            },
        });
    }
    Ok((width, height, depth))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> BlueNoiseMask {
        BlueNoiseMask {
            width: 3,
            height: 2,
            depth: 2,
            values: (0..12u16).map(|i| i * 5000 + 7).collect(),
        }
    }

    #[test]
    fn get_wraps_in_every_axis() {
        let m = small();
        assert_eq!(m.get(0, 0, 0), 7.0 / 65536.0);
        // (x, y, z) = (2, 1, 1) is index (1 * 2 + 1) * 3 + 2 = 11.
        assert_eq!(m.get(2, 1, 1), f32::from(11 * 5000 + 7u16) / 65536.0);
        assert_eq!(m.get(2 + 3 * 7, 1 + 2 * 5, 1 + 2 * 9), m.get(2, 1, 1));
        assert_eq!(m.get(u32::MAX, u32::MAX, u32::MAX), m.get(0, 1, 1));
        let top = BlueNoiseMask {
            width: 1,
            height: 1,
            depth: 1,
            values: vec![u16::MAX],
        };
        assert!(top.get(0, 0, 0) < 1.0);
    }

    #[test]
    fn packed_words_put_even_values_in_the_low_half() {
        let m = small();
        let words = m.packed_words();
        assert_eq!(words.len(), 6);
        for (i, &v) in m.values.iter().enumerate() {
            let word = words[i / 2];
            assert_eq!((word >> ((i as u32 & 1) * 16)) & 0xffff, u32::from(v));
        }
    }

    #[test]
    fn write_then_read_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.bin");
        let m = small();
        m.write(&path).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().len(), HEADER_LEN + 2 * 12);
        assert_eq!(BlueNoiseMask::read(&path).unwrap(), m);
        assert_eq!(
            BlueNoiseMask::from_bytes(&m.to_bytes(), "bytes").unwrap(),
            m
        );
    }

    fn read_bytes(bytes: &[u8]) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.bin");
        std::fs::write(&path, bytes).unwrap();
        let error = BlueNoiseMask::read(&path).unwrap_err().to_string();
        // Decoding from memory must agree with reading the file.
        let from_bytes = BlueNoiseMask::from_bytes(bytes, "x")
            .unwrap_err()
            .to_string();
        assert_eq!(
            error.split_once(": ").unwrap().1,
            from_bytes.split_once(": ").unwrap().1
        );
        assert!(error.contains("bad.bin"), "{error}");
        error
    }

    #[test]
    fn bad_files_are_errors_naming_the_problem() {
        let good = small().to_bytes();

        let error = read_bytes(&good[..good.len() - 1]);
        assert!(
            error.contains("truncated") && error.contains("size mismatch"),
            "{error}"
        );

        let mut long = good.clone();
        long.extend_from_slice(&[0, 0]);
        let error = read_bytes(&long);
        assert!(error.contains("trailing bytes"), "{error}");

        let mut magic = good.clone();
        magic[..4].copy_from_slice(b"PNG\0");
        let error = read_bytes(&magic);
        assert!(error.contains("magic"), "{error}");

        let error = read_bytes(&good[..10]);
        assert!(error.contains("header"), "{error}");

        let error = read_bytes(&[]);
        assert!(error.contains("header"), "{error}");

        // Huge dimensions are refused before anything is allocated.
        let mut huge = good.clone();
        huge[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        let error = read_bytes(&huge);
        assert!(error.contains("bad dimensions"), "{error}");

        let mut zero = good.clone();
        zero[12..16].copy_from_slice(&0u32.to_le_bytes());
        let error = read_bytes(&zero);
        assert!(error.contains("bad dimensions"), "{error}");

        // In range, but 4096^3 values: a size mismatch, not a 128 GiB allocation.
        let mut big = good.clone();
        for i in [4, 8, 12] {
            big[i..i + 4].copy_from_slice(&4096u32.to_le_bytes());
        }
        let error = read_bytes(&big);
        assert!(error.contains("size mismatch"), "{error}");

        let missing = BlueNoiseMask::read("/nonexistent/dir/m.bin").unwrap_err();
        assert!(matches!(missing, NoiseError::Io { .. }), "{missing}");
    }

    #[test]
    fn writing_an_inconsistent_mask_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = small();
        m.values.pop();
        let error = m.write(dir.path().join("m.bin")).unwrap_err();
        assert!(matches!(error, NoiseError::ValueCount { .. }), "{error}");
        m.width = 0;
        let error = m.write(dir.path().join("m.bin")).unwrap_err();
        assert!(matches!(error, NoiseError::BadDimensions { .. }), "{error}");
    }

    #[test]
    fn builtin_mask_has_the_documented_shape() {
        let m = BlueNoiseMask::builtin();
        assert_eq!((m.width, m.height, m.depth), (128, 128, 64));
        assert_eq!(m.values.len(), 128 * 128 * 64);
        assert_eq!(BLTIN_LEN, BUILTIN_BYTES.len());
    }

    const BLTIN_LEN: usize = 16 + 2 * 128 * 128 * 64;
}
