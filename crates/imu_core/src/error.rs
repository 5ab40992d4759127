//! One error type for the whole core. Every variant that comes from a file names the file, the
//! 1-based line and, where there is one, the 1-based column and the field's name from the header,
//! so a user can open the file at the right place. The Python bindings map each variant to its own
//! exception class (see `python/errors.rs`).

use std::fmt;
use std::path::{Path, PathBuf};

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

/// What a reader needs of a file's rows, for `ImuError::TooFewRows`: "IMU file" / "sample" / 2 /
/// "one sampling interval".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowsNeeded {
    /// The kind of file, as a user calls it.
    pub what: &'static str,
    /// One row, as a user calls it.
    pub unit: &'static str,
    pub needed: usize,
    /// Why that many.
    pub why: &'static str,
}

/// IMU files: one sample holds no interval to integrate or align.
pub const IMU_ROWS: RowsNeeded = RowsNeeded {
    what: "IMU file",
    unit: "sample",
    needed: 2,
    why: "one sampling interval",
};

/// Ground-truth files: interpolation onto IMU stamps needs a pose on each side.
pub const POSE_ROWS: RowsNeeded = RowsNeeded {
    what: "ground-truth file",
    unit: "pose",
    needed: 2,
    why: "one on each side of an IMU stamp to interpolate",
};

fn plural(n: usize, unit: &str) -> String {
    if n == 1 {
        format!("{n} {unit}")
    } else {
        format!("{n} {unit}s")
    }
}

fn too_few_rows_message(path: &Path, line: usize, rows: &RowsNeeded, found: usize) -> String {
    let (p, what, unit) = (path.display(), rows.what, rows.unit);
    let need = format!("at least {} are needed ({})", rows.needed, rows.why);
    match (found, line) {
        (0, 0) => format!("{p}: {what} is empty (no {unit}s); {need}"),
        (0, 1) => format!("{p}: {what} has a header but no {unit}s; {need}"),
        (0, _) => format!("{p}: {what} has no {unit}s (only a header, comments or blank lines); {need}"),
        _ => format!("{p}:{line}: {what} has only {}; {need}", plural(found, unit)),
    }
}

/// Seconds with ms resolution: stamps are epoch ns, and a user compares spans by eye.
fn seconds(ns: i64) -> String {
    format!("{:.3}", ns as f64 * 1e-9)
}

fn no_overlap_message(imu: Option<&Path>, gt: Option<&Path>, imu_span: (i64, i64), gt_span: (i64, i64)) -> String {
    let gt_name = gt.map_or("ground truth".to_string(), |p| format!("ground truth {}", p.display()));
    let imu_name = imu.map_or("the IMU".to_string(), |p| format!("the IMU {}", p.display()));
    let (relation, gap_ns) = if gt_span.1 < imu_span.0 {
        ("ends", imu_span.0 - gt_span.1)
    } else {
        ("starts", gt_span.0 - imu_span.1)
    };
    let when = if relation == "ends" {
        "before the IMU starts"
    } else {
        "after the IMU ends"
    };
    format!(
        "{gt_name} covers {}-{} s, {imu_name} {}-{} s: they never overlap (the ground truth {relation} \
         {} s {when}; are both on the same clock and in the same unit?)",
        seconds(gt_span.0),
        seconds(gt_span.1),
        seconds(imu_span.0),
        seconds(imu_span.1),
        seconds(gap_ns),
    )
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

    /// A row (or the header) ends before a column the caller's column map reads.
    #[error(
        "{}:{line}:{column}: field {field:?} is missing: the line has {found} field(s), the column map \
         reads column {column}",
        path.display()
    )]
    MissingColumn {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        found: usize,
    },

    #[error("{}:{line}:{column}: field {field:?} = {value:?} is not a number{hint}", path.display())]
    NotNumeric {
        path: PathBuf,
        line: usize,
        column: usize,
        field: String,
        value: String,
        /// What the value likely is instead ("" where nothing more can be said).
        hint: &'static str,
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

    /// A file that parses but holds too few data rows to be used: empty, a header alone, only
    /// comments, or fewer rows than `needed` (one IMU sample has no interval; one pose cannot be
    /// interpolated). `line` is the last line read (0 for an empty file).
    #[error("{}", too_few_rows_message(path, *line, rows, *found))]
    TooFewRows {
        path: PathBuf,
        line: usize,
        rows: RowsNeeded,
        found: usize,
    },

    /// The IMU's and the ground truth's time spans are disjoint (another clock or unit, a time
    /// offset, or the file of another recording). Paths are `None` for arrays passed in directly.
    #[error("{}", no_overlap_message(imu.as_deref(), gt.as_deref(), *imu_span_ns, *gt_span_ns))]
    NoOverlap {
        imu: Option<PathBuf>,
        gt: Option<PathBuf>,
        imu_span_ns: (i64, i64),
        gt_span_ns: (i64, i64),
    },

    /// Ground truth and IMU cannot be put on one time base (too few poses, nothing long enough
    /// left after alignment, ...).
    #[error("{0}")]
    Alignment(String),

    /// A unit the caller named is not one the core knows (`what`: "time", "gyro", "acc").
    #[error("unknown {what} unit {value:?}; expected one of {allowed}")]
    UnknownUnit {
        what: &'static str,
        value: String,
        allowed: &'static str,
    },

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
