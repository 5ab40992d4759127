//! Plain data carried between the stages (samples, ground truth, sequences, increments, labels)
//! and the one stamp difference → seconds conversion they share. Rows are `[f64; 3]` / `[f64; 4]`
//! so that a `Vec` of them is one contiguous N×3 (N×4) block that crosses to numpy without a copy.
//!
//! Quaternions are Hamilton, body(IMU) → world, stored w,x,y,z (`q_wxyz`) everywhere in the core.
//! Files that store x,y,z,w (TUM) are converted at the reader/writer through `so3::xyzw_to_wxyz`.

pub type Vec3 = [f64; 3];
pub type QuatWxyz = [f64; 4];

/// Raw IMU samples: gyro [rad/s] and specific force [m/s²] in the IMU frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImuSamples {
    pub t_ns: Vec<i64>,
    pub gyro: Vec<Vec3>,
    pub acc: Vec<Vec3>,
}

impl ImuSamples {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
}

/// Ground-truth poses on their own stamps. `v` is present only where the source gives it
/// (ASL state files, Blackbird); pose-only sources leave it `None` and alignment derives it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GroundTruth {
    pub t_ns: Vec<i64>,
    pub p: Vec<Vec3>,
    pub q_wxyz: Vec<QuatWxyz>,
    pub v: Option<Vec<Vec3>>,
    pub bias_gyro: Option<Vec<Vec3>>,
    pub bias_acc: Option<Vec<Vec3>>,
}

impl GroundTruth {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
}

/// IMU samples with ground truth on the same stamps: the unit every later stage works on.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sequence {
    pub t_ns: Vec<i64>,
    pub gyro: Vec<Vec3>,
    pub acc: Vec<Vec3>,
    pub p: Vec<Vec3>,
    pub v: Vec<Vec3>,
    pub q_wxyz: Vec<QuatWxyz>,
}

impl Sequence {
    pub fn len(&self) -> usize {
        self.t_ns.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }
}

/// One increment between state k and state k + n.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Increment {
    pub dq_wxyz: QuatWxyz,
    pub dv: Vec3,
    pub dp: Vec3,
    pub dt: f64,
}

/// Labels of many windows, row-major: entry `w * horizons.len() + h` is window `w`, horizon `h`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Labels {
    pub starts: Vec<usize>,
    pub horizons: Vec<usize>,
    pub dq_wxyz: Vec<QuatWxyz>,
    pub dv: Vec<Vec3>,
    pub dp: Vec<Vec3>,
    pub dt: Vec<f64>,
}

/// Seconds between two nanosecond stamps. Stamps from arbitrary epochs can be far enough apart
/// to overflow i64; only then is the (slow, software) i128 conversion needed, and it gives the
/// same f64 as the i64 one whenever both exist.
#[inline]
pub(crate) fn seconds_between(t0: i64, t1: i64) -> f64 {
    match t1.checked_sub(t0) {
        Some(d) => d as f64 * 1e-9,
        None => (t1 as i128 - t0 as i128) as f64 * 1e-9,
    }
}

/// Default gravity magnitude [m/s²]; the world frame is z-up, so g = [0, 0, -GRAVITY].
pub const GRAVITY: f64 = 9.81;

pub fn gravity_vector(magnitude: f64) -> Vec3 {
    [0.0, 0.0, -magnitude]
}
