//! Ground truth onto IMU stamps: one `Sequence` per stretch of continuous ground truth.
//!
//! Labels (Δq/Δβ/Δγ) need p, v and q at every IMU stamp. Ground truth comes on its own clock
//! (EuRoC TUM files at 200 Hz, BROAD optical capture with gaps where markers were lost,
//! Blackbird already at the IMU stamps), so alignment does three things:
//!
//! 1. **Split at gaps.** Consecutive GT stamps further apart than `max_gap_ns` end one GT segment
//!    and start the next. Nothing is interpolated across a gap: a missing stretch of motion capture
//!    can hide any motion, and a label that straddles it would be invented. Each GT segment yields
//!    its own `Sequence`, so a training window never spans a gap either.
//! 2. **Velocity.** Pose-only ground truth (EuRoC TUM, BROAD) has no velocity, yet Δβ and Δγ
//!    depend on it directly. Central differences of positions amplify position noise by
//!    ~1/(√2·Δt) — 140×/s at 200 Hz, so 0.1 mm of tracker noise becomes 14 mm/s of velocity
//!    noise. `derive_velocity` instead fits a quadratic in time to ±`half_window` samples by least
//!    squares and takes its slope at the centre. A wider window averages out more noise but
//!    flattens fast motion (the fit cannot follow jerk), so the half window sets the noise floor of
//!    every Δβ/Δγ label; see `AlignOptions::default` for the numbers. Velocity is derived per GT
//!    segment, never across a gap.
//! 3. **Interpolate** at each IMU stamp inside a GT segment, between the two bracketing GT stamps:
//!    rotation by slerp (exact for rotation about a fixed axis at a constant rate), position by
//!    the cubic Hermite spline through p and v at both ends (exact for quadratic position with
//!    exact velocities), velocity linearly. Velocity is deliberately *not* the Hermite curve's
//!    derivative: that derivative weights the raw position difference (p₁ − p₀)/Δt by up to 1.5,
//!    re-introducing exactly the finite-difference noise the derivation above removed; linear
//!    interpolation of the smoothed velocities errs only by O(Δt²·jerk), microns per second at
//!    200 Hz. IMU stamps that coincide with a GT stamp copy that GT row unchanged.
//!
//! IMU samples outside the GT span, inside gaps, or in segments shorter than
//! `min_segment_samples` are dropped; `AlignReport` counts each kind so a caller can tell a crop
//! from a broken recording.

use std::path::PathBuf;

use crate::error::{ImuError, Result};
use crate::so3::{quat_from_wxyz, quat_to_wxyz, slerp};
use crate::types::{GroundTruth, ImuSamples, QuatWxyz, Sequence, Vec3};

/// Settings of `align`.
#[derive(Clone, Debug, PartialEq)]
pub struct AlignOptions {
    /// GT stamps further apart than this [ns] are a gap: the GT is split there.
    pub max_gap_ns: i64,
    /// Aligned segments with fewer IMU samples are dropped. At least 2.
    pub min_segment_samples: usize,
    /// Half width, in GT samples, of the quadratic fit that derives velocity from pose-only GT.
    /// 0 is treated as 1 (a fit needs three points).
    pub velocity_half_window: usize,
}

