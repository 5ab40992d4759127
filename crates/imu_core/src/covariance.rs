//! Covariance of the preintegrated increments under per-sample white IMU noise: the closed form of
//! `python/imu_learn/torch_covariance.py` (derivation there), in f64 for inference.
//!
//! Noise model: sample i's error is zero-mean white noise with the *discrete-time* per-axis
//! variances `var[i] = (σ²_gx, σ²_gy, σ²_gz, σ²_ax, σ²_ay, σ²_az)` in (rad/s)² and (m/s²)². Error
//! state (δθ, δβ, δγ), rows in that order, all in the frame at the start of the integration: the
//! true rotation increment is Exp(δθ)·Δq̂ (left perturbation), Δβ = Δβ̂ + δβ, Δγ = Δγ̂ + δγ.
//!
//! To first order sample k's noise moves the state after h samples by E_h F_k n_k, so
//!
//!   Σ_h = E_h (Σ_{k<h} F_k Q_k F_kᵀ) E_hᵀ
//!
//! with F_k built from the states just before and after sample k and E_h from the state at h:
//! one running sum of 9×9 matrices gives every horizon. The states are those of
//! `integrate::integrate_from` (the arithmetic of `preintegrate`), walked here rather than
//! recomputed. Conventions are `preintegrate`'s: stamps `t_ns` [ns], sample i held over
//! [t_i, t_{i+1}), so horizon n (row n) covers [t_0, t_n] with samples 0..n-1 and the last sample
//! enters no horizon (it and its variance are still validated).

use nalgebra::{Matrix3, SMatrix, Vector3};

use crate::error::{ImuError, Result};
use crate::integrate::{check_imu, integrate_from};
use crate::so3::{right_jacobian_coefficients, rotation_matrix_wxyz, v3};
use crate::types::{seconds_between, Increment, QuatWxyz, Vec3};

/// Per-sample discrete-time variances: gyro x, y, z [(rad/s)²], then acc x, y, z [(m/s²)²].
pub type Var6 = [f64; 6];

/// A 9×9 covariance of (δθ, δβ, δγ), row-major (a `Vec` of them is one (M, 9, 9) block).
pub type Cov9 = [[f64; 9]; 9];

type M9 = SMatrix<f64, 9, 9>;
type M93 = SMatrix<f64, 9, 3>;

/// Covariance after integrating from sample 0 over each of `horizons` intervals: entry h is the
/// covariance of row `horizons[h]` of `preintegrate(t_ns, gyro, acc)` (horizon 0 is zero).
/// Horizons may come in any order and repeat; each must be at most `t_ns.len() - 1`.
pub fn increment_covariance(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    var: &[Var6],
    horizons: &[usize],
) -> Result<Vec<Cov9>> {
    check_inputs(t_ns, gyro, acc, var)?;
    let n = t_ns.len();
    if let Some(&bad) = horizons.iter().find(|&&h| h >= n) {
        return Err(ImuError::invalid(format!(
            "horizon {bad} is past the last stamp: {n} stamps allow horizons up to {}",
            n.saturating_sub(1)
        )));
    }
    let Some(&max_h) = horizons.iter().max() else {
        return Ok(Vec::new());
    };
    // Horizon indices for each row 0..=max_h that is asked for (several may share a row).
    let mut wanted: Vec<Vec<usize>> = vec![Vec::new(); max_h + 1];
    for (h, &j) in horizons.iter().enumerate() {
        wanted[j].push(h);
    }
    let mut out = vec![[[0.0; 9]; 9]; horizons.len()];
    propagate(t_ns, gyro, acc, var, 0, max_h, |j, s| {
        if let Some((&first, rest)) = wanted[j].split_first() {
            out[first] = s.covariance();
            for &h in rest {
                out[h] = out[first];
            }
        }
    });
    Ok(out)
}

/// For sample indices `boundaries` b_0 < b_1 < … (each below `t_ns.len()`), the covariance of
/// every interval [t_{b_i}, t_{b_{i+1}}] integrated from its own start (samples b_i..b_{i+1}-1):
/// what one preintegrated factor between keyframes b_i and b_{i+1} carries. Fewer than two
/// boundaries give no intervals.
pub fn interval_covariances(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    var: &[Var6],
    boundaries: &[usize],
) -> Result<Vec<Cov9>> {
    check_inputs(t_ns, gyro, acc, var)?;
    let n = t_ns.len();
    if let Some(&bad) = boundaries.iter().find(|&&b| b >= n) {
        return Err(ImuError::invalid(format!(
            "boundary {bad} is not a sample index of the {n} stamps"
        )));
    }
    if let Some(i) = boundaries.windows(2).position(|w| w[1] <= w[0]) {
        return Err(ImuError::invalid(format!(
            "boundaries[{}] = {} is not after boundaries[{i}] = {}; boundaries must be strictly increasing",
            i + 1,
            boundaries[i + 1],
            boundaries[i]
        )));
    }
    let mut out = Vec::with_capacity(boundaries.len().saturating_sub(1));
    for w in boundaries.windows(2) {
        let (k, len) = (w[0], w[1] - w[0]);
        let mut cov = [[0.0; 9]; 9];
        propagate(t_ns, gyro, acc, var, k, len, |j, s| {
            if j == len {
                cov = s.covariance();
            }
        });
        out.push(cov);
    }
    Ok(out)
}

