//! Reference Δq/Δβ/Δγ from ground truth (paper eqs. 2–4 solved for the increments):
//!
//!   Δq = q_k⁻¹ q_{k+n}
//!   Δβ = R_kᵀ (v_{k+n} − v_k − g Δt)
//!   Δγ = R_kᵀ (p_{k+n} − p_k − v_k Δt − ½ g Δt²)
//!
//! A window of `window` IMU samples starting at k covers [t_k, t_{k+window}]: sample i is held over
//! [t_i, t_{i+1}), so the state at index k + window must exist. Horizon n uses samples k..k+n-1,
//! which is row n of `integrate::preintegrate` run on the window.
//!
//! Every increment goes through one kernel (`Frame`): the start state's quaternion is normalised
//! and turned into R_kᵀ once per window, then reused for all of the window's horizons. `increment`,
//! `labels_at`, `labels_into` and the batches all use it, so they agree bit for bit.

use rayon::prelude::*;

use crate::error::{ImuError, Result};
use crate::so3::rotation_matrix_wxyz;
use crate::types::{gravity_vector, QuatWxyz, Sequence, Vec3};
// Defined with the other plain data in `types`; re-exported where they were first declared.
pub(crate) use crate::types::seconds_between;
pub use crate::types::{Increment, Labels};

/// The paper's five horizons: 20/40/60/80/100 % of the window.
pub const PAPER_FRACTIONS: [f64; 5] = [0.2, 0.4, 0.6, 0.8, 1.0];

/// Ground truth borrowed as slices: all that labels need (no IMU samples). Every slice must
/// have the length of `t_ns` (`GroundTruthView::check`).
#[derive(Clone, Copy, Debug)]
pub struct GroundTruthView<'a> {
    pub t_ns: &'a [i64],
    pub p: &'a [Vec3],
    pub v: &'a [Vec3],
    pub q_wxyz: &'a [QuatWxyz],
}

impl<'a> GroundTruthView<'a> {
    /// The ground-truth part of a sequence.
    pub fn of(seq: &'a Sequence) -> Self {
        GroundTruthView {
            t_ns: &seq.t_ns,
            p: &seq.p,
            v: &seq.v,
            q_wxyz: &seq.q_wxyz,
        }
    }

    pub fn len(&self) -> usize {
        self.t_ns.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_ns.is_empty()
    }

    /// p, v and q have the length of t_ns; the stamps strictly increase; every value is finite and
    /// every quaternion is a rotation (norm above 0.5: a zero or NaN row gave NaN labels).
    pub fn check(&self) -> Result<()> {
        let n = self.t_ns.len();
        let lens = [self.p.len(), self.v.len(), self.q_wxyz.len()];
        if lens.iter().any(|&l| l != n) {
            return Err(ImuError::invalid(format!(
                "ground-truth arrays differ in length: t_ns {n}, p/v/q {lens:?}"
            )));
        }
        crate::integrate::check_stamps(self.t_ns)?;
        let bad = |name: &str, i: usize, row: &[f64]| {
            ImuError::invalid(format!("ground truth {name}[{i}] = {row:?} is not finite"))
        };
        if let Some(i) = self.p.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
            return Err(bad("p", i, &self.p[i]));
        }
        if let Some(i) = self.v.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
            return Err(bad("v", i, &self.v[i]));
        }
        if let Some(i) = self
            .q_wxyz
            .iter()
            .position(|q| q.iter().any(|x| !x.is_finite()) || q.iter().map(|x| x * x).sum::<f64>() <= 0.25)
        {
            return Err(ImuError::invalid(format!(
                "ground truth q_wxyz[{i}] = {:?} is not a rotation (its norm is not near 1)",
                self.q_wxyz[i]
            )));
        }
        Ok(())
    }
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
    let gt = GroundTruthView::of(seq);
    Frame::at(&gt, k, gravity).to(&gt, j)
}