impl Default for AlignOptions {
    /// - `max_gap_ns` = 50 ms. Nominal GT spacing is 3.5–10 ms (BROAD 285.7 Hz, EuRoC 200 Hz,
    ///   Blackbird 100 Hz), so this tolerates a handful of lost GT rows. Across a hole of length h,
    ///   slerp errs by about α·h²/8 for angular acceleration α: 1.6 mrad for α = 5 rad/s² at 50 ms,
    ///   about the orientation noise of optical tracking. Longer holes are split, not bridged.
    /// - `min_segment_samples` = 2, the least that holds one IMU interval. The window length is a
    ///   training choice not known here, and `batch` already ignores sequences shorter than a
    ///   window, so dropping more here would only lose data.
    /// - `velocity_half_window` = 4: a 9-sample fit, ±20 ms at 200 Hz. On uniform stamps the slope
    ///   of the symmetric quadratic fit has noise σ/(Δt·√Σj²) = σ/(Δt·√60), 5.5× lower than central
    ///   differences (0.1 mm position noise → 2.6 mm/s), and its bias from jerk J is
    ///   J·Δt²·Σj⁴/(6·Σj²) ≈ 4.9e-5 s²·J, 2.5 mm/s even at J = 50 m/s³ (aggressive flight). The
    ///   two error terms balance near this width; halving or doubling it makes one of them
    ///   dominate.
    fn default() -> Self {
        AlignOptions {
            max_gap_ns: 50_000_000,
            min_segment_samples: 2,
            velocity_half_window: 4,
        }
    }
}

/// One aligned stretch: the `Sequence` at the same index in `align`'s output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Segment {
    /// First and last IMU stamp [ns] of the aligned sequence.
    pub start_ns: i64,
    pub end_ns: i64,
    /// IMU samples in it.
    pub samples: usize,
}

/// What `align` kept and dropped. Every IMU sample is counted exactly once:
/// `imu_samples = kept + dropped_before + dropped_after + dropped_in_gaps + dropped_short`,
/// with `kept` the sum of `segments[i].samples`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct AlignReport {
    /// IMU samples passed in.
    pub imu_samples: usize,
    /// Before the first GT stamp.
    pub dropped_before: usize,
    /// After the last GT stamp.
    pub dropped_after: usize,
    /// Between GT segments (in a gap, or at a lone GT pose that cannot be interpolated).
    pub dropped_in_gaps: usize,
    /// In aligned segments shorter than `min_segment_samples`.
    pub dropped_short: usize,
    /// Each gap as (last GT stamp before it, first GT stamp after it) [ns].
    pub gaps: Vec<(i64, i64)>,
    /// The kept segments, in time order.
    pub segments: Vec<Segment>,
    /// True when the GT had no velocity and `derive_velocity` supplied it.
    pub velocity_derived: bool,
}

impl AlignReport {
    /// IMU samples that made it into a sequence.
    pub fn kept(&self) -> usize {
        self.segments.iter().map(|s| s.samples).sum()
    }
}

/// Velocity [unit of p per second] at each stamp, from a least-squares quadratic in time fitted to
/// the samples within ±`half_window` (clipped at the ends, so the fit becomes one-sided there,
/// but never fewer than three points); the slope at the centre stamp. Non-uniform stamps are fine. Exact for quadratic positions.
///
/// Stamps must be strictly increasing. If `t_ns` and `p` differ in length, only the common prefix
/// is used (`align` checks lengths before calling). With a single sample the velocity is zero,
/// with two the slope of the line through them.
pub fn derive_velocity(t_ns: &[i64], p: &[Vec3], half_window: usize) -> Vec<Vec3> {
    let n = t_ns.len().min(p.len());
    let h = half_window.max(1);
    (0..n)
        .map(|i| {
            let mut lo = i.saturating_sub(h);
            let mut hi = i.saturating_add(h).min(n - 1);
            // A clipped end window of two points would fall back to a line, which is biased by
            // acceleration; stretch it inwards to three so the ends stay exact for quadratics.
            if hi - lo < 2 && n >= 3 {
                if lo == 0 {
                    hi = 2;
                } else {
                    lo = hi.saturating_sub(2);
                }
            }
            fit_slope(&t_ns[lo..=hi], &p[lo..=hi], t_ns[i], p[i])
        })
        .collect()
}

