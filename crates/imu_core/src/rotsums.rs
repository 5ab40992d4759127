//! The per-sample work of the traditional baseline's gyro fit (`_RotResiduals` in
//! python/imu_learn/baselines/traditional.py): for B windows of W samples and the affine gyro
//! model θ, the zero-order-hold rotation at each horizon and, for the exact Jacobian, the sums
//! of each sample's sensitivity against its inputs.
//!
//! Per sample k of a window, with M = I + θ[0..9], b = θ[9..12], G = θ[12..21] (row-major):
//!
//!   ω_k = M g_k − G a_k − M b,   φ_k = ω_k dt_k,   Q_k = Q_{k−1} ⊗ Exp(φ_k)   (Q_{−1} = I)
//!   A_k = R(Q_k) J_r(φ_k) dt_k,  f_k = (g_k, a_k, 1),  S_h = Σ_{k<h} A_k ⊗ f_k
//!
//! (J_r SO(3)'s right Jacobian). The output is Q_{h−1} and S_h for every horizon h. Exp, the
//! coefficients of J_r and the quaternion product are `so3`'s (Taylor series below θ² = 0.01: no
//! division by θ, no cancellation in 1 − cos θ); the numpy oracle
//! (python/imu_learn/core/numpy_reference.py, closed forms and a doubling scan) agrees to
//! round-off.
//!
//! The accelerometer stage (`_VelResiduals`) holds the calibrated rates ω_k fixed and needs, per
//! window and horizon, the sums of the rotation in force while each sample is held against the
//! sample's specific force (`velocity_window_sums`):
//!
//!   R_0 = I, R_{k+1} = R_k Exp(ω_k dt_k),   Rm_k = R_k dt_k,   T_m = Σ_{j<m} dt_j,
//!   s_k = T_{k+1} − ½ dt_k,   c_k = (a_k, 1, s_k a_k, s_k),   V_h = Σ_{k<h} Rm_k ⊗ c_k
//!
//! (`velocity_window_sums` in python/imu_learn/core/numpy_reference.py, the oracle).

use rayon::prelude::*;

use crate::batch::try_zeroed_vec;
use crate::error::{ImuError, Result};
use crate::so3::{exp_wxyz, qmul, right_jacobian_coefficients, rotation_matrix_wxyz};
use crate::types::{QuatWxyz, Vec3};

/// θ: M_g − I (9), b_g (3), G (9), row-major.
pub const THETA_LEN: usize = 21;
/// Rows of a sum: entry (r, i) of A_k in row 3r + i.
pub const SUM_ROWS: usize = 9;
/// Columns of a sum: f_k = (g_k, a_k, 1).
pub const SUM_COLS: usize = 7;
const SUM_LEN: usize = SUM_ROWS * SUM_COLS;

/// The rotations and sums of every window at every horizon.
#[derive(Clone, Debug, PartialEq)]
pub struct RotSums {
    /// Q_{h−1} (w, x, y, z), (B, H, 4) row-major.
    pub q_wxyz: Vec<f64>,
    /// S_h, entry [b, h, 3r + i, F] = Σ_{k<h} A_k[r, i] f_k[F], (B, H, 9, 7) row-major; only when
    /// asked for.
    pub sums: Option<Vec<f64>>,
}

/// A = R(q) J_r(φ) dt, row-major (entry (r, i) at 3r + i). J_r dt = a I − c1 [φ]× + c2 φφᵀ with
/// a = (1 − c2 θ²) dt and c1, c2 times dt, entry by entry as `_RotResiduals.jacobian`.
#[inline(always)]
fn sensitivity(q: QuatWxyz, phi: Vec3, t2: f64, dt: f64) -> [f64; SUM_ROWS] {
    let (c1, c2) = right_jacobian_coefficients(t2);
    let (a, c1, c2) = ((1.0 - c2 * t2) * dt, c1 * dt, c2 * dt);
    let [x, y, z] = phi;
    let (cx, cy, cz, qx, qy, qz) = (c1 * x, c1 * y, c1 * z, c2 * x, c2 * y, c2 * z);
    let jr = [
        [a + qx * x, qx * y + cz, qx * z - cy],
        [qx * y - cz, a + qy * y, qy * z + cx],
        [qx * z + cy, qy * z - cx, a + qz * z],
    ];
    let r = rotation_matrix_wxyz(q);
    std::array::from_fn(|e| {
        let (row, i) = (e / 3, e % 3);
        r[row][0] * jr[0][i] + r[row][1] * jr[1][i] + r[row][2] * jr[2][i]
    })
}

