//! One rank's share of a step: records `[r N / P, (r + 1) N / P)` of the N records its file(s)
//! hold, read without reading the rest where the format allows it (`docs/distributed.md`).
//!
//! - `.particles`, `.raw`, `.npy` (C or Fortran order) and binary PLY of scalar properties:
//!   fixed-size records, so the byte range of the part's records (of each column, in Fortran
//!   order) is decoded from the memory map and the rest of the file is never touched;
//! - HDF5 snapshots: a hyperslab of rows of each dataset (read straight from the file where a
//!   dataset is contiguous), over the snapshot's files in order: a part that spans two files
//!   reads the end of one and the start of the next, and files outside it only have their
//!   header read;
//! - CSV: the body's bytes split evenly, each range moved forward to the start of a line (a
//!   record belongs to the part whose byte range holds its first byte); every part parses the
//!   header row and the first record (which decides the numeric columns);
//! - ascii PLY whose vertex element is the last and has scalar properties only: as CSV, the
//!   vertex rows' bytes split the same way, one row a line (a part checks each row holds every
//!   property; the header's count is checked where one process reads the step);
//! - other ascii PLY (a vertex element followed by faces or edges, as meshes are written, or
//!   with list properties): one row a line, the lines before the part's rows counted by their
//!   line breaks (memchr), not parsed, from the body's start (the rows of elements before the
//!   vertex element too); the part parses exactly its rows `range(n)`, list counts and items
//!   included, and a file that ends before them is an error naming the line;
//! - binary PLY with list properties (in the vertex element or in an element before it): the
//!   rows before the part's stepped over by reading only their list counts (scalars and list
//!   items stepped over by their size), then the part's rows decoded;
//! - VTK XML of appended data (raw or base64, uncompressed or compressed: zlib, LZ4 or LZMA)
//!   or of inline base64 arrays (`format="binary"`, likewise), or of both mixed in one file:
//!   the pieces' points in order are
//!   the step's records; of each piece the part's rows, and of each array only their bytes,
//!   base64 groups, or the compressed blocks that overlap them, read and decompressed (an
//!   inline array is stepped over by the length its header gives; a whole step of inline
//!   arrays is vtkio's);
//! - VTK XML of inline ascii arrays and legacy ascii VTK: values are not one record a line, so
//!   a part counts the values (whitespace-separated words, not parsed) from an array's start
//!   to its rows and parses only its own; it scans the bytes before its rows (XML: every
//!   ascii array whole, counting its values to check their number), but its memory is its
//!   rows' (a whole step is vtkio's);
//! - legacy binary VTK: the ascii lines between the binary blocks scanned, each block stepped
//!   over by its size, only the part's rows decoded (a whole step is vtkio's); legacy files,
//!   ascii or binary, of every section VTK writes (COLOR_SCALARS, TENSORS,
//!   TEXTURE_COORDINATES, LOOKUP_TABLE, METADATA blocks, CELL_DATA before or after POINT_DATA)
//!   are read so;
//! - legacy VTK outside the layout VTK writes (`bit` arrays, a POINT_DATA or FIELD count other
//!   than the points', ...), VTK XML of a type name only vtkio knows, or whose base64 holds
//!   whitespace: read whole and sliced, with a warning once per format that says why (vtkio
//!   alone reads them).
//!
//! A part goes through the same checks as a whole step ([`super::finish_step`]'s rule), except
//! that it may be empty: the whole step's records are the parts' records, in rank order.

use std::ops::Range;
use std::sync::atomic::{AtomicU8, Ordering};

use super::{Columns, Format};
use crate::values::{Attribute, Step};

/// Rank `rank` of `ranks`: the part of a step it reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Part {
    /// This rank, `0..ranks`.
    pub rank: usize,
    /// How many ranks share the step (at least 1).
    pub ranks: usize,
}

impl Part {
    /// The whole step: rank 0 of 1.
    pub const WHOLE: Part = Part { rank: 0, ranks: 1 };

