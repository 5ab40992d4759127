//! Rotation maths in one place: SO(3) exp/log on unit quaternions, and the single tested pair of
//! functions that convert between quaternion orders at file boundaries.
//!
//! Convention: Hamilton quaternions, stored w,x,y,z (`QuatWxyz`) in the core.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

use crate::types::{QuatWxyz, Vec3};

pub type Quat = UnitQuaternion<f64>;

/// x,y,z,w (TUM, ROS, scipy) → w,x,y,z (core, ASL CSV, GTSAM).
#[inline]
pub fn xyzw_to_wxyz(q: [f64; 4]) -> QuatWxyz {
    [q[3], q[0], q[1], q[2]]
}

/// w,x,y,z → x,y,z,w.
#[inline]
pub fn wxyz_to_xyzw(q: QuatWxyz) -> [f64; 4] {
    [q[1], q[2], q[3], q[0]]
}

/// Array → unit quaternion, normalising (files carry 6–9 digits, so norms are off by ~1e-6).
#[inline]
pub fn quat_from_wxyz(q: QuatWxyz) -> Quat {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

#[inline]
pub fn quat_to_wxyz(q: &Quat) -> QuatWxyz {
    let c = q.quaternion().coords; // nalgebra stores i, j, k, w
    [c[3], c[0], c[1], c[2]]
}

/// Same rotation with w ≥ 0, so that equal rotations compare equal element-wise.
#[inline]
pub fn canonical_wxyz(q: QuatWxyz) -> QuatWxyz {
    if q[0] < 0.0 {
        [-q[0], -q[1], -q[2], -q[3]]
    } else {
        q
    }
}

#[inline]
pub fn v3(a: Vec3) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

#[inline]
pub fn arr3(v: &Vector3<f64>) -> Vec3 {
    [v[0], v[1], v[2]]
}

/// Exponential map so(3) → SO(3), exact for every angle (see `exp_wxyz`: a Taylor series below
/// θ = 0.1 rad, which is every IMU step in practice, so no libm call per sample).
#[inline]
pub fn exp(phi: &Vector3<f64>) -> Quat {
    let q = exp_wxyz([phi[0], phi[1], phi[2]]);
    UnitQuaternion::new_unchecked(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// `exp` on plain arrays: rotation vector → unit quaternion w,x,y,z (the integration's hot path).
#[inline(always)]
pub fn exp_wxyz(phi: Vec3) -> QuatWxyz {
    let theta2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2];
    let (s, c) = if exp_series_holds(theta2) {
        exp_series(theta2)
    } else {
        let theta = theta2.sqrt();
        ((0.5 * theta).sin() / theta, (0.5 * theta).cos())
    };
    [c, s * phi[0], s * phi[1], s * phi[2]]
}

/// Where `exp_series` is exact to double precision: θ² < 0.01 (θ < 0.1 rad; 20 rad/s for 5 ms).
#[inline(always)]
pub fn exp_series_holds(theta2: f64) -> bool {
    theta2 < 1e-2
}

/// (sin(θ/2)/θ, cos(θ/2)) from θ² by their Taylor series, valid where `exp_series_holds`.
///
/// x = θ/2, y = x² = θ²/4: sin(x)/x = Σ (−y)^k/(2k+1)!, cos x = Σ (−y)^k/(2k)!, k ≤ 5 (the next
/// terms are below 1e-25 relative), by Horner with the coefficients as constants (dividing by
/// 6, 20, ... instead cost ten divisions per IMU step, most of an integration's time).
#[inline(always)]
pub fn exp_series(theta2: f64) -> (f64, f64) {
    const SINC: [f64; 6] = [
        1.0,
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5040.0,
        1.0 / 362880.0,
        -1.0 / 39916800.0,
    ];
    const COS: [f64; 6] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40320.0,
        -1.0 / 3628800.0,
    ];
    let y = 0.25 * theta2;
    let sinc = SINC[0] + y * (SINC[1] + y * (SINC[2] + y * (SINC[3] + y * (SINC[4] + y * SINC[5]))));
    let cos = COS[0] + y * (COS[1] + y * (COS[2] + y * (COS[3] + y * (COS[4] + y * COS[5]))));
    (0.5 * sinc, cos)
}

/// Coefficients (c1, c2) of SO(3)'s right Jacobian J_r(φ) = I − c1 [φ]× + c2 [φ]×² at θ² = |φ|²:
/// c1 = (1 − cos θ)/θ², c2 = (θ − sin θ)/θ³. Where `exp_series_holds` they are their Taylor
/// series in θ² (k ≤ 5, exact to double precision there; the closed forms lose digits to
/// cancellation as θ → 0).
#[inline(always)]
pub(crate) fn right_jacobian_coefficients(theta2: f64) -> (f64, f64) {
    const C1: [f64; 6] = [
        1.0 / 2.0,
        -1.0 / 24.0,
        1.0 / 720.0,
        -1.0 / 40320.0,
        1.0 / 3628800.0,
        -1.0 / 479001600.0,
    ];
    const C2: [f64; 6] = [
        1.0 / 6.0,
        -1.0 / 120.0,
        1.0 / 5040.0,
        -1.0 / 362880.0,
        1.0 / 39916800.0,
        -1.0 / 6227020800.0,
    ];
    if exp_series_holds(theta2) {
        let y = theta2;
        (
            C1[0] + y * (C1[1] + y * (C1[2] + y * (C1[3] + y * (C1[4] + y * C1[5])))),
            C2[0] + y * (C2[1] + y * (C2[2] + y * (C2[3] + y * (C2[4] + y * C2[5])))),
        )
    } else {
        let t = theta2.sqrt();
        ((1.0 - t.cos()) / theta2, (t - t.sin()) / (theta2 * t))
    }
}

/// Hamilton product a ⊗ b of quaternions stored w,x,y,z. Written out (not nalgebra's) so that the
/// hot loops are plain arithmetic on arrays, and so that every path (stamps, hold times, windows)
/// shares the exact same operations and gives bit-identical results. Each component's four
/// products are summed as a pair of pairs: the running rotation is a chain of these products,
/// and two additions deep instead of three shortens every link (any grouping rounds alike).
#[inline(always)]
pub(crate) fn qmul(a: QuatWxyz, b: QuatWxyz) -> QuatWxyz {
    [
        (a[0] * b[0] - a[1] * b[1]) - (a[2] * b[2] + a[3] * b[3]),
        (a[0] * b[1] + a[1] * b[0]) + (a[2] * b[3] - a[3] * b[2]),
        (a[0] * b[2] - a[1] * b[3]) + (a[2] * b[0] + a[3] * b[1]),
        (a[0] * b[3] + a[1] * b[2]) - (a[2] * b[1] - a[3] * b[0]),
    ]
}

/// Rotation matrix (row-major) of a unit quaternion w,x,y,z, not renormalised.
#[inline(always)]
pub(crate) fn rotation_matrix_wxyz(q: QuatWxyz) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    let (xx, yy, zz, xy, xz, yz) = (x * x, y * y, z * z, x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
}

/// Logarithm SO(3) → so(3), the rotation vector with angle in [0, π].
#[inline]
pub fn log(q: &Quat) -> Vector3<f64> {
    let qq = q.quaternion();
    let (w, xyz) = if qq.w < 0.0 {
        (-qq.w, -qq.imag())
    } else {
        (qq.w, qq.imag())
    };
    let n = xyz.norm();
    if n < 1e-8 {
        // θ = 2 atan2(n, w) ≈ 2n/w (1 − n²/(3w²)); the factor θ/n follows.
        return xyz * (2.0 / w) * (1.0 - n * n / (3.0 * w * w));
    }
    let theta = 2.0 * n.atan2(w);
    xyz * (theta / n)
}

/// Spherical linear interpolation from `a` (s = 0) to `b` (s = 1) along the shorter arc.
#[inline]
pub fn slerp(a: &Quat, b: &Quat, s: f64) -> Quat {
    let d = a.inverse() * b;
    a * exp(&(log(&d) * s))
}

/// Angle [rad] of the rotation between two quaternions.
#[inline]
pub fn angle_between(a: &Quat, b: &Quat) -> f64 {
    log(&(a.inverse() * b)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_conversions_round_trip_and_put_w_where_named() {
        let xyzw = [0.1, 0.2, 0.3, 0.9];
        let wxyz = xyzw_to_wxyz(xyzw);
        assert_eq!(wxyz, [0.9, 0.1, 0.2, 0.3]);
        assert_eq!(wxyz_to_xyzw(wxyz), xyzw);
        let q = quat_from_wxyz([1.0, 0.0, 0.0, 0.0]);
        assert_eq!(quat_to_wxyz(&q), [1.0, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn exp_of_rotation_about_z_matches_closed_form() {
        let a: f64 = 0.7;
        let q = exp(&Vector3::new(0.0, 0.0, a));
        let w = quat_to_wxyz(&q);
        assert!((w[0] - (a / 2.0).cos()).abs() < 1e-15);
        assert!((w[3] - (a / 2.0).sin()).abs() < 1e-15);
    }

    #[test]
    fn exp_series_branch_matches_sin_and_cos_to_round_off() {
        // Angles on both sides of the series/libm switch at θ = 0.1, on an off-axis direction.
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        for &theta in &[1e-9, 1e-5, 1e-3, 0.01, 0.05, 0.0999, 0.1001, 0.3] {
            let w = quat_to_wxyz(&exp(&(axis * theta)));
            let (s, c) = (0.5 * theta).sin_cos();
            assert!((w[0] - c).abs() <= 4e-16, "cos at {theta}: {} vs {c}", w[0]);
            for k in 0..3 {
                let want = s * axis[k];
                assert!(
                    (w[k + 1] - want).abs() <= 4e-16,
                    "axis {k} at {theta}: {} vs {want}",
                    w[k + 1]
                );
            }
        }
    }

    #[test]
    fn log_inverts_exp_for_small_medium_and_near_pi_angles() {
        for &scale in &[1e-12, 1e-7, 1e-4 * 0.99, 1e-3, 0.5, 2.0, 3.1] {
            let phi = Vector3::new(0.3, -0.5, 0.8).normalize() * scale;
            let back = log(&exp(&phi));
            assert!((back - phi).norm() <= 1e-14 * scale.max(1.0), "scale {scale}");
        }
    }

    #[test]
    fn slerp_hits_ends_and_midpoint() {
        let a = exp(&Vector3::new(0.1, 0.0, 0.0));
        let b = exp(&Vector3::new(0.1, 0.0, 1.0));
        assert!(angle_between(&slerp(&a, &b, 0.0), &a) < 1e-14);
        assert!(angle_between(&slerp(&a, &b, 1.0), &b) < 1e-14);
        let m = slerp(&a, &b, 0.5);
        assert!((angle_between(&a, &m) - angle_between(&m, &b)).abs() < 1e-14);
    }
}
