//! Binary particle files read through a memory map: a step's bytes are decoded straight from
//! the page cache, without first copying the whole file into a buffer, and the arrays a scene
//! did not ask for are never touched (their pages are never faulted in).
//!
//! The one hazard of a map: a file truncated by another process while it is mapped makes the
//! next access of a vanished page fault (SIGBUS). Files are mapped only for the duration of one
//! step's decode, and simulation outputs are written once and then left alone (writers that
//! rewrite in place should write a new file and rename it, as aarbf's own outputs do).

use std::fs::File;
use std::ops::Deref;

use super::{At, DataError};

/// A read-only view of a whole file.
pub(crate) enum Mapped {
    Map(memmap2::Mmap),
    /// An empty file (mapping zero bytes is an error on some systems).
    Empty,
}

impl Mapped {
    /// Maps the file `at` names.
    pub(crate) fn open(at: At<'_>) -> Result<Mapped, DataError> {
        let file = File::open(at.file).map_err(|e| at.io(e))?;
        let size = super::file_len(at, &file)?;
        if size == 0 {
            return Ok(Mapped::Empty);
        }
        // SAFETY: the map is read-only and lives for one decode; see the module documentation
        // for what a concurrent truncation does.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(|e| at.io(e))?;
        // The decoders read each array once, front to back.
        #[cfg(unix)]
        let _ = map.advise(memmap2::Advice::Sequential);
        Ok(Mapped::Map(map))
    }
}

impl Deref for Mapped {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            Mapped::Map(m) => m,
            Mapped::Empty => &[],
        }
    }
}