/// Slope at `tc` of the least-squares quadratic through (t, p). Times are taken relative to `tc`
/// and scaled to [-1, 1], and positions relative to `pc`, so the normal equations stay well
/// conditioned with epoch-nanosecond stamps and metre-scale positions moving by millimetres.
fn fit_slope(t: &[i64], p: &[Vec3], tc: i64, pc: Vec3) -> Vec3 {
    let m = t.len();
    if m < 2 {
        return [0.0; 3];
    }
    let tau: Vec<f64> = t.iter().map(|&s| (s - tc) as f64 * 1e-9).collect();
    let scale = tau.iter().fold(0.0_f64, |a, &x| a.max(x.abs()));
    if scale <= 0.0 {
        return [0.0; 3];
    }
    let u: Vec<f64> = tau.iter().map(|&x| x / scale).collect();
    let mut s = [0.0_f64; 5];
    let mut r = [[0.0_f64; 3]; 3]; // r[k][axis] = Σ u^k (p − pc)
    for (j, &uj) in u.iter().enumerate() {
        let mut pw = 1.0;
        for (k, sk) in s.iter_mut().enumerate() {
            *sk += pw;
            if k < 3 {
                for a in 0..3 {
                    r[k][a] += pw * (p[j][a] - pc[a]);
                }
            }
            pw *= uj;
        }
    }
    let mut out = [0.0; 3];
    if m >= 3 {
        let lu = nalgebra::Matrix3::new(s[0], s[1], s[2], s[1], s[2], s[3], s[2], s[3], s[4]).lu();
        let mut solved = true;
        for ax in 0..3 {
            match lu.solve(&nalgebra::Vector3::new(r[0][ax], r[1][ax], r[2][ax])) {
                Some(c) if c[1].is_finite() => out[ax] = c[1] / scale,
                _ => solved = false,
            }
        }
        if solved {
            return out;
        }
    }
    // Too few or degenerate points for a quadratic: least-squares line.
    let det = s[0] * s[2] - s[1] * s[1];
    if det.abs() > 0.0 {
        for ax in 0..3 {
            out[ax] = (s[0] * r[1][ax] - s[1] * r[0][ax]) / det / scale;
        }
    } else {
        out = [0.0; 3];
    }
    out
}

/// The files the IMU and the ground truth were read from, so that alignment errors can name them;
/// `None` for arrays that came from elsewhere.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Sources {
    pub imu: Option<PathBuf>,
    pub gt: Option<PathBuf>,
}

impl Sources {
    /// "IMU <path>: " / "ground truth <path>: " prefixes for messages, empty when unknown.
    fn prefix(&self) -> String {
        let mut out = String::new();
        if let Some(p) = &self.imu {
            out += &format!("IMU {}", p.display());
        }
        if let Some(p) = &self.gt {
            out += &format!("{}ground truth {}", if out.is_empty() { "" } else { ", " }, p.display());
        }
        if out.is_empty() {
            out
        } else {
            out + ": "
        }
    }
}

/// Put `gt` onto the IMU stamps. Returns one `Sequence` per GT segment (see module docs) that
/// holds at least `opts.min_segment_samples` IMU samples, and a report of what was dropped.
///
/// There is no gravity argument: alignment is kinematics only; `labels` applies gravity later.
///
/// Errors: `InvalidInput` for arrays of mismatched length, non-increasing stamps or bad options;
/// `NoOverlap` when IMU and GT do not overlap in time; `Alignment` when GT has fewer than 2 poses
/// or when no segment survives.
pub fn align(imu: &ImuSamples, gt: &GroundTruth, opts: &AlignOptions) -> Result<(Vec<Sequence>, AlignReport)> {
    align_from(imu, gt, opts, &Sources::default())
}

