//! One reader (and writer where users need one) per file format.
//!
//! Every reader goes through the one row parser of [`table`] (dataset tables, a user's own CSV
//! with its column map, trajectories), so all formats share one set of rules for what a valid
//! file is and one shape of error (file, 1-based line and column, field name). Every writer goes
//! through [`write_atomic`], so an interrupted write never leaves a half-written dataset file
//! where a complete one used to be.

pub mod asl;
pub mod columns;
pub mod kaist;
pub mod table;
pub mod tum;

use std::fs::{self, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{ImuError, Result};

/// Leniencies a reader may grant. The default is strict: every deviation from the format is an
/// error.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Accept nanosecond timestamps written in float notation (`1.40363657975856E+018`, as a
    /// spreadsheet round trip leaves them) instead of failing with `FloatTimestamp`. The stamp is
    /// converted from its decimal text (no detour through f64) and rounded to the nearest ns, ties
    /// to even on the digits. Because such files come out of spreadsheets, this option also drops trailing junk lines a
    /// spreadsheet appends: lines after the last data row whose fields after the first are all
    /// empty (`,,,,,,`, `Step: 0.005 = 1/200,,,,,,`). A junk line followed by a data row is still
    /// an error.
    pub allow_float_timestamps: bool,
}

static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Writes `bytes` to `path` so that readers see either the old file or the complete new one:
/// temp file in the same directory (rename is only atomic within one file system), fsync, rename.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| ImuError::invalid(format!("{}: not a file path", path.display())))?;
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(name);
    tmp_name.push(format!(".tmp.{}.{}", std::process::id(), n));
    let tmp = dir.join(tmp_name);

    let result = (|| -> std::io::Result<()> {
        let mut f = OpenOptions::new().write(true).create_new(true).open(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)
    })();
    if let Err(e) = result {
        let _ = fs::remove_file(&tmp);
        return Err(ImuError::io(path, e));
    }
    // The rename is durable only once the directory entry is; failure here loses nothing that
    // the caller could act on, so it is not reported.
    #[cfg(unix)]
    if let Ok(d) = fs::File::open(&dir) {
        let _ = d.sync_all();
    }
    Ok(())
}
