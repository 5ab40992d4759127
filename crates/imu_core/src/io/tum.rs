//! TUM trajectory text (`t[s] tx ty tz qx qy qz qw`), as OpenVINS' EuRoC `groundtruth_pose.tum`,
//! and Blackbird's `stamped_groundtruth_imu.txt`, which appends `vx vy vz` (11 columns).
//!
//! Whitespace separated, '#' comment lines anywhere, timestamps in decimal seconds. There is no
//! header naming the fields, so errors use the fixed names in [`FIELD_NAMES`]. Quaternions are
//! x,y,z,w in the file and w,x,y,z in the core.

use std::fmt::Write as _;
use std::path::Path;

use super::table::{self, Separator, TableSpec, TimeUnit};
use super::{write_atomic, ReadOptions};
use crate::error::{ImuError, Result, POSE_ROWS};
use crate::so3::{wxyz_to_xyzw, xyzw_to_wxyz};
use crate::types::GroundTruth;

/// Field names used in errors, in file column order.
pub const FIELD_NAMES: [&str; 11] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw", "vx", "vy", "vz"];

/// Reads a TUM file with 8 columns (`v` is `None`) or 11 columns (`v` is `Some`).
pub fn read_tum(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<GroundTruth> {
    let spec = TableSpec {
        separator: Separator::Whitespace,
        columns: vec![8, 11],
        time_unit: TimeUnit::Seconds,
        header_line: false,
        hash_comments: true,
        names: FIELD_NAMES.iter().map(|s| s.to_string()).collect(),
        allow_float_timestamps: opts.allow_float_timestamps,
    };
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let t = table::parse_table(path, &bytes, &spec)?;
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
