//! Trajectories as text: TUM (`t[s] tx ty tz qx qy qz qw`), as OpenVINS' EuRoC
//! `groundtruth_pose.tum` and every SLAM system's output, Blackbird's `stamped_groundtruth_imu.txt`
//! (which appends `vx vy vz`, 11 columns), and the aiding layouts of [`read_trajectory`].
//!
//! One reader for all of them, on the shared row parser of [`super::table`]:
//! - whitespace separated (TUM) or comma separated (`csv`, `asl` layouts);
//! - `#` comment lines anywhere and blank lines anywhere are skipped; [`read_trajectory`] also
//!   skips a `# ...` comment after a row's fields (hand-written and exported aiding files have
//!   them). [`read_tum`], the ground-truth reader, takes a `#` inside a row as a bad field;
//! - a comma-separated layout may start with a header line of names (no field a number), which is
//!   skipped;
//! - every row has the column count of the first row, which must be one the caller allows: 8
//!   (`t x y z qx qy qz qw`), 11 for [`read_tum`] (with `vx vy vz`), 4 (`t x y z`, positions
//!   only) where [`TrajectoryOptions::positions_only`] allows it;
//! - stamps in seconds are converted to integer ns from their decimal text, never through f64:
//!   `1403636579.763556` is `1403636579763556000` ns exactly; digits past the ninth decimal are
//!   rounded half to even on the digits (`…0000000005` drops to the even ns below, anything past
//!   the half rounds up). The `asl` layout's stamps are integer ns.
//!
//! Errors use the fixed names in [`FIELD_NAMES`] (TUM, `csv`) or [`ASL_POSE_FIELD_NAMES`].
//! Quaternions are x,y,z,w in TUM files, w,x,y,z in `asl` files and always w,x,y,z in the core.

use std::fmt::Write as _;
use std::path::Path;

use super::table::{self, BlankLines, Comments, Delimiter, RowRules, Width};
use super::{write_atomic, ReadOptions};
use crate::error::{ImuError, Result, RowsNeeded, POSE_ROWS};
use crate::so3::{wxyz_to_xyzw, xyzw_to_wxyz};
use crate::types::{GroundTruth, QuatWxyz, Vec3};

/// Field names used in errors, in file column order.
pub const FIELD_NAMES: [&str; 11] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw", "vx", "vy", "vz"];

/// Field names of the `asl` layout (EuRoC/Kalibr pose CSV), in file column order.
pub const ASL_POSE_FIELD_NAMES: [&str; 8] = ["timestamp", "px", "py", "pz", "qw", "qx", "qy", "qz"];

/// Trajectory files: two rows make the shortest span an aiding source can cover.
pub const TRAJECTORY_ROWS: RowsNeeded = RowsNeeded {
    what: "trajectory file",
    unit: "row",
    needed: 2,
    why: "a trajectory spans at least two stamps",
};

/// How a trajectory file is laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrajectoryLayout {
    /// `t tx ty tz qx qy qz qw`, whitespace separated, t in seconds.
    Tum,
    /// The same columns separated by commas.
    Csv,
    /// An ASL CSV (EuRoC/Kalibr): `timestamp [ns], px, py, pz, qw, qx, qy, qz`.
    Asl,
}

impl TrajectoryLayout {
    /// `tum`, `csv` or `asl`.
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim() {
            "tum" => Ok(TrajectoryLayout::Tum),
            "csv" => Ok(TrajectoryLayout::Csv),
            "asl" => Ok(TrajectoryLayout::Asl),
            _ => Err(ImuError::invalid(format!(
                "trajectory layout {s:?}: one of tum, csv, asl"
            ))),
        }
    }

    fn delimiter(self) -> Delimiter {
        match self {
            TrajectoryLayout::Tum => Delimiter::Whitespace,
            TrajectoryLayout::Csv | TrajectoryLayout::Asl => Delimiter::Comma,
        }
    }

    fn names(self) -> &'static [&'static str] {
        match self {
            TrajectoryLayout::Asl => &ASL_POSE_FIELD_NAMES,
            TrajectoryLayout::Tum | TrajectoryLayout::Csv => &FIELD_NAMES,
        }
    }

    /// The quaternion of a row's values (after t) in core order.
    fn quaternion(self, r: &[f64]) -> QuatWxyz {
        match self {
            TrajectoryLayout::Asl => [r[3], r[4], r[5], r[6]],
            TrajectoryLayout::Tum | TrajectoryLayout::Csv => xyzw_to_wxyz([r[3], r[4], r[5], r[6]]),
        }
    }
}