/// The gyro model at θ, set up once per call.
struct Model {
    m: [[f64; 3]; 3],
    g: [[f64; 3]; 3],
    mb: Vec3,
}

impl Model {
    fn new(theta: &[f64; THETA_LEN]) -> Self {
        let mut m = [[0.0; 3]; 3];
        let mut g = [[0.0; 3]; 3];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] = theta[3 * r + c] + if r == c { 1.0 } else { 0.0 };
                g[r][c] = theta[12 + 3 * r + c];
            }
        }
        let b = [theta[9], theta[10], theta[11]];
        let mb = m.map(|row| dot(row, b));
        Model { m, g, mb }
    }

    /// ω = M g − G a − M b.
    #[inline(always)]
    fn rate(&self, gyro: Vec3, acc: Vec3) -> Vec3 {
        std::array::from_fn(|r| dot(self.m[r], gyro) - dot(self.g[r], acc) - self.mb[r])
    }
}

#[inline(always)]
fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// One window, sample by sample (its samples up to the longest horizon). `order` lists the
/// horizons' indices by increasing horizon; each horizon's rotation (and sum) goes to its own slot.
#[allow(clippy::too_many_arguments)]
fn window(
    model: &Model,
    gyro: &[Vec3],
    acc: &[Vec3],
    dt: &[f64],
    horizons: &[usize],
    order: &[usize],
    q_out: &mut [f64],
    mut sums_out: Option<&mut [f64]>,
) {
    let mut q: QuatWxyz = [1.0, 0.0, 0.0, 0.0];
    let mut s = [0.0; SUM_LEN];
    let mut next = order.iter().peekable();
    for k in 0..gyro.len() {
        let w = model.rate(gyro[k], acc[k]);
        let phi = [w[0] * dt[k], w[1] * dt[k], w[2] * dt[k]];
        let t2 = dot(phi, phi);
        q = qmul(q, exp_wxyz(phi));
        if sums_out.is_some() {
            let sens = sensitivity(q, phi, t2, dt[k]);
            let (g, a) = (gyro[k], acc[k]);
            let f = [g[0], g[1], g[2], a[0], a[1], a[2], 1.0];
            for (row, &ae) in s.chunks_exact_mut(SUM_COLS).zip(&sens) {
                for (se, &fe) in row.iter_mut().zip(&f) {
                    *se += ae * fe;
                }
            }
        }
        while let Some(&&j) = next.peek() {
            if horizons[j] != k + 1 {
                break;
            }
            q_out[4 * j..4 * j + 4].copy_from_slice(&q);
            if let Some(out) = sums_out.as_deref_mut() {
                out[SUM_LEN * j..SUM_LEN * (j + 1)].copy_from_slice(&s);
            }
            next.next();
        }
    }
}

/// `n` zeros, or an error naming `what` where they cannot be allocated.
fn zeroed(n: usize, what: &str) -> Result<Vec<f64>> {
    try_zeroed_vec(n).map_err(|e| ImuError::invalid(format!("{what}: {n} floats cannot be allocated ({e})")))
}

