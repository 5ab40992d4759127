#![allow(dead_code)]

use std::path::{Path, PathBuf};

use imu_core::ImuError;

pub const IMU_HEADER: &str = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]";

pub fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// An IMU row with a given stamp.
pub fn imu_row(t: i64) -> String {
    format!("{t},0.1,-0.2,0.3,9.81,0.01,-0.02")
}

/// Header plus `n` good rows, 5 ms apart; row k is on line k + 2.
pub fn imu_lines(n: usize) -> Vec<String> {
    let mut v = vec![IMU_HEADER.to_string()];
    v.extend((0..n).map(|k| imu_row(1_403_636_579_758_560_000 + 5_000_000 * k as i64)));
    v
}

pub fn join(lines: &[String]) -> String {
    let mut s = lines.join("\n");
    s.push('\n');
    s
}

/// The Display message names the file, the 1-based line and (where given) the field.
pub fn assert_message(err: &ImuError, path: &Path, line: usize, field: Option<&str>) {
    let msg = err.to_string();
    let at = format!("{}:{}:", path.display(), line);
    assert!(msg.contains(&at), "{msg:?} does not contain {at:?}");
    if let Some(f) = field {
        assert!(msg.contains(&format!("{f:?}")), "{msg:?} does not name field {f:?}");
    }
}
