//! Δq/Δβ/Δγ from IMU samples: the preintegrated increments of paper Section III, with zero bias
//! and no gravity (gravity enters only when the increments are turned into poses, see `labels`).
//!
//! The arithmetic is GTSAM's `ManifoldPreintegration` (`NavState::update` with zero bias): per
//! sample, using the rotation from *before* the sample,
//!
//!   Δγ ← Δγ + Δβ·dt + ½·ΔR·a·dt²
//!   Δβ ← Δβ + ΔR·a·dt
//!   ΔR ← ΔR·Exp(ω·dt)
//!
//! so that results agree with `gtsam.PreintegratedImuMeasurementsManifold` to round-off. GTSAM
//! never re-orthonormalises its rotation matrix, so we do not renormalise the quaternion either:
//! a product of unit quaternions drifts in norm by ~1e-16 per step, far below anything measured.
//!
//! Sample i is held over [t_i, t_{i+1}) (zero-order hold), so row j of a preintegration over
//! stamps t_0..t_{N-1} covers [t_0, t_j] and uses samples 0..j-1. The last sample is held past
//! the last stamp, so it enters no row (it is still validated).

use rayon::prelude::*;

use crate::error::{ImuError, Result};
use crate::labels::check_windows;
use crate::so3::{self, qmul};
use crate::types::{seconds_between, Increment, Labels, QuatWxyz, Vec3};

/// Cumulative increments, one row per stamp: row j covers [t_0, t_j]; row 0 is the identity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Preintegrated {
    pub dq_wxyz: Vec<QuatWxyz>,
    pub dv: Vec<Vec3>,
    pub dp: Vec<Vec3>,
    pub dt: Vec<f64>,
}

impl Preintegrated {
    fn with_capacity(n: usize) -> Self {
        Preintegrated {
            dq_wxyz: Vec::with_capacity(n),
            dv: Vec::with_capacity(n),
            dp: Vec::with_capacity(n),
            dt: Vec::with_capacity(n),
        }
    }

    fn push(&mut self, inc: Increment) {
        self.dq_wxyz.push(inc.dq_wxyz);
        self.dv.push(inc.dv);
        self.dp.push(inc.dp);
        self.dt.push(inc.dt);
    }

    pub fn len(&self) -> usize {
        self.dt.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dt.is_empty()
    }

    /// Row j as one increment (`None` past the end).
    pub fn row(&self, j: usize) -> Option<Increment> {
        Some(Increment {
            dq_wxyz: *self.dq_wxyz.get(j)?,
            dv: *self.dv.get(j)?,
            dp: *self.dp.get(j)?,
            dt: *self.dt.get(j)?,
        })
    }
}