/// `align`, with errors that name the files in `sources`.
pub fn align_from(
    imu: &ImuSamples,
    gt: &GroundTruth,
    opts: &AlignOptions,
    sources: &Sources,
) -> Result<(Vec<Sequence>, AlignReport)> {
    check_inputs(imu, gt, opts, sources)?;
    let tg = &gt.t_ns;
    let ti = &imu.t_ns;
    let (g0, g1) = (tg[0], tg[tg.len() - 1]);
    let (i0, i1) = (ti[0], ti[ti.len() - 1]);
    if i1 < g0 || i0 > g1 {
        return Err(ImuError::NoOverlap {
            imu: sources.imu.clone(),
            gt: sources.gt.clone(),
            imu_span_ns: (i0, i1),
            gt_span_ns: (g0, g1),
        });
    }

    let mut report = AlignReport {
        imu_samples: ti.len(),
        ..AlignReport::default()
    };
    report.dropped_before = ti.partition_point(|&t| t < g0);
    report.dropped_after = ti.len() - ti.partition_point(|&t| t <= g1);

    // GT segments as index ranges [a, b] into gt.
    let mut ranges = Vec::new();
    let mut a = 0;
    for k in 1..tg.len() {
        if tg[k] - tg[k - 1] > opts.max_gap_ns {
            report.gaps.push((tg[k - 1], tg[k]));
            ranges.push((a, k - 1));
            a = k;
        }
    }
    ranges.push((a, tg.len() - 1));

    report.velocity_derived = gt.v.is_none();
    let mut seqs = Vec::new();
    let mut covered = 0usize;
    let mut longest_short = 0usize;
    for &(a, b) in &ranges {
        if b == a {
            continue; // a lone pose: nothing to interpolate between
        }
        let (ts, te) = (tg[a], tg[b]);
        let lo = ti.partition_point(|&t| t < ts);
        let hi = ti.partition_point(|&t| t <= te);
        let count = hi - lo;
        covered += count;
        if count < opts.min_segment_samples {
            report.dropped_short += count;
            longest_short = longest_short.max(count);
            continue;
        }
        let v_seg: Vec<Vec3> = match &gt.v {
            Some(v) => v[a..=b].to_vec(),
            None => derive_velocity(&tg[a..=b], &gt.p[a..=b], opts.velocity_half_window),
        };
        let seq = interpolate_segment(imu, lo, hi, &tg[a..=b], &gt.p[a..=b], &v_seg, &gt.q_wxyz[a..=b]);
        report.segments.push(Segment {
            start_ns: ti[lo],
            end_ns: ti[hi - 1],
            samples: count,
        });
        seqs.push(seq);
    }
    report.dropped_in_gaps = ti.len() - report.dropped_before - report.dropped_after - covered;

    if seqs.is_empty() {
        return Err(ImuError::Alignment(format!(
            "{}no aligned segment has at least {} IMU samples (the longest has {longest_short}; \
             lower the minimum segment length, min_segment_s in Python, to keep shorter ones): of \
             {} IMU samples, {} precede the ground truth, {} follow it, {} fall in its {} gap(s) \
             longer than {} ns, and {} are in segments that are too short",
            sources.prefix(),
            opts.min_segment_samples,
            report.imu_samples,
            report.dropped_before,
            report.dropped_after,
            report.dropped_in_gaps,
            report.gaps.len(),
            opts.max_gap_ns,
            report.dropped_short
        )));
    }
    Ok((seqs, report))
}

