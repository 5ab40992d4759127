//! One error type for the whole core. Every variant that comes from a file names the file, the
//! 1-based line and, where there is one, the 1-based column and the field's name from the header,
//! so a user can open the file at the right place. The Python bindings map each variant to its own
//! exception class (see `python/errors.rs`).

use std::fmt;
use std::path::PathBuf;

pub type Result<T, E = ImuError> = std::result::Result<T, E>;

/// Why a timestamp column was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimestampProblem {
    /// The same timestamp as the row before.
    Duplicate,
    /// Earlier than the row before.
    NotIncreasing,
}

impl fmt::Display for TimestampProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TimestampProblem::Duplicate => f.write_str("duplicates the previous row's timestamp"),
            TimestampProblem::NotIncreasing => f.write_str("is earlier than the previous row's timestamp"),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum ImuError {
    #[error("{}: no such file", path.display())]
    NotFound { path: PathBuf },

    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{}:{line}: header {found:?} is not the expected {expected:?}", path.display())]
    Header {
        path: PathBuf,
        line: usize,
        expected: String,
        found: String,
    },

    #[error("{}:{line}: expected {expected} columns, found {found}", path.display())]
    ColumnCount {
        path: PathBuf,
        line: usize,
        expected: usize,
        found: usize,
    },

    #[error("{}:{line}:{column}: field {field:?} = {value:?} is not a number", path.display())]
    NotNumeric {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        value: String,
    },

    #[error("{}:{line}:{column}: field {field:?} = {value:?} is not finite (NaN or inf)", path.display())]
    NonFinite {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        value: String,
    },

    #[error(
        "{}:{line}:{column}: field {field:?} = {value} {problem} ({previous}); \
         timestamps must be strictly increasing",
        path.display()
    )]
    Timestamp {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        value: i64,
        previous: i64,
        problem: TimestampProblem,
    },

    #[error(
        "{}:{line}:{column}: field {field:?} = {value:?} is a timestamp in float notation, which \
         has lost precision (a spreadsheet round trip does this); re-export the file with integer \
         nanoseconds, or read it with allow_float_timestamps=True to accept the rounded stamps",
        path.display()
    )]
    FloatTimestamp {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        value: String,
    },

    /// Ground truth and IMU cannot be put on one time base (no overlap, too few poses, ...).
    #[error("{0}")]
    Alignment(String),

    /// Arrays or settings passed in by the caller are inconsistent (shapes, lengths, ranges).
    #[error("{0}")]
    InvalidInput(String),
}

impl ImuError {
    /// Build an `Io` error, turning "not found" into its own variant.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        let path = path.into();
        if source.kind() == std::io::ErrorKind::NotFound {
            ImuError::NotFound { path }
        } else {
            ImuError::Io { path, source }
        }
    }

    pub fn invalid(msg: impl Into<String>) -> Self {
        ImuError::InvalidInput(msg.into())
    }
}