/// v rotated by the unit quaternion q (w,x,y,z): v + w·t + u × t with t = 2·(u × v), u = (x, y, z)
/// (15 multiplications instead of the 28 of q ⊗ v ⊗ q⁻¹).
#[inline(always)]
fn rotate(q: QuatWxyz, v: Vec3) -> Vec3 {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

/// The running state of one integration; `dt` is carried by the caller because it is computed
/// differently from stamps (exactly, from integer nanoseconds) and from hold times (summed).
#[derive(Clone, Copy, Debug)]
struct Delta {
    q: QuatWxyz,
    v: Vec3,
    p: Vec3,
}

impl Delta {
    fn identity() -> Self {
        Delta {
            q: [1.0, 0.0, 0.0, 0.0],
            v: [0.0; 3],
            p: [0.0; 3],
        }
    }

    /// One zero-order-hold step, in GTSAM's order (position, velocity, then rotation).
    #[inline]
    fn step(&mut self, gyro: Vec3, acc: Vec3, dt: f64) {
        self.step_exp(acc, dt, so3::exp_wxyz([gyro[0] * dt, gyro[1] * dt, gyro[2] * dt]));
    }

    /// `step` with the rotation increment Exp(ω·dt) already computed.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // p, v and a advance in lockstep, one axis at a time
    fn step_exp(&mut self, acc: Vec3, dt: f64, exp: QuatWxyz) {
        let dt22 = 0.5 * dt * dt;
        let a = rotate(self.q, acc);
        for c in 0..3 {
            // Δγ + (Δβ·dt + ½a·dt²): one addition on the running sum per step, not two.
            self.p[c] += self.v[c] * dt + a[c] * dt22;
            self.v[c] += a[c] * dt;
        }
        self.q = qmul(self.q, exp);
    }

    fn from_row(q: QuatWxyz, v: Vec3, p: Vec3) -> Self {
        Delta { q, v, p }
    }

    /// `self` followed by `next`, an increment over `dt` seconds that starts where `self` ends.
    #[inline]
    #[allow(clippy::needless_range_loop)] // four arrays indexed in lockstep
    fn then(&self, next: &Delta, dt: f64) -> Delta {
        let (rv, rp) = (rotate(self.q, next.v), rotate(self.q, next.p));
        let mut out = Delta {
            q: qmul(self.q, next.q),
            v: [0.0; 3],
            p: [0.0; 3],
        };
        for c in 0..3 {
            out.v[c] = self.v[c] + rv[c];
            out.p[c] = self.p[c] + self.v[c] * dt + rp[c];
        }
        out
    }

    fn increment(&self, dt: f64) -> Increment {
        Increment {
            dq_wxyz: self.q,
            dv: self.v,
            dp: self.p,
            dt,
        }
    }
}

fn check_lengths(what: &str, n: usize, gyro: &[Vec3], acc: &[Vec3]) -> Result<()> {
    if gyro.len() != n || acc.len() != n {
        return Err(ImuError::invalid(format!(
            "{what} has {n} entries but gyro has {} and acc {}; they must be equal",
            gyro.len(),
            acc.len()
        )));
    }
    Ok(())
}

pub(crate) fn check_finite(gyro: &[Vec3], acc: &[Vec3]) -> Result<()> {
    // A float is ±inf or NaN exactly when its 11 exponent bits are all set. OR-ing that flag over
    // every value is branch-free integer work the compiler vectorises (a floating-point sum would
    // be one long chain of dependent adds); only a failure pays for finding the first bad row.
    let all_finite = |rows: &[Vec3]| {
        rows.as_flattened()
            .iter()
            .fold(0u64, |acc, &x| acc | u64::from((x.to_bits() >> 52) & 0x7ff == 0x7ff))
            == 0
    };
    if all_finite(gyro) && all_finite(acc) {
        return Ok(());
    }
    for (name, rows) in [("gyro", gyro), ("acc", acc)] {
        if let Some(i) = rows.iter().position(|r| r.iter().any(|x| !x.is_finite())) {
            return Err(ImuError::invalid(format!("{name}[{i}] = {:?} is not finite", rows[i])));
        }
    }
    Ok(())
}

pub(crate) fn check_stamps(t_ns: &[i64]) -> Result<()> {
    // Branch-free over all pairs first (the compiler vectorises it; an early-exit search does
    // not), then look for the first bad pair only on failure.
    if t_ns.windows(2).fold(true, |ok, w| ok & (w[1] > w[0])) {
        return Ok(());
    }
    if let Some(i) = t_ns.windows(2).position(|w| w[1] <= w[0]) {
        return Err(ImuError::invalid(format!(
            "t_ns[{}] = {} is not after t_ns[{i}] = {}; stamps must be strictly increasing",
            i + 1,
            t_ns[i + 1],
            t_ns[i]
        )));
    }
    Ok(())
}

/// Lengths, stamps and values of IMU inputs (shared with `covariance`).
pub(crate) fn check_imu(t_ns: &[i64], gyro: &[Vec3], acc: &[Vec3]) -> Result<()> {
    check_lengths("t_ns", t_ns.len(), gyro, acc)?;
    check_stamps(t_ns)?;
    check_finite(gyro, acc)
}

/// Rows 0..=n of the integration that starts at sample `k`. The caller has checked the inputs
/// and that k + n is a valid index. `covariance` walks the same per-sample states through it.
pub(crate) fn integrate_from(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    k: usize,
    n: usize,
    mut row: impl FnMut(usize, Increment),
) {
    let mut d = Delta::identity();
    row(0, d.increment(0.0));
    for j in 1..=n {
        let i = k + j - 1;
        d.step(gyro[i], acc[i], seconds_between(t_ns[i], t_ns[i + 1]));
        row(j, d.increment(seconds_between(t_ns[k], t_ns[k + j])));
    }
}

/// Preintegrate samples on stamps `t_ns` [ns]: N stamps give N rows, row j covering [t_0, t_j]
/// with samples 0..j-1. Row dt is computed from the integer stamps, so it carries no summed
/// round-off and equals the ground-truth labels' Δt exactly.
///
/// Long inputs are integrated in parallel pieces that are then chained (see `preintegrate_into`).
pub fn preintegrate(t_ns: &[i64], gyro: &[Vec3], acc: &[Vec3]) -> Result<Preintegrated> {
    let n = t_ns.len();
    let mut out = Preintegrated {
        dq_wxyz: vec![[0.0; 4]; n],
        dv: vec![[0.0; 3]; n],
        dp: vec![[0.0; 3]; n],
        dt: vec![0.0; n],
    };
    preintegrate_into(
        t_ns,
        gyro,
        acc,
        PreintegratedMut {
            dq_wxyz: &mut out.dq_wxyz,
            dv: &mut out.dv,
            dp: &mut out.dp,
            dt: &mut out.dt,
        },
    )?;
    Ok(out)
}

/// Output buffers for `preintegrate_into`, one row per stamp.
pub struct PreintegratedMut<'a> {
    pub dq_wxyz: &'a mut [QuatWxyz],
    pub dv: &'a mut [Vec3],
    pub dp: &'a mut [Vec3],
    pub dt: &'a mut [f64],
}

/// Below this many samples per piece a preintegration runs on one thread.
const MIN_PIECE: usize = 8192;

/// `preintegrate` into caller-owned buffers (the Python binding passes numpy's own arrays).
///
/// The recursion is a prefix product, but increments compose: with piece a = [t_0, t_m] and
/// piece b = [t_m, t_j] integrated from the identity,
///
///   Δq_0j = Δq_0m Δq_mj,   Δβ_0j = Δβ_0m + ΔR_0m Δβ_mj,   Δγ_0j = Δγ_0m + Δβ_0m Δt_mj + ΔR_0m Δγ_mj
///
/// exactly (this is how GTSAM combines preintegrated factors). So a long input is cut into one
/// piece per thread, the pieces are integrated in parallel, and each row of piece c > 0 is then
/// chained onto the end of the pieces before it, again in parallel. The first piece is
/// bit-identical to the plain loop; later rows differ from it by round-off only (relative
/// ~1e-16 per chaining, far below GTSAM agreement at 1e-9).
///
/// On error the buffers hold unspecified values.
pub fn preintegrate_into(t_ns: &[i64], gyro: &[Vec3], acc: &[Vec3], out: PreintegratedMut<'_>) -> Result<()> {
    check_lengths("t_ns", t_ns.len(), gyro, acc)?;
    check_stamps(t_ns)?;
    let n = t_ns.len();
    let lens = [out.dq_wxyz.len(), out.dv.len(), out.dp.len(), out.dt.len()];
    if lens.iter().any(|&l| l != n) {
        return Err(ImuError::invalid(format!(
            "output buffers hold {lens:?} rows, {n} stamps need {n}"
        )));
    }
    if n == 0 {
        return Ok(());
    }
    let PreintegratedMut { dq_wxyz, dv, dp, dt } = out;
    integrate_pieces(
        t_ns,
        gyro,
        acc,
        PreintegratedMut {
            dq_wxyz: &mut *dq_wxyz,
            dv: &mut *dv,
            dp: &mut *dp,
            dt: &mut *dt,
        },
    );
    // Values are checked after integrating rather than before: a separate pass over every input
    // cost as much as a third of the integration. A non-finite sample cannot vanish from the
    // result: it makes its Exp or ΔR·a non-finite, NaN and ±inf survive every later product and
    // sum, so the last row is non-finite too. That row covers samples 0..n-1; the last sample
    // (held past the last stamp, in no row) is checked directly. Only then is the full scan run,
    // to name the first bad sample (it finds none if finite inputs overflowed: no error then).
    let last = n - 1;
    let finite = |x: &f64| x.is_finite();
    let row_ok = dq_wxyz[last].iter().all(finite) && dv[last].iter().all(finite) && dp[last].iter().all(finite);
    if !(row_ok && gyro[last].iter().all(finite) && acc[last].iter().all(finite)) {
        check_finite(gyro, acc)?;
    }
    Ok(())
}