fn check_inputs(t_ns: &[i64], gyro: &[Vec3], acc: &[Vec3], var: &[Var6]) -> Result<()> {
    check_imu(t_ns, gyro, acc)?;
    if var.len() != t_ns.len() {
        return Err(ImuError::invalid(format!(
            "var has {} rows but t_ns has {}; they must be equal",
            var.len(),
            t_ns.len()
        )));
    }
    for (i, row) in var.iter().enumerate() {
        if let Some(c) = row.iter().position(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(ImuError::invalid(format!(
                "var[{i}][{c}] = {} is not a finite non-negative variance",
                row[c]
            )));
        }
    }
    Ok(())
}

/// The running sum Σ_{k<h} F_k Q_k F_kᵀ and the state after h samples, which E_h needs.
struct Propagation {
    sum: M9,
    v: Vector3<f64>,
    p: Vector3<f64>,
    /// Time since the start of the integration [s].
    t: f64,
}

impl Propagation {
    /// Σ_h = E_h · sum · E_hᵀ, E_h = [[I, 0, 0], [−[v]×, I, 0], [−[p]×, t·I, I]], made exactly
    /// symmetric, row-major.
    fn covariance(&self) -> Cov9 {
        let mut e = M9::identity();
        e.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-self.v.cross_matrix()));
        e.fixed_view_mut::<3, 3>(6, 0).copy_from(&(-self.p.cross_matrix()));
        e.fixed_view_mut::<3, 3>(6, 3)
            .copy_from(&(Matrix3::identity() * self.t));
        let s = e * self.sum * e.transpose();
        std::array::from_fn(|r| std::array::from_fn(|c| 0.5 * (s[(r, c)] + s[(c, r)])))
    }

    /// Adds F_k Q_k F_kᵀ of sample k held for `dt`, with rotations `before` (R_k) and `after`
    /// (R_{k+1}); `self.v`, `self.p`, `self.t` already hold the state after the sample.
    ///
    ///   F_k (gyro) = [M; [v]× M; [p − t v]× M],  M = R_{k+1} J_r(ω dt) dt
    ///   F_k (acc)  = [0; R_k dt; (dt/2 − t) R_k dt]
    fn add_sample(&mut self, gyro: Vec3, dt: f64, before: QuatWxyz, after: QuatWxyz, var: &Var6) {
        let m = rotation_matrix(after) * right_jacobian(v3(gyro) * dt) * dt;
        let mut fg = M93::zeros();
        fg.fixed_view_mut::<3, 3>(0, 0).copy_from(&m);
        fg.fixed_view_mut::<3, 3>(3, 0).copy_from(&(self.v.cross_matrix() * m));
        fg.fixed_view_mut::<3, 3>(6, 0)
            .copy_from(&((self.p - self.v * self.t).cross_matrix() * m));
        let a = rotation_matrix(before) * dt;
        let mut fa = M93::zeros();
        fa.fixed_view_mut::<3, 3>(3, 0).copy_from(&a);
        fa.fixed_view_mut::<3, 3>(6, 0).copy_from(&(a * (0.5 * dt - self.t)));
        let qg = Matrix3::from_diagonal(&Vector3::new(var[0], var[1], var[2]));
        let qa = Matrix3::from_diagonal(&Vector3::new(var[3], var[4], var[5]));
        self.sum += fg * qg * fg.transpose() + fa * qa * fa.transpose();
    }
}

/// Walks rows 0..=n of the integration from sample `k` (inputs checked, k + n a valid index),
/// calling `at(j, state)` with the propagation after j samples.
fn propagate(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    var: &[Var6],
    k: usize,
    n: usize,
    mut at: impl FnMut(usize, &Propagation),
) {
    let mut s = Propagation {
        sum: M9::zeros(),
        v: Vector3::zeros(),
        p: Vector3::zeros(),
        t: 0.0,
    };
    let mut before: QuatWxyz = [1.0, 0.0, 0.0, 0.0];
    integrate_from(t_ns, gyro, acc, k, n, |j, inc: Increment| {
        if j > 0 {
            let i = k + j - 1;
            (s.v, s.p, s.t) = (v3(inc.dv), v3(inc.dp), inc.dt);
            s.add_sample(
                gyro[i],
                seconds_between(t_ns[i], t_ns[i + 1]),
                before,
                inc.dq_wxyz,
                &var[i],
            );
        }
        before = inc.dq_wxyz;
        at(j, &s);
    });
}

/// Rotation matrix of a unit quaternion w,x,y,z (not renormalised, as the integration's own).
fn rotation_matrix(q: QuatWxyz) -> Matrix3<f64> {
    let r = rotation_matrix_wxyz(q);
    Matrix3::from_fn(|i, j| r[i][j])
}

/// Right Jacobian of SO(3): J_r(φ) = I − c1 [φ]× + c2 [φ]×² with `so3::right_jacobian_coefficients`.
pub(crate) fn right_jacobian(phi: Vector3<f64>) -> Matrix3<f64> {
    let (a, b) = right_jacobian_coefficients(phi.norm_squared());
    let k = phi.cross_matrix();
    Matrix3::identity() - k * a + k * k * b
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_jacobian_series_matches_the_closed_form_below_the_switch() {
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        for theta in [0.01_f64, 0.05, 0.0999, 0.1, 0.5] {
            let phi = axis * theta;
            let k = phi.cross_matrix();
            let t2 = theta * theta;
            let want =
                Matrix3::identity() - k * ((1.0 - theta.cos()) / t2) + k * k * ((theta - theta.sin()) / (t2 * theta));
            assert!((right_jacobian(phi) - want).abs().max() < 1e-13, "θ = {theta}");
        }
        // d/dθ of J_r at 0 is −½[axis]×; a tiny angle follows it.
        let tiny = right_jacobian(axis * 1e-9);
        let want = Matrix3::identity() - (axis * 1e-9).cross_matrix() * 0.5;
        assert!((tiny - want).abs().max() < 1e-18);
    }
}