fn check_inputs(imu: &ImuSamples, gt: &GroundTruth, opts: &AlignOptions, sources: &Sources) -> Result<()> {
    if opts.max_gap_ns <= 0 {
        return Err(ImuError::invalid(format!(
            "max_gap_ns must be positive, got {}",
            opts.max_gap_ns
        )));
    }
    if opts.min_segment_samples < 2 {
        return Err(ImuError::invalid(format!(
            "min_segment_samples must be at least 2, got {}",
            opts.min_segment_samples
        )));
    }
    let n = imu.t_ns.len();
    if imu.gyro.len() != n || imu.acc.len() != n {
        return Err(ImuError::invalid(format!(
            "IMU arrays differ in length: t_ns {n}, gyro {}, acc {}",
            imu.gyro.len(),
            imu.acc.len()
        )));
    }
    let m = gt.t_ns.len();
    let opt_len = |o: &Option<Vec<Vec3>>| o.as_ref().map_or(m, Vec::len);
    if gt.p.len() != m || gt.q_wxyz.len() != m || opt_len(&gt.v) != m {
        return Err(ImuError::invalid(format!(
            "ground-truth arrays differ in length: t_ns {m}, p {}, q_wxyz {}, v {}",
            gt.p.len(),
            gt.q_wxyz.len(),
            gt.v.as_ref().map_or("none".to_string(), |v| v.len().to_string())
        )));
    }
    if n == 0 {
        return Err(ImuError::invalid(format!("{}no IMU samples", sources.prefix())));
    }
    if m < 2 {
        return Err(ImuError::Alignment(format!(
            "{}ground truth has {m} pose(s); at least 2 are needed to interpolate",
            sources.prefix()
        )));
    }
    strictly_increasing("IMU", &imu.t_ns)?;
    strictly_increasing("ground-truth", &gt.t_ns)?;
    Ok(())
}

fn strictly_increasing(what: &str, t: &[i64]) -> Result<()> {
    match t.windows(2).position(|w| w[1] <= w[0]) {
        Some(k) => Err(ImuError::invalid(format!(
            "{what} stamps must be strictly increasing: row {} ({}) follows {}",
            k + 1,
            t[k + 1],
            t[k]
        ))),
        None => Ok(()),
    }
}

/// Sequence for IMU samples lo..hi, all within [tg[0], tg[last]] of this GT segment.
fn interpolate_segment(
    imu: &ImuSamples,
    lo: usize,
    hi: usize,
    tg: &[i64],
    p: &[Vec3],
    v: &[Vec3],
    q: &[QuatWxyz],
) -> Sequence {
    let count = hi - lo;
    let mut seq = Sequence {
        t_ns: imu.t_ns[lo..hi].to_vec(),
        gyro: imu.gyro[lo..hi].to_vec(),
        acc: imu.acc[lo..hi].to_vec(),
        p: Vec::with_capacity(count),
        v: Vec::with_capacity(count),
        q_wxyz: Vec::with_capacity(count),
    };
    // IMU stamps increase, so the bracket only moves forward.
    let mut j = 0usize;
    for &t in &imu.t_ns[lo..hi] {
        while j + 1 < tg.len() && tg[j + 1] <= t {
            j += 1;
        }
        if tg[j] == t {
            seq.p.push(p[j]);
            seq.v.push(v[j]);
            // Files carry 6-9 digits, so their quaternions are off unit by up to ~1e-5: store unit ones.
            seq.q_wxyz.push(quat_to_wxyz(&quat_from_wxyz(q[j])));
            continue;
        }
        // tg[j] < t < tg[j + 1]; j + 1 exists because t ≤ tg[last] and t ≠ tg[j].
        let k = (j + 1).min(tg.len() - 1);
        let h_ns = tg[k] - tg[j];
        let s = if h_ns > 0 {
            (t - tg[j]) as f64 / h_ns as f64
        } else {
            0.0
        };
        let h = h_ns as f64 * 1e-9;
        let (s2, s3) = (s * s, s * s * s);
        let (h00, h10, h01, h11) = (
            2.0 * s3 - 3.0 * s2 + 1.0,
            s3 - 2.0 * s2 + s,
            3.0 * s2 - 2.0 * s3,
            s3 - s2,
        );
        let mut pi = [0.0; 3];
        let mut vi = [0.0; 3];
        for a in 0..3 {
            pi[a] = h00 * p[j][a] + h10 * h * v[j][a] + h01 * p[k][a] + h11 * h * v[k][a];
            vi[a] = (1.0 - s) * v[j][a] + s * v[k][a];
        }
        let qi = slerp(&quat_from_wxyz(q[j]), &quat_from_wxyz(q[k]), s);
        seq.p.push(pi);
        seq.v.push(vi);
        seq.q_wxyz.push(quat_to_wxyz(&qi));
    }
    seq
}