/// `preintegrate_into` once the inputs are checked and the buffers have one row per stamp (n ≥ 1).
fn integrate_pieces(t_ns: &[i64], gyro: &[Vec3], acc: &[Vec3], out: PreintegratedMut<'_>) {
    let n = t_ns.len();
    let pieces = (rayon::current_num_threads().min(n / MIN_PIECE)).max(1);
    // Piece c writes rows bounds[c]+1 ..= bounds[c+1] (row 0 is the identity).
    let bounds: Vec<usize> = (0..=pieces).map(|c| c * (n - 1) / pieces).collect();
    let PreintegratedMut { dq_wxyz, dv, dp, dt } = out;
    dq_wxyz[0] = [1.0, 0.0, 0.0, 0.0];
    dv[0] = [0.0; 3];
    dp[0] = [0.0; 3];
    dt[0] = 0.0;
    if pieces == 1 {
        integrate_rows(
            t_ns,
            gyro,
            acc,
            0,
            &mut dq_wxyz[1..],
            &mut dv[1..],
            &mut dp[1..],
            &mut dt[1..],
        );
        return;
    }
    let mut parts = Vec::with_capacity(pieces);
    let (mut q_rest, mut v_rest, mut p_rest, mut t_rest) =
        (&mut dq_wxyz[1..], &mut dv[1..], &mut dp[1..], &mut dt[1..]);
    for c in 0..pieces {
        let len = bounds[c + 1] - bounds[c];
        let (q, qr) = std::mem::take(&mut q_rest).split_at_mut(len);
        let (v, vr) = std::mem::take(&mut v_rest).split_at_mut(len);
        let (p, pr) = std::mem::take(&mut p_rest).split_at_mut(len);
        let (t, tr) = std::mem::take(&mut t_rest).split_at_mut(len);
        (q_rest, v_rest, p_rest, t_rest) = (qr, vr, pr, tr);
        parts.push((bounds[c], q, v, p, t));
    }
    // 1. Every piece from the identity, in parallel.
    parts.par_iter_mut().for_each(|(k, q, v, p, t)| {
        integrate_rows(t_ns, gyro, acc, *k, q, v, p, t);
    });
    // 2. The state at the start of each piece: the pieces before it, chained.
    let mut starts = Vec::with_capacity(pieces);
    let mut chained = Delta::identity();
    for (_, q, v, p, t) in &parts {
        starts.push(chained);
        let last = q.len() - 1;
        chained = chained.then(&Delta::from_row(q[last], v[last], p[last]), t[last]);
    }
    // 3. Chain every row of pieces 1.. onto its piece's start, in parallel chunks.
    const CHAIN_CHUNK: usize = 4096;
    let mut jobs = Vec::new();
    for ((k, q, v, p, t), s) in parts.into_iter().zip(starts).skip(1) {
        let (mut q, mut v, mut p, mut t, mut row) = (q, v, p, t, k + 1);
        while !t.is_empty() {
            let m = t.len().min(CHAIN_CHUNK);
            let (q0, q1) = q.split_at_mut(m);
            let (v0, v1) = v.split_at_mut(m);
            let (p0, p1) = p.split_at_mut(m);
            let (t0, t1) = t.split_at_mut(m);
            jobs.push((row, s, q0, v0, p0, t0));
            (q, v, p, t, row) = (q1, v1, p1, t1, row + m);
        }
    }
    jobs.par_iter_mut().for_each(|(row, s, q, v, p, t)| {
        for i in 0..t.len() {
            let d = s.then(&Delta::from_row(q[i], v[i], p[i]), t[i]);
            (q[i], v[i], p[i]) = (d.q, d.v, d.p);
            // Row Δt from the stamps, exactly as the one-piece loop gives it.
            t[i] = seconds_between(t_ns[0], t_ns[*row + i]);
        }
    });
}

/// Rows k+1 ..= k+len of the integration that starts at sample `k` from the identity, written to
/// the buffers (of len rows each) with row Δt measured from t_k. The caller has checked inputs.
#[allow(clippy::too_many_arguments)]
fn integrate_rows(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    k: usize,
    dq_wxyz: &mut [QuatWxyz],
    dv: &mut [Vec3],
    dp: &mut [Vec3],
    dt: &mut [f64],
) {
    let len = dt.len();
    let (t, g, a) = (&t_ns[k..=k + len], &gyro[k..k + len], &acc[k..k + len]);
    let out = PreintegratedMut { dq_wxyz, dv, dp, dt };
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, checked just above.
        unsafe { rows_avx2(t, g, a, out) };
        return;
    }
    rows(t, g, a, out);
}

