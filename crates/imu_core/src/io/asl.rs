//! ASL CSV (EuRoC MAV, TUM-VI): `mav0/imu0/data.csv`, `state_groundtruth_estimate0/data.csv`
//! (and the 20 Hz `groundtruth_state_*.csv` spelling of it), TUM-VI `mav0/mocap0/data.csv`.
//!
//! Comma separated, integer ns timestamps, one header line. Headers are compared by name only:
//! '#', units in brackets and whitespace are ignored, so `#timestamp [ns]` and `# timestamp`
//! match, while a file with its columns in another order does not.

use std::fmt::Write as _;
use std::io::BufRead;
use std::path::Path;

use super::table::{self, Separator, Table, TableSpec, TimeUnit};
use super::{write_atomic, ReadOptions};
use crate::error::{ImuError, Result, RowsNeeded, IMU_ROWS, POSE_ROWS};
use crate::types::{GroundTruth, ImuSamples, Vec3};

/// The EuRoC imu0 header; written when `write_imu` gets no header.
pub const IMU_HEADER: &str = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],\
w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";

/// The official EuRoC `state_groundtruth_estimate0` header.
pub const STATE_HEADER: &str = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], \
q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], \
v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], \
b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], b_a_RS_S_z [m s^-2]";

/// The short spelling of the same 17 columns (OpenVINS' `groundtruth_state_*.csv`).
pub const STATE_HEADER_SHORT: &str = "#time(ns),px,py,pz,qw,qx,qy,qz,vx,vy,vz,bwx,bwy,bwz,bax,bay,baz";

/// TUM-VI `mav0/mocap0/data.csv`.
pub const POSE_HEADER: &str = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],\
q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []";

/// EuRoC `mav0/leica0/data.csv`: the position of a tracked prism, no orientation.
pub const POSITION_HEADER: &str = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]";

fn normalize_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut depth = 0usize;
    for c in name.chars() {
        match c {
            '[' => depth += 1,
            ']' => depth = depth.saturating_sub(1),
            '#' => {}
            c if c.is_whitespace() => {}
            c if depth == 0 => out.push(c),
            _ => {}
        }
    }
    out
}

fn header_matches(found: &str, expected: &str) -> bool {
    let f = found.split(',').map(normalize_name);
    let e = expected.split(',').map(normalize_name);
    f.eq(e)
}

fn check_header(path: &Path, found: &str, accepted: &[&str]) -> Result<()> {
    if accepted.iter().any(|e| header_matches(found, e)) {
        return Ok(());
    }
    Err(ImuError::Header {
        path: path.to_path_buf(),
        line: 1,
        expected: accepted.join("  or  "),
        found: found.to_string(),
    })
}

/// Reads an ASL file: header checked, rows parsed, and, where `rows` says what they are for, at
/// least as many rows as that needs (an empty file is reported as such, not as a bad header).
fn read_checked(
    path: &Path,
    accepted: &[&str],
    n_columns: usize,
    opts: &ReadOptions,
    rows: Option<&RowsNeeded>,
) -> Result<Table> {
    let bytes = table::read_bytes(path)?;
    let empty = Table {
        path: path.to_path_buf(),
        ..Table::default()
    };
    if let Some(rows) = rows {
        if bytes.iter().all(u8::is_ascii_whitespace) {
            table::require_rows(&empty, &bytes, rows)?;
        }
    }
    check_header(path, &table::first_line(&bytes), accepted)?;
    let spec = TableSpec {
        separator: Separator::Comma,
        columns: vec![n_columns],
        time_unit: TimeUnit::Nanoseconds,
        header_line: true,
        hash_comments: false,
        names: Vec::new(),
        allow_float_timestamps: opts.allow_float_timestamps,
    };
    let t = table::parse_table(path, &bytes, &spec)?;
    if let Some(rows) = rows {
        table::require_rows(&t, &bytes, rows)?;
    }
    Ok(t)
}

fn v3(r: &[f64], at: usize) -> Vec3 {
    [r[at], r[at + 1], r[at + 2]]
}