/// Rotations Q_{h−1} and (with `jacobian`) sums S_h of `b` windows of `w` samples each, for the
/// gyro model `theta` (see the module doc). `gyro`, `acc` (the specific force driving G) and `dt`
/// [s] hold the windows one after another (B·W rows each); `horizons` (H, in 1..=W, any order,
/// repeats allowed) are sample counts. Everything is checked before anything is allocated; the
/// samples' values are not checked (a NaN sample gives NaN outputs of its window). Windows run in
/// parallel, each one sequentially.
#[allow(clippy::too_many_arguments)]
pub fn rotation_window_sums(
    gyro: &[Vec3],
    acc: &[Vec3],
    dt: &[f64],
    b: usize,
    w: usize,
    theta: &[f64; THETA_LEN],
    horizons: &[usize],
    jacobian: bool,
) -> Result<RotSums> {
    check_windows(
        [("gyro", gyro.len()), ("acc", acc.len()), ("dt", dt.len())],
        b,
        w,
        horizons,
    )?;
    if let Some((i, v)) = theta.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(ImuError::invalid(format!("theta[{i}] = {v} is not finite")));
    }
    let nh = horizons.len();
    let q_len = b.checked_mul(nh).and_then(|x| x.checked_mul(4));
    let s_len = b.checked_mul(nh).and_then(|x| x.checked_mul(SUM_LEN));
    let (Some(q_len), Some(s_len)) = (q_len, s_len) else {
        return Err(ImuError::invalid(format!("{b} windows x {nh} horizons overflow")));
    };

    let mut order: Vec<usize> = (0..nh).collect();
    order.sort_by_key(|&j| horizons[j]);
    let last = horizons[order[nh - 1]];
    let model = Model::new(theta);
    let mut q_wxyz = zeroed(q_len, "q_wxyz")?;
    let mut sums = if jacobian { Some(zeroed(s_len, "sums")?) } else { None };
    // Window i's samples, up to its longest horizon.
    let run = |i: usize, q: &mut [f64], s: Option<&mut [f64]>| {
        let k = i * w..i * w + last;
        let (g, a, d) = (&gyro[k.clone()], &acc[k.clone()], &dt[k]);
        window(&model, g, a, d, horizons, &order, q, s);
    };
    let (qn, sn) = (4 * nh, SUM_LEN * nh);
    match (sums.as_deref_mut(), crate::par::parallel()) {
        (Some(s), true) => q_wxyz
            .par_chunks_mut(qn)
            .zip(s.par_chunks_mut(sn))
            .enumerate()
            .for_each(|(i, (q, s))| run(i, q, Some(s))),
        (Some(s), false) => q_wxyz
            .chunks_mut(qn)
            .zip(s.chunks_mut(sn))
            .enumerate()
            .for_each(|(i, (q, s))| run(i, q, Some(s))),
        (None, true) => q_wxyz.par_chunks_mut(qn).enumerate().for_each(|(i, q)| run(i, q, None)),
        (None, false) => q_wxyz.chunks_mut(qn).enumerate().for_each(|(i, q)| run(i, q, None)),
    }
    Ok(RotSums { q_wxyz, sums })
}

/// Columns of a velocity sum: c_k = (a_k, 1, s_k a_k, s_k).
pub const VEL_COLS: usize = 8;
const VEL_LEN: usize = SUM_ROWS * VEL_COLS;

/// The checks both entry points share: B·W samples in every input, horizons non-empty and in
/// 1..=W. Returns B·W.
fn check_windows(inputs: [(&str, usize); 3], b: usize, w: usize, horizons: &[usize]) -> Result<usize> {
    let n = b
        .checked_mul(w)
        .ok_or_else(|| ImuError::invalid(format!("{b} windows of {w} samples overflow")))?;
    for (name, len) in inputs {
        if len != n {
            return Err(ImuError::invalid(format!(
                "{name} has {len} samples, expected {b} windows x {w} samples = {n}"
            )));
        }
    }
    if horizons.is_empty() {
        return Err(ImuError::invalid("horizons is empty: at least one horizon is needed"));
    }
    if let Some((i, h)) = horizons.iter().enumerate().find(|(_, &h)| h == 0 || h > w) {
        return Err(ImuError::invalid(format!(
            "horizons[{i}] = {h}: a horizon must be in 1..={w} (the window's samples)"
        )));
    }
    Ok(n)
}