/// `rows` compiled for AVX2: the vectorised passes run four lanes wide instead of SSE2's two
/// (~15% faster). Results are bit-identical to `rows`: without FMA (not enabled, and Rust never
/// fuses a multiply and an add by itself) every operation rounds exactly as in SSE2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn rows_avx2(t: &[i64], g: &[Vec3], a: &[Vec3], out: PreintegratedMut<'_>) {
    rows(t, g, a, out);
}

/// Rows 1..=g.len() over stamps `t` (one more than samples) into `out`.
#[inline(always)]
fn rows(t: &[i64], g: &[Vec3], a: &[Vec3], out: PreintegratedMut<'_>) {
    let len = g.len();
    // Stamps are strictly increasing, so every difference lies in 0..=span. Below 2^52 ns (52
    // days: every real recording) plain subtraction is exact and `exact_f64` converts it (the fast,
    // branch-free case); longer spans take `seconds_between`, which gives the same f64 per pair.
    match t[len].checked_sub(t[0]) {
        Some(span) if span < EXACT_LIMIT => rows_kernel(t, g, a, out, |a, b| exact_f64(b.wrapping_sub(a)) * 1e-9),
        _ => rows_kernel(t, g, a, out, seconds_between),
    }
}

/// Integers below this convert exactly by `exact_f64`.
const EXACT_LIMIT: i64 = 1 << 52;

/// `x as f64` for 0 ≤ x < 2^52, the same value bit for bit (such integers are exact in f64), but
/// as integer OR + float subtraction, which vectorise on AVX2 (there is no vector i64 → f64
/// conversion before AVX-512): the bits of 2^52 with x in the mantissa are the double 2^52 + x.
#[inline(always)]
fn exact_f64(x: i64) -> f64 {
    const TWO52: f64 = 4_503_599_627_370_496.0;
    f64::from_bits(x as u64 | TWO52.to_bits()) - TWO52
}

/// Samples per block of `rows_kernel`: its scratch (15 arrays of this many f64) stays in L1
/// (128 measured ~4 % faster than 256 and 512 on 12k EuRoC samples).
const BLOCK: usize = 128;

/// One block's intermediate results, stored component-wise so that the passes over them are
/// plain loops over arrays (which the compiler vectorises).
struct BlockScratch {
    /// Hold time of each sample [s].
    h: [f64; BLOCK],
    /// Exp(ω·dt) of each sample, w, x, y, z.
    e: [[f64; BLOCK]; 4],
    /// Running rotation: `q[..][i]` before sample i of the block, `q[..][i + 1]` after it.
    q: [[f64; BLOCK + 1]; 4],
    /// Rotated specific force times dt and times ½dt², per axis.
    a_dt: [[f64; BLOCK]; 3],
    a_dt22: [[f64; BLOCK]; 3],
}

/// `Delta::step_exp` over rows, bit for bit, rearranged into passes per block of samples so that
/// only the two true recursions run sample by sample:
///
/// 1. `exp_pass`: dt and Exp(ω·dt) of every sample (independent of the state: vectorised);
/// 2. `rotation_pass`: ΔR ← ΔR·Exp(ω·dt), one quaternion product per sample (latency-bound);
/// 3. `force_pass`: ΔR·a·dt and ΔR·a·½dt² of every sample, the Δq and Δt rows (vectorised);
/// 4. `velocity_pass`: Δγ and Δβ, running sums of those (a few additions per sample).
///
/// In one fused loop the throughput work of 1 and 3 and the two recursions compete for the same
/// execution ports, and the compiler half-vectorises the quaternion product with shuffles on its
/// critical path; separate passes measured ~15% faster (12k EuRoC samples, SSE2).
#[inline(always)]
fn rows_kernel(t: &[i64], g: &[Vec3], a: &[Vec3], out: PreintegratedMut<'_>, seconds: impl Fn(i64, i64) -> f64) {
    let mut s = BlockScratch {
        h: [0.0; BLOCK],
        e: [[0.0; BLOCK]; 4],
        q: [[0.0; BLOCK + 1]; 4],
        a_dt: [[0.0; BLOCK]; 3],
        a_dt22: [[0.0; BLOCK]; 3],
    };
    let mut d = Delta::identity();
    let t0 = t[0];
    let PreintegratedMut { dq_wxyz, dv, dp, dt } = out;
    let blocks = g
        .chunks(BLOCK)
        .zip(a.chunks(BLOCK))
        .zip(dq_wxyz.chunks_mut(BLOCK))
        .zip(dv.chunks_mut(BLOCK).zip(dp.chunks_mut(BLOCK)))
        .zip(dt.chunks_mut(BLOCK));
    for (b, ((((gb, ab), qb), (vb, pb)), tb)) in blocks.enumerate() {
        let stamps = &t[b * BLOCK..=b * BLOCK + gb.len()];
        exp_pass(&mut s, stamps, gb, &seconds);
        rotation_pass(&mut s, &mut d.q, qb);
        force_pass(&mut s, ab);
        velocity_pass(&s, &mut d, vb, pb);
        for (row, w) in tb.iter_mut().zip(stamps.windows(2)) {
            *row = seconds(t0, w[1]);
        }
    }
}

