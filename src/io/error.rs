//! Errors from reading particle data: every one names the file, the step and what is wrong.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where in the data a problem was found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    pub file: PathBuf,
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
    // No `#[from]`/`#[source]`: the message includes the I/O error (see DataError).
    #[error("cannot read: {0}")]
    Io(std::io::Error),
    #[error("file is truncated: {what} needs {needed} bytes but the file has {available}")]
    Truncated {
        what: String,
        needed: u64,
        available: u64,
    },
    #[error(
        "{what} count {count} is larger than the file can hold ({size} bytes allow at most {max})"
    )]
    CountTooLarge {
        what: String,
        count: u64,
        max: u64,
        size: u64,
    },
    #[error("attribute '{name}' not found; the data has: {available}")]
    MissingAttribute {
        name: String,
        available: String,
        /// The names the data has, for finding the one meant.
        names: Vec<String>,
    },
    #[error("step holds no particles{0}")]
    EmptyStep(String),
    #[error("wrong dimensionality: {0}")]
    Dimensionality(String),
    #[error("unknown format: {0}")]
    UnknownFormat(String),
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
    pub location: Location,
    // Not a `#[source]`: the message already includes it, and `{:#}` would print it twice.
    pub problem: Problem,
}

impl DataError {
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
    pub file: &'a Path,
    pub step: Option<&'a str>,
}

impl<'a> At<'a> {
    pub fn new(file: &'a Path, step: Option<&'a str>) -> Self {
        At { file, step }
    }

    pub fn location(&self) -> Location {
        Location {
            file: self.file.to_path_buf(),
            step: self.step.map(str::to_owned),
        }
    }

    pub fn err(&self, problem: Problem) -> DataError {
        DataError::new(self.file, self.step, problem)
    }

    pub fn malformed(&self, message: impl Into<String>) -> DataError {
        self.err(Problem::Malformed(message.into()))
    }

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