/// Unit quaternion w,x,y,z from a stored one (files carry 6–9 digits, so norms are off by ~1e-6).
#[inline]
fn normalized(q: QuatWxyz) -> QuatWxyz {
    let inv = 1.0 / (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    [q[0] * inv, q[1] * inv, q[2] * inv, q[3] * inv]
}

/// The state at a window start k, prepared once for all of the window's horizons.
pub(crate) struct Frame {
    /// q_k⁻¹ (normalised, conjugated).
    qi: QuatWxyz,
    /// R_kᵀ, row-major.
    rt: [[f64; 3]; 3],
    p: Vec3,
    v: Vec3,
    t: i64,
    g: Vec3,
}

impl Frame {
    #[inline]
    pub(crate) fn at(gt: &GroundTruthView<'_>, k: usize, gravity: f64) -> Frame {
        let q = normalized(gt.q_wxyz[k]);
        let [w, x, y, z] = q;
        // R of the unit quaternion (body → world); its transpose maps world into body k.
        let r = rotation_matrix_wxyz(q);
        let rt = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
        Frame {
            qi: [w, -x, -y, -z],
            rt,
            p: gt.p[k],
            v: gt.v[k],
            t: gt.t_ns[k],
            g: gravity_vector(gravity),
        }
    }

    #[inline]
    fn rotate(&self, a: Vec3) -> Vec3 {
        let r = &self.rt;
        [
            r[0][0] * a[0] + r[0][1] * a[1] + r[0][2] * a[2],
            r[1][0] * a[0] + r[1][1] * a[1] + r[1][2] * a[2],
            r[2][0] * a[0] + r[2][1] * a[1] + r[2][2] * a[2],
        ]
    }

    /// The increment from this state to state j (j within the view).
    #[inline]
    pub(crate) fn to(&self, gt: &GroundTruthView<'_>, j: usize) -> Increment {
        let dt = seconds_between(self.t, gt.t_ns[j]);
        let (a, b) = (self.qi, normalized(gt.q_wxyz[j]));
        let dq_wxyz = [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ];
        let (pj, vj, g) = (gt.p[j], gt.v[j], self.g);
        let half = 0.5 * dt * dt;
        let dv = std::array::from_fn(|c| vj[c] - self.v[c] - g[c] * dt);
        let dp = std::array::from_fn(|c| pj[c] - self.p[c] - self.v[c] * dt - g[c] * half);
        Increment {
            dq_wxyz,
            dv: self.rotate(dv),
            dp: self.rotate(dp),
            dt,
        }
    }
}

/// Output buffers for `labels_into`, each `starts.len() * horizons.len()` entries, row-major.
pub struct LabelsMut<'a> {
    pub dq_wxyz: &'a mut [QuatWxyz],
    pub dv: &'a mut [Vec3],
    pub dp: &'a mut [Vec3],
    pub dt: &'a mut [f64],
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

/// The windows `labels_at` and `integrate::integrate_windows` are asked for, checked before
/// anything is sized by them: every horizon is at least 1 and fits in a sequence of `len` states
/// (horizon n needs states k..=k+n, so n ≤ len − 1), and every start leaves room for the longest
/// horizon. Returns the longest horizon (0 for none). Errors name the argument and its index.
pub fn check_windows(len: usize, starts: &[usize], horizons: &[usize]) -> Result<usize> {
    for (i, &n) in horizons.iter().enumerate() {
        if n == 0 {
            return Err(ImuError::invalid(format!(
                "horizons[{i}] = 0: a horizon must be at least 1 sample"
            )));
        }
        if n >= len {
            let allowed = match len {
                0 | 1 => format!("a sequence of {len} samples holds no interval, so no horizon fits"),
                _ => format!("a sequence of {len} samples allows horizons 1..={}", len - 1),
            };
            return Err(ImuError::invalid(format!(
                "horizons[{i}] = {n} is past the sequence end: {allowed}"
            )));
        }
    }
    let max_h = horizons.iter().copied().max().unwrap_or(0);
    if let Some((i, &bad)) = starts
        .iter()
        .enumerate()
        .find(|&(_, &k)| k.checked_add(max_h).is_none_or(|e| e >= len))
    {
        return Err(ImuError::invalid(format!(
            "starts[{i}]: window start {bad} + horizon {max_h} is past the sequence end ({len} samples)"
        )));
    }
    Ok(max_h)
}

/// Labels at the given horizons for the given window starts, computed in parallel.
pub fn labels_at(seq: &Sequence, starts: &[usize], horizons: &[usize], gravity: f64) -> Result<Labels> {
    check_sequence(seq)?;
    // Checked before the buffers are sized by the caller's arguments.
    check_windows(seq.len(), starts, horizons)?;
    let total = starts.len().checked_mul(horizons.len()).ok_or_else(|| {
        ImuError::invalid(format!(
            "{} windows × {} horizons overflow",
            starts.len(),
            horizons.len()
        ))
    })?;
    let alloc = |e| {
        ImuError::invalid(format!(
            "{} windows × {} horizons cannot be allocated ({e})",
            starts.len(),
            horizons.len()
        ))
    };
    let mut out = Labels {
        starts: starts.to_vec(),
        horizons: horizons.to_vec(),
        dq_wxyz: crate::batch::try_zeroed_vec(total).map_err(alloc)?,
        dv: crate::batch::try_zeroed_vec(total).map_err(alloc)?,
        dp: crate::batch::try_zeroed_vec(total).map_err(alloc)?,
        dt: crate::batch::try_zeroed_vec(total).map_err(alloc)?,
    };
    labels_into(
        GroundTruthView::of(seq),
        starts,
        horizons,
        gravity,
        LabelsMut {
            dq_wxyz: &mut out.dq_wxyz,
            dv: &mut out.dv,
            dp: &mut out.dp,
            dt: &mut out.dt,
        },
    )?;
    Ok(out)
}

/// `labels_at` on borrowed ground truth, writing into caller-owned buffers (the Python binding
/// hands numpy's own arrays here, so nothing is copied afterwards). Windows run in parallel.
pub fn labels_into(
    gt: GroundTruthView<'_>,
    starts: &[usize],
    horizons: &[usize],
    gravity: f64,
    out: LabelsMut<'_>,
) -> Result<()> {
    gt.check()?;
    check_windows(gt.len(), starts, horizons)?;
    if !gravity.is_finite() {
        return Err(ImuError::invalid(format!("gravity = {gravity} is not finite")));
    }
    let nh = horizons.len();
    let total = starts.len() * nh;
    let lens = [out.dq_wxyz.len(), out.dv.len(), out.dp.len(), out.dt.len()];
    if lens.iter().any(|&l| l != total) {
        return Err(ImuError::invalid(format!(
            "label buffers hold {lens:?} entries, {} windows × {nh} horizons need {total}",
            starts.len()
        )));
    }
    if nh == 0 {
        return Ok(());
    }
    out.dq_wxyz
        .par_chunks_mut(nh)
        .zip(out.dv.par_chunks_mut(nh))
        .zip(out.dp.par_chunks_mut(nh))
        .zip(out.dt.par_chunks_mut(nh))
        .zip(starts.par_iter())
        .with_min_len(256)
        .for_each(|((((dq, dv), dp), dt), &k)| {
            let f = Frame::at(&gt, k, gravity);
            for (h, &n) in horizons.iter().enumerate() {
                let inc = f.to(&gt, k + n);
                dq[h] = inc.dq_wxyz;
                dv[h] = inc.dv;
                dp[h] = inc.dp;
                dt[h] = inc.dt;
            }
        });
    Ok(())
}

/// Every window of a sequence (start step `stride`) at `fractions` of `window`.
pub fn window_labels(seq: &Sequence, window: usize, stride: usize, fractions: &[f64], gravity: f64) -> Result<Labels> {
    let hs = horizons(window, fractions)?;
    let starts = window_starts(seq.len(), window, stride)?;
    if starts.is_empty() {
        // A sequence shorter than one window has no windows (not an error): `labels_at` would
        // reject its horizons, which do not fit, though no window asks for them.
        check_sequence(seq)?;
        return Ok(Labels {
            horizons: hs,
            ..Labels::default()
        });
    }
    labels_at(seq, &starts, &hs, gravity)
}

/// All arrays of a sequence have its length, its stamps strictly increase and its values are finite
/// (its quaternions rotations: [`GroundTruthView::check`]).
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
    GroundTruthView::of(seq).check()?;
    crate::integrate::check_finite(&seq.gyro, &seq.acc)
}
