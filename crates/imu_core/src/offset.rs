//! The timing floor's cost at one time offset (`RotationWindows.angles` in
//! python/imu_learn/baselines/timing.py): the gyro resampled at t + τ·period by linear
//! interpolation, integrated over each window, and each window's rotation compared with the
//! reference's.
//!
//! For a window starting at sample k and a horizon n:
//!
//!   ω̃_i = interp(t_i − t_0 + τ P),   Q = ⊗_{i=k}^{k+n−1} Exp(ω̃_i (t_{i+1} − t_i)),
//!   angle = 2 atan2(|e_xyz|, |e_w|),   e = Δq_ref⁻¹ ⊗ Q
//!
//! with `interp` numpy's `np.interp` on the stamps (relative to the first, as float64; ends held)
//! term by term, so the resampled gyro equals `timing.resample`'s bit for bit, and the rotation
//! chain `integrate_windows`'s (the same Exp and product). Only the samples the windows hold are
//! resampled, and only the rotation is integrated: the search's cost evaluations no longer
//! resample whole recordings and integrate velocities and positions they do not use. The numpy
//! path is the oracle (tests/test_offset_angles.py).

use rayon::prelude::*;

use crate::error::{ImuError, Result};
use crate::integrate::check_imu;
use crate::labels::check_windows;
use crate::so3::{exp_wxyz, qmul};
use crate::types::{seconds_between, QuatWxyz, Vec3};

/// numpy's `interp(x, xp, fp)` for one x, with `j` a starting guess of the interval (moved to
/// the one holding x): the same branches and the same arithmetic.
#[inline]
fn interp(x: f64, xp: &[f64], fp: &[Vec3], j: &mut usize) -> Vec3 {
    let n = xp.len();
    if x > xp[n - 1] {
        return fp[n - 1];
    }
    if x < xp[0] {
        return fp[0];
    }
    // xp[j] <= x < xp[j + 1], or j = n - 1 where x == xp[n - 1]
    let mut i = (*j).min(n - 1);
    while i > 0 && xp[i] > x {
        i -= 1;
    }
    while i + 1 < n && xp[i + 1] <= x {
        i += 1;
    }
    *j = i;
    if i == n - 1 || xp[i] == x {
        return fp[i];
    }
    let (x0, x1) = (xp[i], xp[i + 1]);
    std::array::from_fn(|c| {
        let (y0, y1) = (fp[i][c], fp[i + 1][c]);
        let slope = (y1 - y0) / (x1 - x0);
        let v = slope * (x - x0) + y0;
        if !v.is_nan() {
            return v;
        }
        let w = slope * (x - x1) + y1;
        if w.is_nan() && y0 == y1 {
            y0
        } else {
            w
        }
    })
}

/// Angle [rad] of `a⁻¹ ⊗ b` (w, x, y, z).
#[inline]
fn angle_between(a: QuatWxyz, b: QuatWxyz) -> f64 {
    let e = qmul([a[0], -a[1], -a[2], -a[3]], b);
    2.0 * (e[1] * e[1] + e[2] * e[2] + e[3] * e[3]).sqrt().atan2(e[0].abs())
}

