//! Errors from reading particle data: every one names the file, the step and what is wrong.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in the data a problem was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// The file being read (a split snapshot's first file).
    pub file: PathBuf,
    /// The step's name where the file alone does not say which step (a `.particles` step file);
    /// `None` otherwise.
    pub step: Option<String>,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(step) = &self.step {
            write!(f, " (step '{step}')")?;
        }
        Ok(())
    }
}

/// What is wrong with the data.
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    /// The file could not be opened or read (the I/O error, quoted in the message).
    // No `#[from]`/`#[source]`: the message includes the I/O error (see DataError).
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    /// The file is shorter than its own header or counts say.
    #[error("file is truncated: {what} needs {needed} bytes but the file has {available}")]
    Truncated {
        /// What needs the bytes ("the u64 particle count", "a 100 x 3 array").
        what: String,
        /// Bytes it needs.
        needed: u64,
        /// Bytes the file has for it.
        available: u64,
    },
    /// A count the file states is more than its size can hold; refused before anything is allocated
    /// from it.
    #[error(
        "{what} count {count} is larger than the file can hold ({size} bytes allow at most {max})"
    )]
    CountTooLarge {
        /// What is counted (points, vertices, ...).
        what: String,
        /// The count the file states.
        count: u64,
        /// The most items of that kind the bytes available can hold.
        max: u64,
        /// The bytes available for them.
        size: u64,
    },
    /// An attribute asked for is not in the data.
    #[error("attribute '{name}' not found; the data has: {available}")]
    MissingAttribute {
        /// The attribute asked for.
        name: String,
        /// The data's attribute names, comma-separated, for the message.
        available: String,
        /// The names the data has, for finding the one meant.
        names: Vec<String>,
    },
    /// The step holds no particles, or none are left once those with a non-finite value are dropped
    /// (the text after "particles" in the message says which).
    #[error("step holds no particles{0}")]
    EmptyStep(String),
    /// The data has no three position coordinates per particle; the message says what it has.
    #[error("wrong dimensionality: {0}")]
    Dimensionality(String),
    /// The format of a file cannot be told from its extension, or the files named are of more than
    /// one format; the message says which.
    #[error("unknown format: {0}")]
    UnknownFormat(String),
    /// The file breaks its format; the message says where and how.
    #[error("{0}")]
    Malformed(String),
}

impl From<std::io::Error> for Problem {
    fn from(e: std::io::Error) -> Problem {
        Problem::Io(e)
    }
}

/// A problem together with where it was found.
#[derive(Debug, thiserror::Error)]
#[error("{location}: {problem}")]
pub struct DataError {
    /// Where the problem was found.
    pub location: Location,
    /// What is wrong.
    // Not a `#[source]`: the message already includes it, and `{:#}` would print it twice.
    pub problem: Problem,
}

impl DataError {
    /// `problem` in `file`; `step` as in [`Location::step`].
    pub fn new(file: impl AsRef<Path>, step: Option<&str>, problem: Problem) -> DataError {
        DataError {
            location: Location {
                file: file.as_ref().to_path_buf(),
                step: step.map(str::to_owned),
            },
            problem,
        }
    }
}

/// Attaches a location to the problems of one step's read.
#[derive(Clone, Copy)]
pub struct At<'a> {
    /// The file being read.
    pub file: &'a Path,
    /// The step's name where the file alone does not say which step (a `.particles` step file);
    /// `None` otherwise.
    pub step: Option<&'a str>,
}

impl<'a> At<'a> {
    /// The location `file`, `step`.
    pub fn new(file: &'a Path, step: Option<&'a str>) -> Self {
        At { file, step }
    }

    /// The location as an owned [`Location`].
    pub fn location(&self) -> Location {
        Location {
            file: self.file.to_path_buf(),
            step: self.step.map(str::to_owned),
        }
    }

    /// `problem` at this location.
    pub fn err(&self, problem: Problem) -> DataError {
        DataError::new(self.file, self.step, problem)
    }

    /// A [`Problem::Malformed`] with `message`, at this location.
    pub fn malformed(&self, message: impl Into<String>) -> DataError {
        self.err(Problem::Malformed(message.into()))
    }

    /// An I/O error at this location: an unexpected end of file becomes a file that ends early
    /// ([`Problem::Malformed`]), any other error [`Problem::Io`].
    pub fn io(&self, e: std::io::Error) -> DataError {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            self.err(Problem::Malformed(
                "file ends early (unexpected end of file)".into(),
            ))
        } else {
            self.err(Problem::Io(e))
        }
    }

    /// Checks that `count` items of at least `bytes_per_item` bytes fit in `available` bytes,
    /// before anything is allocated from `count`.
    pub fn check_count(
        &self,
        what: &str,
        count: u64,
        bytes_per_item: u64,
        available: u64,
    ) -> Result<usize, DataError> {
        let max = available / bytes_per_item.max(1);
        if count > max {
            return Err(self.err(Problem::CountTooLarge {
                what: what.to_owned(),
                count,
                max,
                size: available,
            }));
        }
        usize::try_from(count)
            .map_err(|_| self.malformed(format!("{what} count {count} overflows")))
    }
}