/// Reads an ASL IMU file (`#timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]`).
pub fn read_imu(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<ImuSamples> {
    let t = read_checked(path.as_ref(), &[IMU_HEADER], 7, opts, Some(&IMU_ROWS))?;
    let n = t.len();
    let mut gyro = Vec::with_capacity(n);
    let mut acc = Vec::with_capacity(n);
    for r in t.values.chunks_exact(6) {
        gyro.push(v3(r, 0));
        acc.push(v3(r, 3));
    }
    Ok(ImuSamples {
        t_ns: t.t_ns,
        gyro,
        acc,
    })
}

/// The header line of an ASL IMU file exactly as written (without line ending), after checking
/// it, so that `write_imu` can reproduce it.
pub fn read_imu_header(path: impl AsRef<Path>) -> Result<String> {
    let path = path.as_ref();
    let f = std::fs::File::open(path).map_err(|e| ImuError::io(path, e))?;
    let mut line = Vec::new();
    std::io::BufReader::new(f)
        .read_until(b'\n', &mut line)
        .map_err(|e| ImuError::io(path, e))?;
    let header = table::first_line(&line);
    check_header(path, &header, &[IMU_HEADER])?;
    Ok(header)
}

fn check_finite(what: &str, i: usize, xs: &[f64]) -> Result<()> {
    if xs.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(ImuError::invalid(format!("{what}[{i}] = {xs:?} is not finite")))
    }
}

/// Rejects what the readers would reject, so that every written file reads back.
pub(crate) fn check_stamps(t_ns: &[i64]) -> Result<()> {
    for (i, w) in t_ns.windows(2).enumerate() {
        if w[1] <= w[0] {
            return Err(ImuError::invalid(format!(
                "t_ns[{}] = {} is not after t_ns[{}] = {}; timestamps must be strictly increasing",
                i + 1,
                w[1],
                i,
                w[0]
            )));
        }
    }
    Ok(())
}

/// Writes an ASL IMU file: integer ns, floats in shortest round-trip form (they read back
/// bit-for-bit). `header` defaults to [`IMU_HEADER`]; a given one must be a valid IMU header.
pub fn write_imu(path: impl AsRef<Path>, samples: &ImuSamples, header: Option<&str>) -> Result<()> {
    write_imu_lines(path, samples, header, false)
}

/// [`write_imu`] with every line ended by `\r\n` where `crlf` (the EuRoC zips' own line ends, kept
/// where a refined copy replaces such a file).
pub fn write_imu_lines(path: impl AsRef<Path>, samples: &ImuSamples, header: Option<&str>, crlf: bool) -> Result<()> {
    let path = path.as_ref();
    let end = if crlf { "\r\n" } else { "\n" };
    let header = header.unwrap_or(IMU_HEADER);
    if header.contains(['\n', '\r']) || !header_matches(header, IMU_HEADER) {
        return Err(ImuError::invalid(format!(
            "header {header:?} is not an ASL IMU header like {IMU_HEADER:?}"
        )));
    }
    let n = samples.t_ns.len();
    if samples.gyro.len() != n || samples.acc.len() != n {
        return Err(ImuError::invalid(format!(
            "ImuSamples lengths differ: t_ns {n}, gyro {}, acc {}",
            samples.gyro.len(),
            samples.acc.len()
        )));
    }
    check_stamps(&samples.t_ns)?;
    let mut out = String::with_capacity(header.len() + 1 + n * 128);
    out.push_str(header);
    out.push_str(end);
    for i in 0..n {
        let (g, a) = (samples.gyro[i], samples.acc[i]);
        check_finite("gyro", i, &g)?;
        check_finite("acc", i, &a)?;
        // Writing to a String cannot fail.
        let _ = write!(
            out,
            "{},{},{},{},{},{},{}{end}",
            samples.t_ns[i], g[0], g[1], g[2], a[0], a[1], a[2]
        );
    }
    write_atomic(path, out.as_bytes())
}

