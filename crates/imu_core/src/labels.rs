//! Reference Δq/Δβ/Δγ from ground truth (paper eqs. 2–4 solved for the increments):
//!
//!   Δq = q_k⁻¹ q_{k+n}
//!   Δβ = R_kᵀ (v_{k+n} − v_k − g Δt)
//!   Δγ = R_kᵀ (p_{k+n} − p_k − v_k Δt − ½ g Δt²)
//!
//! A window of `window` IMU samples starting at k covers [t_k, t_{k+window}]: sample i is held over
//! [t_i, t_{i+1}), so the state at index k + window must exist. Horizon n uses samples k..k+n-1,
//! which is row n of `integrate::preintegrate` run on the window.

use rayon::prelude::*;

use crate::error::{ImuError, Result};
use crate::so3::{arr3, quat_from_wxyz, quat_to_wxyz, v3};
use crate::types::{gravity_vector, QuatWxyz, Sequence, Vec3};

/// The paper's five horizons: 20/40/60/80/100 % of the window.
pub const PAPER_FRACTIONS: [f64; 5] = [0.2, 0.4, 0.6, 0.8, 1.0];

/// One increment between state k and state k + n.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Increment {
    pub dq_wxyz: QuatWxyz,
    pub dv: Vec3,
    pub dp: Vec3,
    pub dt: f64,
}

/// Horizons in samples for a window length and fractions of it (rounded, at least 1).
pub fn horizons(window: usize, fractions: &[f64]) -> Result<Vec<usize>> {
    if window == 0 {
        return Err(ImuError::invalid("window must be at least 1 sample"));
    }
    fractions
        .iter()
        .map(|&f| {
            if !(f > 0.0 && f <= 1.0) {
                return Err(ImuError::invalid(format!("horizon fraction {f} is not in (0, 1]")));
            }
            Ok(((f * window as f64).round() as usize).clamp(1, window))
        })
        .collect()
}

/// Δq, Δβ, Δγ from ground truth between states k and k + n.
pub fn increment(seq: &Sequence, k: usize, n: usize, gravity: f64) -> Result<Increment> {
    check_sequence(seq)?;
    let j = match k.checked_add(n) {
        Some(j) if j < seq.len() => j,
        _ => {
            return Err(ImuError::invalid(format!(
                "state {k} + {n} is past the sequence end ({} samples)",
                seq.len()
            )))
        }
    };
    Ok(increment_unchecked(seq, k, j, gravity))
}

/// `increment` for indices the caller has already checked (k ≤ j < len).
pub(crate) fn increment_unchecked(seq: &Sequence, k: usize, j: usize, gravity: f64) -> Increment {
    let g = v3(gravity_vector(gravity));
    // i128: stamps from arbitrary epochs can be far enough apart to overflow i64.
    let dt = (seq.t_ns[j] as i128 - seq.t_ns[k] as i128) as f64 * 1e-9;
    let qk = quat_from_wxyz(seq.q_wxyz[k]);
    let qj = quat_from_wxyz(seq.q_wxyz[j]);
    let rk_t = qk.inverse();
    let (pk, pj, vk, vj) = (v3(seq.p[k]), v3(seq.p[j]), v3(seq.v[k]), v3(seq.v[j]));
    let dv = rk_t * (vj - vk - g * dt);
    let dp = rk_t * (pj - pk - vk * dt - g * (0.5 * dt * dt));
    Increment {
        dq_wxyz: quat_to_wxyz(&(rk_t * qj)),
        dv: arr3(&dv),
        dp: arr3(&dp),
        dt,
    }
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

/// Window starts 0, stride, 2·stride, … for which the whole window fits in the sequence.
pub fn window_starts(len: usize, window: usize, stride: usize) -> Result<Vec<usize>> {
    if stride == 0 {
        return Err(ImuError::invalid("stride must be at least 1 sample"));
    }
    if window == 0 {
        return Err(ImuError::invalid("window must be at least 1 sample"));
    }
    // The window needs states k..=k+window; `len <= window` rather than `len < window + 1`, which
    // overflows for a window of usize::MAX.
    if len <= window {
        return Ok(Vec::new());
    }
    Ok((0..=len - window - 1).step_by(stride).collect())
}

/// Labels at the given horizons for the given window starts, computed in parallel.
pub fn labels_at(seq: &Sequence, starts: &[usize], horizons: &[usize], gravity: f64) -> Result<Labels> {
    check_sequence(seq)?;
    let max_h = horizons.iter().copied().max().unwrap_or(0);
    if let Some(&bad) = starts
        .iter()
        .find(|&&k| k.checked_add(max_h).is_none_or(|e| e >= seq.len()))
    {
        return Err(ImuError::invalid(format!(
            "window start {bad} + horizon {max_h} is past the sequence end ({} samples)",
            seq.len()
        )));
    }
    let nh = horizons.len();
    let incs: Vec<Increment> = starts
        .par_iter()
        .flat_map_iter(|&k| {
            horizons
                .iter()
                .map(move |&n| increment_unchecked(seq, k, k + n, gravity))
        })
        .collect();
    let mut out = Labels {
        starts: starts.to_vec(),
        horizons: horizons.to_vec(),
        dq_wxyz: Vec::with_capacity(incs.len()),
        dv: Vec::with_capacity(incs.len()),
        dp: Vec::with_capacity(incs.len()),
        dt: Vec::with_capacity(incs.len()),
    };
    debug_assert_eq!(incs.len(), starts.len() * nh);
    for inc in incs {
        out.dq_wxyz.push(inc.dq_wxyz);
        out.dv.push(inc.dv);
        out.dp.push(inc.dp);
        out.dt.push(inc.dt);
    }
    Ok(out)
}

/// Every window of a sequence (start step `stride`) at `fractions` of `window`.
pub fn window_labels(seq: &Sequence, window: usize, stride: usize, fractions: &[f64], gravity: f64) -> Result<Labels> {
    let hs = horizons(window, fractions)?;
    let starts = window_starts(seq.len(), window, stride)?;
    labels_at(seq, &starts, &hs, gravity)
}

/// All arrays of a sequence have its length.
pub fn check_sequence(seq: &Sequence) -> Result<()> {
    let n = seq.t_ns.len();
    let lens = [
        seq.gyro.len(),
        seq.acc.len(),
        seq.p.len(),
        seq.v.len(),
        seq.q_wxyz.len(),
    ];
    if lens.iter().any(|&l| l != n) {
        return Err(ImuError::invalid(format!(
            "sequence arrays differ in length: t_ns {n}, gyro/acc/p/v/q {lens:?}"
        )));
    }
    Ok(())
}