/// What [`read_trajectory`] accepts.
#[derive(Clone, Debug)]
pub struct TrajectoryOptions {
    pub layout: TrajectoryLayout,
    /// Accept rows of 4 columns (`t x y z`: positions only) as well as 8.
    pub positions_only: bool,
    /// As [`ReadOptions::allow_float_timestamps`], for the `asl` layout's ns stamps.
    pub allow_float_timestamps: bool,
}

/// A trajectory as read: stamps, positions, orientations where the file has them, and the
/// 1-based line of each row.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Trajectory {
    pub t_ns: Vec<i64>,
    pub p: Vec<Vec3>,
    /// `None` for a file of positions only (4 columns).
    pub q_wxyz: Option<Vec<QuatWxyz>>,
    pub lines: Vec<usize>,
}

impl Trajectory {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
}

/// The rows of a trajectory file in `layout` with one of the `allowed` column counts (module doc).
fn read_rows(
    path: &Path,
    bytes: &[u8],
    layout: TrajectoryLayout,
    allowed: &[usize],
    comments: Comments,
    allow_float_timestamps: bool,
) -> Result<table::Table> {
    let bytes = table::strip_bom(bytes);
    let delimiter = layout.delimiter();
    let (mut body_start, mut body_line) = (0, 0);
    if delimiter == Delimiter::Comma {
        // A header of names: the first row when none of its fields is a number.
        if let Some((pos, idx, line)) = table::first_row(bytes, comments) {
            let mut spans = Vec::new();
            table::field_spans(line, delimiter, &mut spans);
            if spans.iter().all(|&(a, b)| !table::is_number(&line[a..b])) {
                let end = memchr::memchr(b'\n', &bytes[pos..]).map_or(bytes.len(), |i| pos + i + 1);
                (body_start, body_line) = (end, idx + 1);
            }
        }
    }
    let body = &bytes[body_start..];
    let n_columns = table::pick_column_count(body, delimiter, comments, allowed);
    let names: Vec<String> = (0..n_columns)
        .map(|c| {
            layout
                .names()
                .get(c)
                .map_or_else(|| format!("column {}", c + 1), |s| s.to_string())
        })
        .collect();
    let rules = RowRules {
        delimiter,
        comments,
        blank_lines: BlankLines::Skip,
        width: Width::Exact(n_columns),
        time_col: 0,
        time_digits: if layout == TrajectoryLayout::Asl { 0 } else { 9 },
        float_ns: allow_float_timestamps,
        values: (1..n_columns).collect(),
        trailing_junk: false,
        skip_bad_lines: false,
    };
    let rows = table::parse_rows(path, body, body_line, &rules, &names)?;
    Ok(table::Table {
        path: path.to_path_buf(),
        header: None,
        names,
        n_columns,
        t_ns: rows.t_ns,
        values: rows.values,
        lines: rows.lines,
    })
}

