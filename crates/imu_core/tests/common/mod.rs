//! Shared helpers for the integration tests: comparisons, a synthetic trajectory whose IMU signal
//! is known in closed form, and the real recordings' data root (`have`: a test on a recording the
//! data root lacks says so on stderr, or fails where `IMU_LEARN_REQUIRE_DATA=1`).

#![allow(dead_code)]

use std::io::Write;
use std::path::PathBuf;

use imu_core::so3::{self, angle_between, arr3, quat_from_wxyz, quat_to_wxyz, v3};
use imu_core::types::{gravity_vector, QuatWxyz, Sequence, Vec3};
use nalgebra::{Matrix3, Vector3};

/// Real recordings, outside the repository: the data root `IMU_LEARN_DATA` names (the README's
/// layout), else `../shared/data` beside the checkout.
pub const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data");

/// Set to 1 (CI, which has the data root) and a test whose recording is missing fails instead of
/// skipping.
pub const REQUIRE_DATA: &str = "IMU_LEARN_REQUIRE_DATA";

pub fn data_root() -> PathBuf {
    std::env::var_os("IMU_LEARN_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(DATA))
}

pub fn data(rel: &str) -> PathBuf {
    data_root().join(rel)
}

fn data_required() -> bool {
    std::env::var(REQUIRE_DATA).is_ok_and(|v| !v.is_empty() && v != "0")
}

/// Whether the data root holds `rel`. Where it does not, the test is skipped visibly: with
/// `IMU_LEARN_REQUIRE_DATA=1` this panics (the test fails); otherwise it writes "skipped: <path>
/// missing" to the process's stderr itself (not through `eprintln!`, which the test harness
/// captures and shows only for a failing test) and returns false, for the test to return early.
#[track_caller]
pub fn have(rel: &str) -> bool {
    let p = data(rel);
    if p.exists() {
        return true;
    }
    let msg = format!(
        "{} missing (the data root is IMU_LEARN_DATA, else ../shared/data beside the checkout)",
        p.display()
    );
    if data_required() {
        panic!("{msg}; {REQUIRE_DATA} is set, so a missing recording fails the test");
    }
    let _ = writeln!(
        std::io::stderr(),
        "skipped: {msg}; set {REQUIRE_DATA}=1 to fail instead"
    );
    false
}

pub fn rot_err(a: QuatWxyz, b: QuatWxyz) -> f64 {
    angle_between(&quat_from_wxyz(a), &quat_from_wxyz(b))
}

pub fn vec_err(a: Vec3, b: Vec3) -> f64 {
    (v3(a) - v3(b)).norm()
}

/// Stamps 0, period, 2·period, … with a deterministic jitter of up to ±`jitter_ns`, still strictly
/// increasing as long as jitter_ns < period_ns / 2.
pub fn jittered_stamps(n: usize, period_ns: i64, jitter_ns: i64) -> Vec<i64> {
    (0..n as i64)
        .map(|i| {
            let j = if jitter_ns == 0 {
                0
            } else {
                (i * 7919 + i * i * 104_729) % (2 * jitter_ns + 1) - jitter_ns
            };
            1_000_000 + i * period_ns + j
        })
        .collect()
}

/// A smooth, non-trivial IMU signal (rotation about every axis, time-varying force).
pub fn wiggly_imu(t_ns: &[i64]) -> (Vec<Vec3>, Vec<Vec3>) {
    let gyro = t_ns
        .iter()
        .map(|&t| {
            let s = t as f64 * 1e-9;
            [
                0.9 * (1.7 * s).sin() + 0.2,
                -0.6 * (0.8 * s + 0.4).cos(),
                1.1 * (0.5 * s).sin() - 0.3,
            ]
        })
        .collect();
    let acc = t_ns
        .iter()
        .map(|&t| {
            let s = t as f64 * 1e-9;
            [
                1.5 * (2.1 * s).cos(),
                0.4 + 0.7 * (1.3 * s).sin(),
                9.81 + 0.9 * (0.6 * s).sin(),
            ]
        })
        .collect();
    (gyro, acc)
}

fn rx(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(1.0, 0.0, 0.0, 0.0, c, -s, 0.0, s, c)
}

fn ry(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, 0.0, s, 0.0, 1.0, 0.0, -s, 0.0, c)
}

fn rz(a: f64) -> Matrix3<f64> {
    let (s, c) = a.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

/// Ground truth and the exact IMU signal of a trajectory known in closed form:
///
///   R(t) = Rz(α t) · Rx(b(t)) · Ry(c(t)),  b = 0.5 sin(1.3 t), c = 0.4 sin(0.9 t + 0.3)
///   ω(t) = Cᵀ Bᵀ α ẑ + Cᵀ ḃ x̂ + ċ ŷ        (from Rᵀ Ṙ with A = Rz, B = Rx, C = Ry)
///   p(t) = [2 sin 0.7t, 1.5 cos 0.5t + 0.2 t, 0.3 sin 1.1t + 0.05 t²]
///   a(t) = Rᵀ (p̈ − g)
///
/// Each IMU sample is the signal at its own stamp, which is what a zero-order hold integrates.
pub fn synthetic_sequence(t_ns: &[i64], gravity: f64) -> Sequence {
    let alpha = 0.8;
    let g = v3(gravity_vector(gravity));
    let mut seq = Sequence::default();
    for &tn in t_ns {
        let t = tn as f64 * 1e-9;
        let (b, bd) = (0.5 * (1.3 * t).sin(), 0.5 * 1.3 * (1.3 * t).cos());
        let (c, cd) = (0.4 * (0.9 * t + 0.3).sin(), 0.4 * 0.9 * (0.9 * t + 0.3).cos());
        let (a_m, b_m, c_m) = (rz(alpha * t), rx(b), ry(c));
        let r = a_m * b_m * c_m;
        let w = c_m.transpose() * b_m.transpose() * Vector3::z() * alpha
            + c_m.transpose() * Vector3::x() * bd
            + Vector3::y() * cd;
        let p = Vector3::new(
            2.0 * (0.7 * t).sin(),
            1.5 * (0.5 * t).cos() + 0.2 * t,
            0.3 * (1.1 * t).sin() + 0.05 * t * t,
        );
        let v = Vector3::new(
            1.4 * (0.7 * t).cos(),
            -0.75 * (0.5 * t).sin() + 0.2,
            0.33 * (1.1 * t).cos() + 0.1 * t,
        );
        let pdd = Vector3::new(
            -0.98 * (0.7 * t).sin(),
            -0.375 * (0.5 * t).cos(),
            -0.363 * (1.1 * t).sin() + 0.1,
        );
        let acc = r.transpose() * (pdd - g);
        // Built from the same three elementary rotations, so that q and r agree to round-off.
        let q = so3::exp(&(Vector3::z() * (alpha * t))) * so3::exp(&(Vector3::x() * b)) * so3::exp(&(Vector3::y() * c));
        seq.t_ns.push(tn);
        seq.gyro.push(arr3(&w));
        seq.acc.push(arr3(&acc));
        seq.p.push(arr3(&p));
        seq.v.push(arr3(&v));
        seq.q_wxyz.push(quat_to_wxyz(&q));
    }
    seq
}