/// Hold times and Exp(ω·dt) of a block; `t` has one stamp more than `g` has samples.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // indexing pre-cut slices lets the compiler vectorise
fn exp_pass(s: &mut BlockScratch, t: &[i64], g: &[Vec3], seconds: &impl Fn(i64, i64) -> f64) {
    let m = g.len().min(BLOCK);
    let (t, g) = (&t[..=m], &g[..m]);
    let (h, [ew, ex, ey, ez]) = (&mut s.h[..m], &mut s.e);
    let (ew, ex, ey, ez) = (&mut ew[..m], &mut ex[..m], &mut ey[..m], &mut ez[..m]);
    let mut large = false;
    for i in 0..m {
        let hi = seconds(t[i], t[i + 1]);
        let phi = [g[i][0] * hi, g[i][1] * hi, g[i][2] * hi];
        let theta2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2];
        // `so3::exp_wxyz`'s series branch, taken for every sample (so the loop has no branch);
        // the rare large angles are redone below with the library's own function.
        let (sinc, cos) = so3::exp_series(theta2);
        large |= !so3::exp_series_holds(theta2);
        (h[i], ew[i], ex[i], ey[i], ez[i]) = (hi, cos, sinc * phi[0], sinc * phi[1], sinc * phi[2]);
    }
    if large {
        for i in 0..m {
            let hi = h[i];
            [ew[i], ex[i], ey[i], ez[i]] = so3::exp_wxyz([g[i][0] * hi, g[i][1] * hi, g[i][2] * hi]);
        }
    }
}

/// ΔR ← ΔR·Exp(ω·dt) over the block's samples, recording ΔR before and after each, and the Δq
/// rows (ΔR after each sample). Stored component-wise: storing whole quaternions invites the
/// compiler to pair up the product's components in vector registers, which puts shuffles on this
/// latency-bound chain. The row stores ride along (they are off the chain).
#[inline(always)]
fn rotation_pass(s: &mut BlockScratch, q: &mut QuatWxyz, dq_rows: &mut [QuatWxyz]) {
    let m = dq_rows.len().min(BLOCK);
    let [qw, qx, qy, qz] = &mut s.q;
    let [ew, ex, ey, ez] = &s.e;
    (qw[0], qx[0], qy[0], qz[0]) = (q[0], q[1], q[2], q[3]);
    for (i, row) in dq_rows[..m].iter_mut().enumerate() {
        *q = qmul(*q, [ew[i], ex[i], ey[i], ez[i]]);
        (qw[i + 1], qx[i + 1], qy[i + 1], qz[i + 1]) = (q[0], q[1], q[2], q[3]);
        *row = *q;
    }
}

/// ΔR·a·dt and ΔR·a·½dt² with ΔR before each sample.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // indexing pre-cut slices lets the compiler vectorise
fn force_pass(s: &mut BlockScratch, a: &[Vec3]) {
    let m = a.len().min(BLOCK);
    let (a, h) = (&a[..m], &s.h[..m]);
    let [qw, qx, qy, qz] = &s.q;
    let (qw, qx, qy, qz) = (&qw[..m], &qx[..m], &qy[..m], &qz[..m]);
    let ([ax, ay, az], [bx, by, bz]) = (&mut s.a_dt, &mut s.a_dt22);
    let (ax, ay, az) = (&mut ax[..m], &mut ay[..m], &mut az[..m]);
    let (bx, by, bz) = (&mut bx[..m], &mut by[..m], &mut bz[..m]);
    for i in 0..m {
        let dt22 = 0.5 * h[i] * h[i];
        let r = rotate([qw[i], qx[i], qy[i], qz[i]], a[i]);
        (ax[i], ay[i], az[i]) = (r[0] * h[i], r[1] * h[i], r[2] * h[i]);
        (bx[i], by[i], bz[i]) = (r[0] * dt22, r[1] * dt22, r[2] * dt22);
    }
}

/// Δγ ← Δγ + Δβ·dt + ½·ΔR·a·dt², Δβ ← Δβ + ΔR·a·dt, as in `Delta::step_exp`, and their rows.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // indexing pre-cut slices lets the compiler vectorise
fn velocity_pass(s: &BlockScratch, d: &mut Delta, dv_rows: &mut [Vec3], dp_rows: &mut [Vec3]) {
    let m = dv_rows.len().min(dp_rows.len()).min(BLOCK);
    let (dv_rows, dp_rows, h) = (&mut dv_rows[..m], &mut dp_rows[..m], &s.h[..m]);
    let ([ax, ay, az], [bx, by, bz]) = (&s.a_dt, &s.a_dt22);
    let (ax, ay, az) = (&ax[..m], &ay[..m], &az[..m]);
    let (bx, by, bz) = (&bx[..m], &by[..m], &bz[..m]);
    let (mut v, mut p) = (d.v, d.p);
    for i in 0..m {
        let (a_dt, a_dt22) = ([ax[i], ay[i], az[i]], [bx[i], by[i], bz[i]]);
        for c in 0..3 {
            p[c] += v[c] * h[i] + a_dt22[c];
            v[c] += a_dt[c];
        }
        (dv_rows[i], dp_rows[i]) = (v, p);
    }
    (d.v, d.p) = (v, p);
}

/// Preintegrate samples given by hold times: `dt[i]` [s] is how long sample i is held. N samples
/// give N + 1 rows (row 0 the identity, row N after every sample); row dt is the running sum,
/// as GTSAM's `deltaTij`.
pub fn preintegrate_dt(dt: &[f64], gyro: &[Vec3], acc: &[Vec3]) -> Result<Preintegrated> {
    check_lengths("dt", dt.len(), gyro, acc)?;
    if let Some(i) = dt.iter().position(|&h| !(h.is_finite() && h > 0.0)) {
        return Err(ImuError::invalid(format!(
            "dt[{i}] = {} is not a finite positive hold time",
            dt[i]
        )));
    }
    check_finite(gyro, acc)?;
    let mut out = Preintegrated::with_capacity(dt.len() + 1);
    let mut d = Delta::identity();
    let mut t = 0.0;
    out.push(d.increment(t));
    for ((&h, &w), &a) in dt.iter().zip(gyro).zip(acc) {
        d.step(w, a, h);
        t += h;
        out.push(d.increment(t));
    }
    Ok(out)
}