    /// Rank `rank` of `ranks`; `ranks` must be at least 1 and `rank` below it.
    pub fn new(rank: usize, ranks: usize) -> Part {
        assert!(rank < ranks, "rank {rank} of {ranks}");
        Part { rank, ranks }
    }

    /// The records `[r N / P, (r + 1) N / P)` of `n`: the one rule of which rank reads which
    /// records (floor division, so that consecutive parts meet and the last ends at `n`).
    pub fn range(self, n: usize) -> Range<usize> {
        let at = |r: usize| (n as u128 * r as u128 / self.ranks as u128) as usize;
        at(self.rank)..at(self.rank + 1)
    }

    /// Whether this is the whole step.
    pub fn is_whole(self) -> bool {
        self.ranks == 1
    }
}

/// One rank's part of a step, and how many records it decoded to get it.
#[derive(Clone, Debug)]
pub struct StepPart {
    /// The part's records that are finite, with the selected attributes (may be empty).
    pub step: Step,
    /// Records decoded from the file: the part's own (CSV and ascii PLY ending in its vertex
    /// rows of scalars: the records whose first byte lies in the part's byte range), or every
    /// record of the step for a format read whole.
    pub decoded: usize,
}

/// A whole step's columns cut to `part` (for a format that cannot read a part alone), with a
/// warning, once per format, that each rank reads the whole step; and the records decoded.
pub(crate) fn read_whole(
    format: Format,
    why: &str,
    columns: Columns,
    part: Part,
) -> (Columns, usize) {
    static WARNED: AtomicU8 = AtomicU8::new(0);
    let bit = 1u8 << (Format::ALL.iter().position(|f| *f == format).unwrap_or(0) as u8);
    if !part.is_whole() && WARNED.fetch_or(bit, Ordering::Relaxed) & bit == 0 {
        tracing::warn!(
            "{format} files are read whole by every rank ({why}): each rank keeps its part, but \
             its memory and read time are the whole step's"
        );
    }
    let decoded = columns.positions.len();
    (slice_columns(columns, part), decoded)
}

/// `part`'s records of a step held whole.
pub fn slice_step(step: &Step, part: Part) -> Step {
    let range = part.range(step.len());
    Step {
        name: step.name.clone(),
        positions: step.positions[range.clone()].to_vec(),
        attributes: step
            .attributes
            .iter()
            .map(|a| Attribute {
                name: a.name.clone(),
                values: a.values[range.clone()].to_vec(),
            })
            .collect(),
    }
}

/// `part`'s records of a reader's columns (attributes of another length are left for the
/// checks to refuse).
pub(crate) fn slice_columns(columns: Columns, part: Part) -> Columns {
    if part.is_whole() {
        return columns;
    }
    let range = part.range(columns.positions.len());
    Columns {
        positions: columns.positions[range.clone()].to_vec(),
        attributes: columns
            .attributes
            .into_iter()
            .map(|a| Attribute {
                values: a.values.get(range.clone()).unwrap_or(&a.values).to_vec(),
                name: a.name,
            })
            .collect(),
        skipped: columns.skipped,
        finite: columns.finite,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_meet_and_cover_every_record_once() {
        for n in [0usize, 1, 2, 7, 1001, 4099] {
            for ranks in (1..=9).chain([16, 1000]) {
                let mut next = 0;
                for rank in 0..ranks {
                    let r = Part::new(rank, ranks).range(n);
                    assert_eq!(r.start, next, "n {n}, rank {rank} of {ranks}");
                    assert!(
                        r.len() <= n.div_ceil(ranks),
                        "n {n}, rank {rank} of {ranks}"
                    );
                    assert!(r.len() + 1 >= n / ranks, "n {n}, rank {rank} of {ranks}");
                    next = r.end;
                }
                assert_eq!(next, n);
            }
        }
        let huge = usize::MAX / 2;
        assert_eq!(Part::new(2, 3).range(huge).end, huge);
    }
}