/// Rotation residual angles [rad] of every window (`starts`) and horizon (`horizons`, sample
/// counts), window-major as `labels::labels_at` lays out `dq_ref` (B·H quaternions), with the gyro
/// resampled at t + `tau`·`period_ns` (see the module doc). The inputs are checked as
/// `integrate_windows` checks them, and `dq_ref`'s length and the offset's finiteness.
#[allow(clippy::too_many_arguments)]
pub fn offset_rotation_angles(
    t_ns: &[i64],
    gyro: &[Vec3],
    starts: &[usize],
    horizons: &[usize],
    dq_ref: &[QuatWxyz],
    tau: f64,
    period_ns: f64,
) -> Result<Vec<f64>> {
    check_imu(t_ns, gyro, gyro)?;
    let max_h = check_windows(t_ns.len(), starts, horizons)?;
    let nh = horizons.len();
    if dq_ref.len() != starts.len() * nh {
        return Err(ImuError::invalid(format!(
            "dq_ref has {} rows, expected {} windows x {nh} horizons",
            dq_ref.len(),
            starts.len()
        )));
    }
    if !(tau.is_finite() && period_ns.is_finite()) {
        return Err(ImuError::invalid(format!(
            "tau = {tau} and period_ns = {period_ns} must be finite"
        )));
    }
    if starts.is_empty() {
        return Ok(Vec::new());
    }
    let t0 = t_ns[0];
    let xp: Vec<f64> = t_ns.iter().map(|&t| t.wrapping_sub(t0) as f64).collect();
    let shift = tau * period_ns;
    let mut wanted: Vec<Vec<usize>> = vec![Vec::new(); max_h + 1];
    for (h, &n) in horizons.iter().enumerate() {
        wanted[n].push(h);
    }
    let one = |(w, out): (usize, &mut [f64])| {
        let k = starts[w];
        let mut q: QuatWxyz = [1.0, 0.0, 0.0, 0.0];
        let mut j = k;
        for (n, hs) in wanted.iter().enumerate().skip(1) {
            let i = k + n - 1;
            let g = if tau == 0.0 {
                gyro[i]
            } else {
                interp(xp[i] + shift, &xp, gyro, &mut j)
            };
            let dt = seconds_between(t_ns[i], t_ns[i + 1]);
            q = qmul(q, exp_wxyz([g[0] * dt, g[1] * dt, g[2] * dt]));
            for &h in hs {
                out[h] = angle_between(dq_ref[w * nh + h], q);
            }
        }
    };
    let mut out = vec![0.0; starts.len() * nh];
    if crate::par::parallel() {
        out.par_chunks_mut(nh).enumerate().for_each(one);
    } else {
        out.chunks_mut(nh).enumerate().for_each(one);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interp_holds_the_ends_and_is_linear_between_from_any_guess() {
        let xp = [0.0, 1.0, 3.0];
        let fp = [[0.0, 1.0, 2.0], [2.0, 1.0, 0.0], [6.0, 1.0, -4.0]];
        for guess in [0, 1, 2, 7] {
            let at = |x: f64| {
                let mut j = guess;
                interp(x, &xp, &fp, &mut j)
            };
            assert_eq!(at(-1.0), fp[0]);
            assert_eq!(at(0.0), fp[0]);
            assert_eq!(at(0.5), [1.0, 1.0, 1.0]);
            assert_eq!(at(1.0), fp[1]);
            assert_eq!(at(2.0), [4.0, 1.0, -2.0]);
            assert_eq!(at(3.0), fp[2]);
            assert_eq!(at(4.5), fp[2]);
        }
    }

    #[test]
    fn zero_offset_integrates_the_samples_as_they_are() {
        // One window of two samples at 1 rad/s about z over 0.5 s each: 1 rad against the identity.
        let t = [0, 500_000_000, 1_000_000_000];
        let g = [[0.0, 0.0, 1.0]; 3];
        let a = offset_rotation_angles(&t, &g, &[0], &[2], &[[1.0, 0.0, 0.0, 0.0]], 0.0, 5e8).unwrap();
        assert!((a[0] - 1.0).abs() < 1e-15, "{a:?}");
        // Half a sample later the held last sample changes nothing here (a constant rate).
        let b = offset_rotation_angles(&t, &g, &[0], &[2], &[[1.0, 0.0, 0.0, 0.0]], 0.5, 5e8).unwrap();
        assert!((b[0] - 1.0).abs() < 1e-15, "{b:?}");
        let bad = offset_rotation_angles(&t, &g, &[0], &[2], &[], 0.0, 5e8);
        assert!(matches!(bad, Err(ImuError::InvalidInput(m)) if m.contains("dq_ref")));
    }
}
