//! KAIST Complex Urban dataset (Jeong et al., IJRR 2019): `sensor_data/xsens_imu.csv` and
//! `global_pose.csv`. No sample file was at hand; the layout comes from:
//! - the dataset's format page (https://sites.google.com/view/complex-urban-dataset/format):
//!   sensor CSVs are headerless, comma separated, ROS stamps in integer ns;
//! - ModuSLAM's KAIST Urban IMU handler (fatrybl/ModuSLAM,
//!   `kaist_urban_handler.py`), which takes gyro from columns 7..9 and acceleration from 10..12
//!   (0-based) of xsens_imu.csv: stamp, quaternion x y z w, Euler x y z, gyro x y z,
//!   acceleration x y z, magnetic field x y z (17 columns);
//! - MRPT's loader for MulRan (same lab, same `global_pose.csv` layout), which asserts 13
//!   columns and fills a 3×4 [R|t] row-major from columns 1..12, and a KAIST loader that does
//!   the same (`RT[0,0] = x[1] ... RT[0,3] = x[4]`).
//!
//! Field names in errors are the fixed ones below, since the files have no header.

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

use super::table::{self, Separator, TableSpec, TimeUnit};
use super::ReadOptions;
use crate::error::{ImuError, Result, IMU_ROWS, POSE_ROWS};
use crate::so3::{canonical_wxyz, quat_from_wxyz, quat_to_wxyz};
use crate::types::{GroundTruth, ImuSamples};

pub const XSENS_FIELD_NAMES: [&str; 17] = [
    "timestamp",
    "quat_x",
    "quat_y",
    "quat_z",
    "quat_w",
    "euler_x",
    "euler_y",
    "euler_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "acc_x",
    "acc_y",
    "acc_z",
    "mag_x",
    "mag_y",
    "mag_z",
];

pub const POSE_FIELD_NAMES: [&str; 13] = [
    "timestamp",
    "r11",
    "r12",
    "r13",
    "tx",
    "r21",
    "r22",
    "r23",
    "ty",
    "r31",
    "r32",
    "r33",
    "tz",
];

/// Largest entry of |RᵀR − I| and |det R − 1| accepted as a rotation. The files print ~7
/// significant digits, so a real rotation is off by ~1e-7; 1e-3 still rejects shifted columns
/// or a translation read as a matrix entry.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

fn spec(names: &[&str], opts: &ReadOptions) -> TableSpec {
    TableSpec {
        separator: Separator::Comma,
        columns: vec![names.len()],
        time_unit: TimeUnit::Nanoseconds,
        header_line: false,
        hash_comments: false,
        names: names.iter().map(|s| s.to_string()).collect(),
        allow_float_timestamps: opts.allow_float_timestamps,
    }
}

/// Reads `xsens_imu.csv`: gyro [rad/s] and acceleration [m/s²]; the Xsens orientation, Euler
/// angles and magnetic field are checked like every field but not returned.
pub fn read_xsens_imu(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<ImuSamples> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let t = table::parse_table(path, &bytes, &spec(&XSENS_FIELD_NAMES, opts))?;
    table::require_rows(&t, &bytes, &IMU_ROWS)?;
    let n = t.len();
    let mut gyro = Vec::with_capacity(n);
    let mut acc = Vec::with_capacity(n);
    for r in t.values.chunks_exact(16) {
        gyro.push([r[7], r[8], r[9]]);
        acc.push([r[10], r[11], r[12]]);
    }
    Ok(ImuSamples {
        t_ns: t.t_ns,
        gyro,
        acc,
    })
}

/// Reads `global_pose.csv`: stamp and a 3×4 [R|t] row-major (vehicle → world, t in UTM metres);
/// `v` is `None`. A matrix that is not a rotation within [`ROTATION_TOLERANCE`] is an
/// `InvalidInput` error naming file and line.
pub fn read_global_pose(path: impl AsRef<Path>, opts: &ReadOptions) -> Result<GroundTruth> {
    let path = path.as_ref();
    let bytes = table::read_bytes(path)?;
    let t = table::parse_table(path, &bytes, &spec(&POSE_FIELD_NAMES, opts))?;
    let n = t.len();
    let mut p = Vec::with_capacity(n);
    let mut q = Vec::with_capacity(n);
    for (i, r) in t.values.chunks_exact(12).enumerate() {
        let m = Matrix3::new(r[0], r[1], r[2], r[4], r[5], r[6], r[8], r[9], r[10]);
        let ortho = (m.transpose() * m - Matrix3::identity()).abs().max();
        let det = m.determinant();
        if !(ortho <= ROTATION_TOLERANCE && (det - 1.0).abs() <= ROTATION_TOLERANCE) {
            let line = t.lines.get(i).copied().unwrap_or(0);
            return Err(ImuError::invalid(format!(
                "{}:{line}: the 3x3 part of the pose is not a rotation (max |RᵀR - I| = {ortho:.3e}, \
                 det = {det:.6}; tolerance {ROTATION_TOLERANCE:e})",
                path.display()
            )));
        }
        // The printed matrix is only orthonormal to ~1e-7, so the quaternion from it is
        // renormalised (quat_from_wxyz) rather than trusted to be unit.
        let raw = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
        q.push(canonical_wxyz(quat_to_wxyz(&quat_from_wxyz(quat_to_wxyz(&raw)))));
        p.push([r[3], r[7], r[11]]);
    }
    // After the rotation check, so that a bad matrix is reported as such even in a one-row file.
    table::require_rows(&t, &bytes, &POSE_ROWS)?;
    Ok(GroundTruth {
        t_ns: t.t_ns,
        p,
        q_wxyz: q,
        ..GroundTruth::default()
    })
}
