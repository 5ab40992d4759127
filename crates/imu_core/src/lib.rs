//! imu_core: the per-sample work of imu-learn, in pure Rust.
//!
//! Data flows one way: `io` (files → `ImuSamples` / `GroundTruth`) → `align` (→ `Sequence`s) →
//! `labels` (Δq/Δβ/Δγ from ground truth) and `batch` (augmented training windows), with
//! `integrate` (Δq/Δβ/Δγ from IMU samples), `covariance` (their covariance under per-sample
//! noise) and `so3` as the shared maths; `allan` characterises a sensor's noise (overlapping Allan
//! deviation and its slope fits); `rotsums` is the per-sample work of the traditional baseline's
//! gyro fit (rotations and Jacobian sums over windows), `offset` the cost of its time offset's
//! search, `filter` the floor's zero-phase low-pass. Nothing here knows Python; the bindings
//! live in `python` behind the `python` feature.

pub mod align;
pub mod allan;
pub mod batch;
pub mod covariance;
pub mod error;
pub mod filter;
pub mod integrate;
pub mod io;
pub mod labels;
pub mod offset;
pub mod par;
pub mod rotsums;
pub mod so3;
pub mod types;

#[cfg(feature = "python")]
mod python;

pub use error::{ImuError, Result};
pub use types::{GroundTruth, ImuSamples, Increment, Labels, QuatWxyz, Sequence, Vec3, GRAVITY};