/// Reads an ASL state file: t, p, q_wxyz, v, gyro bias, accel bias (17 columns). Accepts the
/// official header and the short `#time(ns),px,py,pz,qw,...` spelling.
pub fn read_state(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<GroundTruth> {
    let t = read_checked(
        path.as_ref(),
        &[STATE_HEADER, STATE_HEADER_SHORT],
        17,
        opts,
        Some(&POSE_ROWS),
    )?;
    let n = t.len();
    let mut gt = GroundTruth {
        p: Vec::with_capacity(n),
        q_wxyz: Vec::with_capacity(n),
        ..GroundTruth::default()
    };
    let (mut v, mut bg, mut ba) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for r in t.values.chunks_exact(16) {
        gt.p.push(v3(r, 0));
        gt.q_wxyz.push([r[3], r[4], r[5], r[6]]);
        v.push(v3(r, 7));
        bg.push(v3(r, 10));
        ba.push(v3(r, 13));
    }
    gt.t_ns = t.t_ns;
    gt.v = Some(v);
    gt.bias_gyro = Some(bg);
    gt.bias_acc = Some(ba);
    Ok(gt)
}

/// Reads a TUM-VI mocap pose file: t, p, q_wxyz (8 columns); `v` is `None`.
pub fn read_pose(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<GroundTruth> {
    let t = read_checked(path.as_ref(), &[POSE_HEADER], 8, opts, Some(&POSE_ROWS))?;
    let n = t.len();
    let mut p = Vec::with_capacity(n);
    let mut q = Vec::with_capacity(n);
    for r in t.values.chunks_exact(7) {
        p.push(v3(r, 0));
        q.push([r[3], r[4], r[5], r[6]]);
    }
    Ok(GroundTruth {
        t_ns: t.t_ns,
        p,
        q_wxyz: q,
        ..GroundTruth::default()
    })
}

/// Reads an ASL position file (EuRoC's Leica laser tracker, `mav0/leica0/data.csv`): t and p
/// (4 columns), with the same strict parsing as every ASL file.
pub fn read_position(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<(Vec<i64>, Vec<Vec3>)> {
    let t = read_checked(path.as_ref(), &[POSITION_HEADER], 4, opts, None)?;
    let p = t.values.chunks_exact(3).map(|r| v3(r, 0)).collect();
    Ok((t.t_ns, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_file_reads_and_names_the_bad_cell() {
        let dir = std::env::temp_dir().join(format!("imu_core_leica_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let good = dir.join("good.csv");
        std::fs::write(
            &good,
            format!("{POSITION_HEADER}\n1000,1.0,2.0,3.0\n2000,1.5,2.5,3.5\n"),
        )
        .unwrap();
        let (t, p) = read_position(&good, &ReadOptions::default()).unwrap();
        assert_eq!(t, vec![1000, 2000]);
        assert_eq!(p[1], [1.5, 2.5, 3.5]);
        let bad = dir.join("bad.csv");
        std::fs::write(&bad, format!("{POSITION_HEADER}\n1000,1.0,2.0,3.0\n2000,1.5,x,3.5\n")).unwrap();
        let msg = read_position(&bad, &ReadOptions::default()).unwrap_err().to_string();
        assert!(msg.contains("bad.csv:3:3") && msg.contains("p_RS_R_y"), "{msg}");
        let wrong = dir.join("imu.csv");
        std::fs::write(&wrong, format!("{IMU_HEADER}\n1000,1,2,3,4,5,6\n")).unwrap();
        assert!(matches!(
            read_position(&wrong, &ReadOptions::default()),
            Err(ImuError::Header { .. })
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn header_comparison_ignores_units_hash_and_spaces() {
        assert!(header_matches(
            "# timestamp,w_RS_S_x,w_RS_S_y,w_RS_S_z,a_RS_S_x,a_RS_S_y,a_RS_S_z",
            IMU_HEADER
        ));
        assert!(!header_matches(
            "#timestamp [ns],a_RS_S_x,a_RS_S_y,a_RS_S_z,w_RS_S_x,w_RS_S_y,w_RS_S_z",
            IMU_HEADER
        ));
        assert!(header_matches(STATE_HEADER_SHORT, STATE_HEADER_SHORT));
        assert!(!header_matches(STATE_HEADER_SHORT, STATE_HEADER));
    }
}