/// IMU-side increments for many windows, laid out as `labels::labels_at` lays out the ground-truth
/// ones (entry `w * horizons.len() + h` is window `w`, horizon `h`), so the two compare entry by
/// entry. Window start k at horizon n integrates samples k..k+n-1 over [t_k, t_{k+n}], and equals
/// row n of `preintegrate` on the stamps k..=k+n bit for bit. Windows run in parallel.
///
/// The arguments are checked before anything is allocated (`labels::check_windows`): horizons in
/// 1..=len−1, starts leaving room for the longest one. No starts give no windows (an empty result).
pub fn integrate_windows(
    t_ns: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    starts: &[usize],
    horizons: &[usize],
) -> Result<Labels> {
    check_imu(t_ns, gyro, acc)?;
    // Every argument is checked before anything is sized by it: `wanted` below has max_h + 1
    // entries, so an unchecked horizon of 2^40 (or a negative one cast to u64) would abort.
    let max_h = check_windows(t_ns.len(), starts, horizons)?;
    if starts.is_empty() {
        return Ok(Labels {
            horizons: horizons.to_vec(),
            ..Labels::default()
        });
    }
    // Horizon index for each row 0..=max_h that is asked for (several horizons may share a row).
    let mut wanted: Vec<Vec<usize>> = vec![Vec::new(); max_h + 1];
    for (h, &n) in horizons.iter().enumerate() {
        wanted[n].push(h);
    }
    let nh = horizons.len();
    // Every buffer is reserved fallibly before any work: windows × horizons past memory is an error
    // naming them, never an abort.
    let total = starts
        .len()
        .checked_mul(nh)
        .ok_or_else(|| ImuError::invalid(format!("{} windows × {nh} horizons overflow", starts.len())))?;
    let alloc = |what: &str| {
        ImuError::invalid(format!(
            "{} windows × {nh} horizons: {what} ({total} entries) cannot be allocated",
            starts.len()
        ))
    };
    let identity = Increment {
        dq_wxyz: [1.0, 0.0, 0.0, 0.0],
        dv: [0.0; 3],
        dp: [0.0; 3],
        dt: 0.0,
    };
    let mut incs: Vec<Increment> = Vec::new();
    incs.try_reserve_exact(total).map_err(|_| alloc("the increments"))?;
    incs.resize(total, identity);
    let mut out = Labels {
        starts: starts.to_vec(),
        horizons: horizons.to_vec(),
        ..Labels::default()
    };
    out.dq_wxyz.try_reserve_exact(total).map_err(|_| alloc("dq_wxyz"))?;
    out.dv.try_reserve_exact(total).map_err(|_| alloc("dv"))?;
    out.dp.try_reserve_exact(total).map_err(|_| alloc("dp"))?;
    out.dt.try_reserve_exact(total).map_err(|_| alloc("dt"))?;
    let one = |(chunk, &k): (&mut [Increment], &usize)| {
        integrate_from(t_ns, gyro, acc, k, max_h, |j, inc| {
            for &h in &wanted[j] {
                chunk[h] = inc;
            }
        });
    };
    if nh > 0 {
        if crate::par::parallel() {
            incs.par_chunks_mut(nh).zip(starts.par_iter()).for_each(one);
        } else {
            incs.chunks_mut(nh).zip(starts.iter()).for_each(one);
        }
    }
    for inc in incs {
        out.dq_wxyz.push(inc.dq_wxyz);
        out.dv.push(inc.dv);
        out.dp.push(inc.dp);
        out.dt.push(inc.dt);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::so3::quat_to_wxyz;

    fn is_invalid<T: std::fmt::Debug>(r: Result<T>, needle: &str) {
        match r {
            Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(needle), "{msg:?} lacks {needle:?}"),
            other => panic!("expected InvalidInput containing {needle:?}, got {other:?}"),
        }
    }

    #[test]
    fn empty_input_gives_empty_output() {
        let p = preintegrate(&[], &[], &[]).unwrap();
        assert!(p.is_empty());
        let p = preintegrate_dt(&[], &[], &[]).unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!(p.row(0).unwrap().dq_wxyz, [1.0, 0.0, 0.0, 0.0]);
        let l = integrate_windows(&[], &[], &[], &[], &[]).unwrap();
        assert!(l.dq_wxyz.is_empty());
        let t = [0, 1, 2, 3];
        let l = integrate_windows(&t, &[[0.0; 3]; 4], &[[0.0; 3]; 4], &[], &[1, 3]).unwrap();
        assert!(l.dq_wxyz.is_empty() && l.starts.is_empty());
        assert_eq!(l.horizons, vec![1, 3]);
    }

    #[test]
    fn one_stamp_gives_the_identity_row_only() {
        let p = preintegrate(&[5], &[[1.0, 2.0, 3.0]], &[[4.0, 5.0, 6.0]]).unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!(
            p.row(0).unwrap(),
            Increment {
                dq_wxyz: [1.0, 0.0, 0.0, 0.0],
                dv: [0.0; 3],
                dp: [0.0; 3],
                dt: 0.0
            }
        );
        assert!(p.row(1).is_none());
    }

    #[test]
    fn first_step_uses_the_initial_rotation_for_velocity_and_position() {
        // With ΔR = I before the first sample, Δβ = a·dt and Δγ = ½·a·dt² whatever the gyro says.
        let a = [0.3, -1.2, 9.0];
        let p = preintegrate(&[0, 10_000_000], &[[5.0, -4.0, 3.0], [0.0; 3]], &[a, [0.0; 3]]).unwrap();
        let dt = 0.01;
        assert_eq!(p.dv[1], a.map(|x| x * dt));
        assert_eq!(p.dp[1], a.map(|x| x * (0.5 * dt * dt)));
        let want = quat_to_wxyz(&so3::exp(&(Vector3::new(5.0, -4.0, 3.0) * dt)));
        assert_eq!(p.dq_wxyz[1], want);
        assert_eq!(p.dt[1], dt);
    }

    #[test]
    fn rejects_bad_lengths_stamps_and_values() {
        let z = [0.0; 3];
        is_invalid(preintegrate(&[0, 1], &[z], &[z, z]), "gyro has 1");
        is_invalid(
            preintegrate(&[0, 1, 1], &[z; 3], &[z; 3]),
            "t_ns[2] = 1 is not after t_ns[1]",
        );
        is_invalid(preintegrate(&[0, 2, 1], &[z; 3], &[z; 3]), "strictly increasing");
        is_invalid(preintegrate(&[0, 1], &[z, [0.0, f64::NAN, 0.0]], &[z; 2]), "gyro[1]");
        is_invalid(
            preintegrate(&[0, 1], &[z; 2], &[[f64::INFINITY, 0.0, 0.0], z]),
            "acc[0]",
        );
        is_invalid(preintegrate_dt(&[0.1], &[z; 2], &[z; 2]), "dt has 1");
        is_invalid(preintegrate_dt(&[0.1, 0.0], &[z; 2], &[z; 2]), "dt[1]");
        is_invalid(preintegrate_dt(&[-0.1], &[z], &[z]), "dt[0]");
        is_invalid(preintegrate_dt(&[f64::NAN], &[z], &[z]), "dt[0]");
        is_invalid(
            preintegrate_dt(&[0.1], &[z], &[[0.0, 0.0, f64::NEG_INFINITY]]),
            "acc[0]",
        );
    }

    #[test]
    fn non_finite_samples_anywhere_are_named_and_huge_finite_ones_are_not_errors() {
        // Values are checked after integrating (see `preintegrate_into`): a bad sample deep inside
        // a long input, in either array, must still be found and named.
        let n = 1000;
        let t: Vec<i64> = (0..n as i64).map(|i| i * 5_000_000).collect();
        let (g, a) = (vec![[0.1, -0.2, 0.3]; n], vec![[0.5, 0.0, 9.81]; n]);
        for (i, bad) in [(3, f64::NAN), (517, f64::INFINITY), (998, f64::NEG_INFINITY)] {
            let mut gb = g.clone();
            gb[i][1] = bad;
            is_invalid(preintegrate(&t, &gb, &a), &format!("gyro[{i}]"));
            let mut ab = a.clone();
            ab[i][2] = bad;
            is_invalid(preintegrate(&t, &g, &ab), &format!("acc[{i}]"));
        }
        // Finite inputs whose result overflows are not an input error.
        let big = vec![[f64::MAX, f64::MAX, f64::MAX]; n];
        assert!(preintegrate(&t, &g, &big).is_ok());
    }

    #[test]
    fn window_ranges_are_checked_without_overflow() {
        let z = [0.0; 3];
        let t = [0, 1, 2, 3];
        is_invalid(
            integrate_windows(&t, &[z; 4], &[z; 4], &[1], &[3]),
            "window start 1 + horizon 3",
        );
        is_invalid(
            integrate_windows(&t, &[z; 4], &[z; 4], &[usize::MAX], &[1]),
            "past the sequence end",
        );
        is_invalid(integrate_windows(&t, &[z; 4], &[z; 4], &[4], &[]), "window start 4");
        assert!(integrate_windows(&t, &[z; 4], &[z; 4], &[0], &[3]).is_ok());
    }

    #[test]
    fn window_arguments_are_checked_before_anything_is_allocated() {
        // Without starts nothing is integrated, but the horizons are still checked: a horizon of
        // 2^40 (or usize::MAX, a negative one cast) used to size a Vec of max_h + 1 entries first.
        let z = [0.0; 3];
        let t = [0, 1, 2, 3];
        for huge in [1usize << 40, usize::MAX, usize::MAX - 1] {
            is_invalid(
                integrate_windows(&t, &[z; 4], &[z; 4], &[], &[2, huge]),
                &format!("horizons[1] = {huge} is past the sequence end"),
            );
            is_invalid(
                integrate_windows(&t, &[z; 4], &[z; 4], &[0], &[huge]),
                "allows horizons 1..=3",
            );
        }
        is_invalid(
            integrate_windows(&t, &[z; 4], &[z; 4], &[], &[0]),
            "horizons[0] = 0: a horizon must be at least 1 sample",
        );
        is_invalid(integrate_windows(&t, &[z; 4], &[z; 4], &[0], &[4]), "horizons[0] = 4");
        is_invalid(integrate_windows(&[], &[], &[], &[], &[1]), "no horizon fits");
        is_invalid(integrate_windows(&[7], &[z], &[z], &[], &[1]), "no horizon fits");
        is_invalid(
            integrate_windows(&t, &[z; 4], &[z; 4], &[0, 1, 2], &[2]),
            "starts[2]: window start 2 + horizon 2",
        );
        // Lengths are checked first of all.
        is_invalid(integrate_windows(&t, &[z; 3], &[z; 4], &[], &[1 << 40]), "gyro has 3");
        assert_eq!(
            integrate_windows(&t, &[z; 4], &[z; 4], &[0, 1], &[2, 1])
                .unwrap()
                .dt
                .len(),
            4
        );
    }

    #[test]
    fn extreme_stamps_do_not_overflow() {
        let z = [0.0; 3];
        let t = [i64::MIN, 0, i64::MAX];
        let p = preintegrate(&t, &[z; 3], &[[1.0, 0.0, 0.0]; 3]).unwrap();
        let total = (i64::MAX as f64 - i64::MIN as f64) * 1e-9;
        assert!((p.dt[2] - total).abs() <= 1e-12 * total);
    }

    #[test]
    fn every_stamp_conversion_matches_the_hold_time_path() {
        // Spans below 2^52 ns, up to i64::MAX, and beyond it take the three ways of turning
        // stamp differences into seconds; each must give what the hold-time path gives.
        let gyro: Vec<Vec3> = (0..6).map(|i| [0.1 * i as f64, -0.2, 0.05]).collect();
        let acc: Vec<Vec3> = (0..6).map(|i| [1.0, 0.1 * i as f64, 9.8]).collect();
        for step in [5_000_000_i64, 1 << 50, i64::MAX / 8] {
            let t: Vec<i64> = (0..6).map(|i| -2 * step + i * step + (i * i) % 3).collect();
            let hold: Vec<f64> = t.windows(2).map(|w| seconds_between(w[0], w[1])).collect();
            let p = preintegrate(&t, &gyro, &acc).unwrap();
            let q = preintegrate_dt(&hold, &gyro[..5], &acc[..5]).unwrap();
            assert_eq!((&p.dq_wxyz, &p.dv, &p.dp), (&q.dq_wxyz, &q.dv, &q.dp), "step {step}");
        }
    }

    #[test]
    fn horizons_in_any_order_and_repeated_land_in_their_own_columns() {
        let t: Vec<i64> = (0..12).map(|i| i * 5_000_000 + (i * i) % 7 * 100_000).collect();
        let gyro: Vec<Vec3> = (0..12).map(|i| [0.1 * i as f64, -0.2, 0.05]).collect();
        let acc: Vec<Vec3> = (0..12).map(|i| [1.0, 0.1 * i as f64, 9.8]).collect();
        let hs = [4, 1, 2, 4];
        let l = integrate_windows(&t, &gyro, &acc, &[3, 0], &hs).unwrap();
        for (w, &k) in [3usize, 0].iter().enumerate() {
            let p = preintegrate(&t[k..], &gyro[k..], &acc[k..]).unwrap();
            for (h, &n) in hs.iter().enumerate() {
                let e = w * hs.len() + h;
                let got = Increment {
                    dq_wxyz: l.dq_wxyz[e],
                    dv: l.dv[e],
                    dp: l.dp[e],
                    dt: l.dt[e],
                };
                assert_eq!(Some(got), p.row(n));
            }
        }
    }

    #[test]
    fn long_inputs_integrated_in_pieces_match_the_plain_loop() {
        // Three pieces of 8192+ samples on three threads; one thread gives the plain loop.
        let n = 3 * MIN_PIECE + 101;
        let t: Vec<i64> = (0..n as i64)
            .map(|i| 1_403_636_580_000_000_000 + i * 5_000_000 + (i * i) % 13 * 1000)
            .collect();
        let gyro: Vec<Vec3> = (0..n)
            .map(|i| [(i as f64 * 1e-3).sin(), 0.3, -0.2 * (i as f64 * 7e-4).cos()])
            .collect();
        let acc: Vec<Vec3> = (0..n).map(|i| [0.5, (i as f64 * 2e-3).cos(), 9.81]).collect();
        let hold: Vec<f64> = t.windows(2).map(|w| seconds_between(w[0], w[1])).collect();
        let plain = preintegrate_dt(&hold, &gyro[..n - 1], &acc[..n - 1]).unwrap();
        let pool = |k| rayon::ThreadPoolBuilder::new().num_threads(k).build().unwrap();
        let one = pool(1).install(|| preintegrate(&t, &gyro, &acc)).unwrap();
        let three = pool(3).install(|| preintegrate(&t, &gyro, &acc)).unwrap();
        assert_eq!((&one.dq_wxyz, &one.dv, &one.dp), (&plain.dq_wxyz, &plain.dv, &plain.dp));
        let first_piece = (n - 1) / 3;
        for j in 0..n {
            assert_eq!(three.dt[j], seconds_between(t[0], t[j]));
            assert_eq!(one.dt[j], three.dt[j]);
            let close = |a: &[f64], b: &[f64], scale: f64| {
                a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-12 * scale.max(1.0))
            };
            let scale = one.dp[j].iter().chain(&one.dv[j]).fold(0.0f64, |m, x| m.max(x.abs()));
            if j <= first_piece {
                assert_eq!(three.row(j), one.row(j), "row {j}");
            } else {
                assert!(close(&three.dq_wxyz[j], &one.dq_wxyz[j], 1.0), "row {j}");
                assert!(close(&three.dv[j], &one.dv[j], scale), "row {j}");
                assert!(close(&three.dp[j], &one.dp[j], scale), "row {j}");
            }
        }
    }

    #[test]
    fn exact_f64_is_as_f64_below_two_to_the_52() {
        for x in [
            0,
            1,
            2,
            4_999_999,
            5_000_000,
            123_456_789_012,
            EXACT_LIMIT - 2,
            EXACT_LIMIT - 1,
        ] {
            assert_eq!(exact_f64(x).to_bits(), (x as f64).to_bits(), "{x}");
        }
        let mut x: i64 = 0x2545_f491_4f6c_dd1d;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let y = x.rem_euclid(EXACT_LIMIT);
            assert_eq!(exact_f64(y).to_bits(), (y as f64).to_bits(), "{y}");
        }
    }
}