/// One window of `velocity_window_sums`, sample by sample (its samples up to the longest
/// horizon), with plain running sums; `order` as in `window`. `steps` (scratch, one per sample)
/// takes every sample's Exp(ω_k dt_k) first: they do not depend on each other, so computing
/// them apart from the product chain lets the processor overlap them.
#[allow(clippy::too_many_arguments)]
fn velocity_window(
    rates: &[Vec3],
    acc: &[Vec3],
    dt: &[f64],
    horizons: &[usize],
    order: &[usize],
    steps: &mut Vec<QuatWxyz>,
    out: &mut [f64],
) {
    steps.clear();
    steps.extend(rates.iter().zip(dt).map(|(wk, &d)| {
        let phi = [wk[0] * d, wk[1] * d, wk[2] * d];
        exp_wxyz(phi)
    }));
    let mut q: QuatWxyz = [1.0, 0.0, 0.0, 0.0];
    let mut t = 0.0; // T_k, summed in sample order as numpy's cumsum
    let mut s = [0.0; VEL_LEN];
    let mut next = order.iter().peekable();
    for k in 0..rates.len() {
        let d = dt[k];
        // R_k dt_k with R_k the product of the steps before sample k (R_0 = I).
        let r = rotation_matrix_wxyz(q);
        let rm: [f64; SUM_ROWS] = std::array::from_fn(|e| r[e / 3][e % 3] * d);
        t += d;
        let sk = t - 0.5 * d;
        let a = acc[k];
        let c = [a[0], a[1], a[2], 1.0, sk * a[0], sk * a[1], sk * a[2], sk];
        for (row, &re) in s.chunks_exact_mut(VEL_COLS).zip(&rm) {
            for (se, &ce) in row.iter_mut().zip(&c) {
                *se += re * ce;
            }
        }
        while let Some(&&j) = next.peek() {
            if horizons[j] != k + 1 {
                break;
            }
            out[VEL_LEN * j..VEL_LEN * (j + 1)].copy_from_slice(&s);
            next.next();
        }
        q = qmul(q, steps[k]);
    }
}

/// The accelerometer stage's sums V_h of `b` windows of `w` samples each (see the module doc):
/// entry [b, h, 3r + i, F] = Σ_{k<h} R_k[r, i] dt_k c_k[F], (B, H, 9, 8) row-major. `rates` (the
/// calibrated rates [rad/s]), `acc` (specific force) and `dt` [s] hold the windows one after
/// another (B·W rows each); `horizons` (H, in 1..=W, any order, repeats allowed) are sample
/// counts. Everything is checked before anything is allocated; the samples' values are not
/// checked (a NaN sample gives NaN outputs in its window from where it enters). Windows run in
/// parallel, each one sequentially, so the result does not depend on the number of threads.
pub fn velocity_window_sums(
    rates: &[Vec3],
    acc: &[Vec3],
    dt: &[f64],
    b: usize,
    w: usize,
    horizons: &[usize],
) -> Result<Vec<f64>> {
    check_windows(
        [("rates", rates.len()), ("acc", acc.len()), ("dt", dt.len())],
        b,
        w,
        horizons,
    )?;
    let nh = horizons.len();
    let Some(len) = b.checked_mul(nh).and_then(|x| x.checked_mul(VEL_LEN)) else {
        return Err(ImuError::invalid(format!("{b} windows x {nh} horizons overflow")));
    };
    let mut order: Vec<usize> = (0..nh).collect();
    order.sort_by_key(|&j| horizons[j]);
    let last = horizons[order[nh - 1]];
    let mut sums = zeroed(len, "sums")?;
    let one = |steps: &mut Vec<_>, (i, out): (usize, &mut [f64])| {
        let k = i * w..i * w + last;
        velocity_window(&rates[k.clone()], &acc[k.clone()], &dt[k], horizons, &order, steps, out);
    };
    if crate::par::parallel() {
        sums.par_chunks_mut(VEL_LEN * nh)
            .enumerate()
            .for_each_init(Vec::new, one);
    } else {
        let mut steps = Vec::new();
        sums.chunks_mut(VEL_LEN * nh)
            .enumerate()
            .for_each(|x| one(&mut steps, x));
    }
    Ok(sums)
}