/// Reads a TUM ground-truth file with 8 columns (`v` is `None`) or 11 columns (`v` is `Some`).
pub fn read_tum(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<GroundTruth> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let t = read_rows(
        path,
        &bytes,
        TrajectoryLayout::Tum,
        &[8, 11],
        Comments::Lines,
        opts.allow_float_timestamps,
    )?;
    table::require_rows(&t, &bytes, &POSE_ROWS)?;
    let n = t.len();
    let w = t.n_columns - 1;
    let with_v = t.n_columns == 11;
    let mut p = Vec::with_capacity(n);
    let mut q = Vec::with_capacity(n);
    let mut v = Vec::with_capacity(if with_v { n } else { 0 });
    for r in t.values.chunks_exact(w) {
        p.push([r[0], r[1], r[2]]);
        q.push(xyzw_to_wxyz([r[3], r[4], r[5], r[6]]));
        if with_v {
            v.push([r[7], r[8], r[9]]);
        }
    }
    Ok(GroundTruth {
        t_ns: t.t_ns,
        p,
        q_wxyz: q,
        v: with_v.then_some(v),
        ..GroundTruth::default()
    })
}

/// Reads a trajectory (poses, or positions where `opts.positions_only` allows them) in one of the
/// layouts of [`TrajectoryLayout`] (module doc for the rules). Quaternions are returned as the
/// file has them (not normalised), in w,x,y,z order.
pub fn read_trajectory(path: impl AsRef<Path>, opts: &TrajectoryOptions) -> Result<Trajectory> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let allowed: &[usize] = if opts.positions_only { &[8, 4] } else { &[8] };
    let t = read_rows(
        path,
        &bytes,
        opts.layout,
        allowed,
        Comments::LinesAndTrailing,
        opts.allow_float_timestamps,
    )?;
    table::require_rows(&t, &bytes, &TRAJECTORY_ROWS)?;
    let w = t.n_columns - 1;
    let p = t.values.chunks_exact(w).map(|r| [r[0], r[1], r[2]]).collect();
    let q_wxyz = (t.n_columns == 8).then(|| t.values.chunks_exact(w).map(|r| opts.layout.quaternion(r)).collect());
    Ok(Trajectory {
        t_ns: t.t_ns,
        p,
        q_wxyz,
        lines: t.lines,
    })
}

/// Exact decimal seconds with all 9 ns digits, so that `read_tum` gets the same stamp back.
fn write_seconds(out: &mut String, t_ns: i64) {
    let sign = if t_ns < 0 { "-" } else { "" };
    let m = t_ns.unsigned_abs();
    let _ = write!(out, "{sign}{}.{:09}", m / 1_000_000_000, m % 1_000_000_000);
}

/// Writes a TUM file (8 columns, or 11 with `vx vy vz` when `gt.v` is present; biases have no
/// place in the format and are not written). Floats are written in shortest round-trip form.
pub fn write_tum(path: impl AsRef<Path>, gt: &GroundTruth) -> Result<()> {
    let n = gt.t_ns.len();
    let v_len = gt.v.as_ref().map_or(n, Vec::len);
    if gt.p.len() != n || gt.q_wxyz.len() != n || v_len != n {
        return Err(ImuError::invalid(format!(
            "GroundTruth lengths differ: t_ns {n}, p {}, q_wxyz {}, v {v_len}",
            gt.p.len(),
            gt.q_wxyz.len()
        )));
    }
    super::asl::check_stamps(&gt.t_ns)?;
    let mut out = String::with_capacity(64 + n * 160);
    out.push_str("# timestamp(s) tx ty tz qx qy qz qw");
    if gt.v.is_some() {
        out.push_str(" vx vy vz");
    }
    out.push('\n');
    for i in 0..n {
        let p = gt.p[i];
        let q = wxyz_to_xyzw(gt.q_wxyz[i]);
        let v = gt.v.as_ref().and_then(|v| v.get(i).copied());
        let all = p.iter().chain(q.iter()).chain(v.iter().flatten());
        if let Some(x) = all.clone().find(|x| !x.is_finite()) {
            return Err(ImuError::invalid(format!(
                "ground truth row {i} holds a non-finite value {x}"
            )));
        }
        write_seconds(&mut out, gt.t_ns[i]);
        for x in all {
            let _ = write!(out, " {x}");
        }
        out.push('\n');
    }
    write_atomic(path.as_ref(), out.as_bytes())
}
