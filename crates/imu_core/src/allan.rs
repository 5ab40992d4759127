//! Overlapping Allan deviation of rate samples (gyro rad/s, accelerometer m/s²) and the standard
//! slope fits of an inertial sensor's noise (IEEE Std 952 / 1554).
//!
//! For N samples y_i of period τ0 and a cluster size m (τ = m τ0), with S the cumulative sum
//! (S_0 = 0, S_j = Σ_{i<j} y_i), the overlapping Allan variance is
//!
//! ```text
//! σ²(τ) = 1 / (2 m² (N + 1 - 2m)) Σ_{k=0}^{N-2m} (S_{k+2m} - 2 S_{k+m} + S_k)²
//! ```
//!
//! i.e. half the mean squared difference of adjacent cluster means over every start k. It is the
//! `allantools.oadev` estimator of frequency data (phase x = τ0 S has N + 1 points), O(N) per τ.
//! Each axis' mean is removed before summing (σ² does not change; the sums stay small, so the
//! second differences keep their digits on a long recording with a bias or gravity in it).
//!
//! The fits read three coefficients off the log-log curve:
//! - white noise density N (angle / velocity random walk): the line of slope −1/2 through the
//!   region where the curve's local slope is within ±[`SLOPE_TOLERANCE`] of −1/2, read at τ = 1 s;
//! - rate random walk K: the line of slope +1/2 through the +1/2 region, read at τ = 3 s;
//! - bias instability B: the curve's minimum / sqrt(2 ln 2 / π) (≈ 0.664).
//!
//! The local slope at a τ is the least-squares slope of log σ over log τ within ±0.1 decade
//! ([`SLOPE_HALF_WINDOW_DECADES`]). Only points whose relative error 1/sqrt(2 (N/m − 1)) is at most
//! [`MAX_REL_ERR`] take part (the last few clusters of a recording scatter too much to fit). Of
//! the points within the tolerance, the contiguous run spanning most decades is the region; the
//! line's intercept is the mean of log σ − s log τ over it, every point weighing the same.

use rayon::prelude::*;

use crate::error::{ImuError, Result};

/// Cluster sizes per decade of τ of [`cluster_sizes`]' default set.
pub const DEFAULT_PER_DECADE: usize = 20;

/// How far (in slope) the local log-log slope may be from −1/2 or +1/2 in a fit region.
pub const SLOPE_TOLERANCE: f64 = 0.1;

/// Half width (decades of τ) of the window the local slope is fitted over.
pub const SLOPE_HALF_WINDOW_DECADES: f64 = 0.1;

/// Points less certain than this (relative error of σ) are left out of the fits.
pub const MAX_REL_ERR: f64 = 0.3;

/// sqrt(2 ln 2 / π): the flicker-noise floor of the Allan deviation is this × B.
pub const BIAS_INSTABILITY_FACTOR: f64 = 0.664_282_992_599_827_8;

/// Allan deviation of k axes over one set of cluster sizes.
#[derive(Clone, Debug, Default)]
pub struct AllanDeviation {
    /// Cluster sizes (samples per cluster), increasing.
    pub m: Vec<usize>,
    /// τ = m × period [s].
    pub tau_s: Vec<f64>,
    /// Number of whole clusters N / m (what the error estimate counts).
    pub n_clusters: Vec<usize>,
    /// Approximate relative error of σ: 1 / sqrt(2 (N/m − 1)).
    pub rel_err: Vec<f64>,
    /// σ(τ), row-major (len(m), k).
    pub adev: Vec<f64>,
    /// Number of axes k.
    pub axes: usize,
}

/// `per_decade` log-spaced cluster sizes from 1 to N/2 (rounded, duplicates dropped; N/2 last).
pub fn cluster_sizes(n: usize, per_decade: usize) -> Vec<usize> {
    let max_m = n / 2;
    if max_m == 0 || per_decade == 0 {
        return Vec::new();
    }
    let decades = (max_m as f64).log10();
    let steps = (decades * per_decade as f64).floor() as usize;
    let mut out: Vec<usize> = Vec::with_capacity(steps + 2);
    for j in 0..=steps {
        let m = (10f64.powf(j as f64 / per_decade as f64).round() as usize).clamp(1, max_m);
        if out.last() != Some(&m) {
            out.push(m);
        }
    }
    if out.last() != Some(&max_m) {
        out.push(max_m);
    }
    out
}

/// Approximate relative error of the Allan deviation at cluster size m of n samples.
pub fn relative_error(n: usize, m: usize) -> f64 {
    let clusters = n as f64 / m as f64;
    if clusters > 1.0 {
        1.0 / (2.0 * (clusters - 1.0)).sqrt()
    } else {
        f64::INFINITY
    }
}

/// Cumulative sums (with a leading 0) of column `axis` of the row-major (n, k) `samples`, its
/// mean removed.
fn centred_cumsum(samples: &[f64], k: usize, axis: usize) -> Vec<f64> {
    let n = samples.len() / k;
    let column = || samples.iter().skip(axis).step_by(k);
    let mean = column().sum::<f64>() / n as f64;
    let mut s = Vec::with_capacity(n + 1);
    let mut acc = 0.0;
    s.push(acc);
    for y in column() {
        acc += y - mean;
        s.push(acc);
    }
    s
}

/// Σ (c[i] − 2 b[i] + a[i])² over equal-length slices, in eight lanes (vectorised, and shorter
/// rounding chains than one running sum).
fn second_difference_energy(a: &[f64], b: &[f64], c: &[f64]) -> f64 {
    const L: usize = 8;
    let mut lanes = [0.0f64; L];
    let (ac, bc, cc) = (a.chunks_exact(L), b.chunks_exact(L), c.chunks_exact(L));
    let mut tail = 0.0;
    for ((x, y), z) in ac.remainder().iter().zip(bc.remainder()).zip(cc.remainder()) {
        let d = z - 2.0 * y + x;
        tail += d * d;
    }
    for ((x, y), z) in ac.zip(bc).zip(cc) {
        for l in 0..L {
            let d = z[l] - 2.0 * y[l] + x[l];
            lanes[l] += d * d;
        }
    }
    lanes.iter().sum::<f64>() + tail
}

/// Starts per block of [`second_differences`]: at most 2 MiB of the cumulative sum (it stays in
/// the L2/L3 cache while every cluster size passes over it; measured best among 64 KiB … 4 MiB),
/// and at least 4 blocks per thread.
const MAX_BLOCK: usize = 256 * 1024;
const MIN_BLOCK: usize = 8 * 1024;

/// For each cluster size m, Σ_k (s[k+2m] − 2 s[k+m] + s[k])² over k = 0 … len(s) − 1 − 2m.
/// The starts are cut in blocks and every m runs over one block before the next: the block's
/// own stretch of `s` is read from memory once for all m (only the two shifted streams are not),
/// and the blocks run in parallel. Block sums are added in block order (deterministic).
fn second_differences(s: &[f64], m: &[usize]) -> Vec<f64> {
    let len = s.len();
    let block = (len / (4 * rayon::current_num_threads())).clamp(MIN_BLOCK, MAX_BLOCK);
    let blocks = len.div_ceil(block);
    let partial: Vec<Vec<f64>> = (0..blocks)
        .into_par_iter()
        .map(|blk| {
            let i0 = blk * block;
            m.iter()
                .map(|&mi| {
                    let end = (i0 + block).min(len.saturating_sub(2 * mi));
                    if end <= i0 {
                        return 0.0;
                    }
                    second_difference_energy(&s[i0..end], &s[i0 + mi..end + mi], &s[i0 + 2 * mi..end + 2 * mi])
                })
                .collect()
        })
        .collect();
    (0..m.len()).map(|j| partial.iter().map(|p| p[j]).sum()).collect()
}

/// Overlapping Allan deviation of the row-major (n, `axes`) rate `samples` of period `period_s`
/// at cluster sizes `m` (each 1 ≤ m ≤ n/2; see [`cluster_sizes`]). Axes run one after the other
/// (one cumulative sum in memory), blocks of each in parallel.
pub fn overlapping_adev(samples: &[f64], axes: usize, period_s: f64, m: &[usize]) -> Result<AllanDeviation> {
    if axes == 0 || !samples.len().is_multiple_of(axes) {
        return Err(ImuError::invalid(format!(
            "samples must be (N, k) with k >= 1; got {} values for k = {axes}",
            samples.len()
        )));
    }
    let n = samples.len() / axes;
    if !(period_s.is_finite() && period_s > 0.0) {
        return Err(ImuError::invalid(format!(
            "period_s = {period_s} must be positive and finite"
        )));
    }
    if n < 2 {
        return Err(ImuError::invalid(format!(
            "the Allan deviation needs at least 2 samples (two clusters of one), got {n}"
        )));
    }
    if let Some(i) = samples.iter().position(|x| !x.is_finite()) {
        return Err(ImuError::invalid(format!(
            "samples[{}, {}] = {} is not finite",
            i / axes,
            i % axes,
            samples[i]
        )));
    }
    for (i, w) in m.windows(2).enumerate() {
        if w[1] <= w[0] {
            return Err(ImuError::invalid(format!(
                "cluster sizes must increase: m[{}] = {} follows m[{i}] = {}",
                i + 1,
                w[1],
                w[0]
            )));
        }
    }
    if let Some(&bad) = m.iter().find(|&&x| x == 0 || x > n / 2) {
        return Err(ImuError::invalid(format!(
            "cluster size {bad} is outside 1..={} (two clusters must fit in {n} samples)",
            n / 2
        )));
    }
    let mut adev = vec![0.0; m.len() * axes];
    for axis in 0..axes {
        let s = centred_cumsum(samples, axes, axis);
        for (j, (e, &mi)) in second_differences(&s, m).into_iter().zip(m).enumerate() {
            let terms = (n + 1 - 2 * mi) as f64;
            adev[j * axes + axis] = (e / (2.0 * (mi * mi) as f64 * terms)).sqrt();
        }
    }
    Ok(AllanDeviation {
        m: m.to_vec(),
        tau_s: m.iter().map(|&x| x as f64 * period_s).collect(),
        n_clusters: m.iter().map(|&x| n / x).collect(),
        rel_err: m.iter().map(|&x| relative_error(n, x)).collect(),
        adev,
        axes,
    })
}

/// One coefficient read off a line of fixed slope: NaN value (and range) where the curve has no
/// such region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LineFit {
    /// The line's value at its reference τ (1 s for N, 3 s for K).
    pub value: f64,
    /// Relative uncertainty: the smallest relative error of a point in the region (neighbouring
    /// overlapping estimates are strongly correlated, so points are not counted as independent).
    pub rel_err: f64,
    /// The region fitted [s].
    pub tau_lo: f64,
    pub tau_hi: f64,
    /// Points in the region.
    pub points: usize,
}

impl LineFit {
    pub const NONE: LineFit = LineFit {
        value: f64::NAN,
        rel_err: f64::NAN,
        tau_lo: f64::NAN,
        tau_hi: f64::NAN,
        points: 0,
    };

    pub fn found(&self) -> bool {
        self.points > 0
    }
}

/// The noise of one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseFit {
    /// White noise density N [unit/√Hz = unit·√s]: the −1/2 line at τ = 1 s.
    pub white: LineFit,
    /// Rate random walk K [unit/√s]: the +1/2 line at τ = 3 s.
    pub random_walk: LineFit,
    /// Bias instability B [unit]: min σ / 0.664.
    pub bias_instability: f64,
    /// Where the minimum is [s], and its relative error.
    pub tau_bias: f64,
    pub bias_rel_err: f64,
    /// The minimum lies inside the usable points (false: at their last one, so the curve was
    /// still falling and B is an upper bound).
    pub bias_observed: bool,
}

/// Least-squares slope of y over x.
fn ls_slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx) * (a - mx);
    }
    if sxx > 0.0 {
        sxy / sxx
    } else {
        f64::NAN
    }
}

/// Local log-log slope at each point (NaN where the window holds one point).
pub fn local_slopes(log_tau: &[f64], log_adev: &[f64]) -> Vec<f64> {
    let n = log_tau.len();
    let (mut lo, mut hi) = (0usize, 0usize);
    (0..n)
        .map(|i| {
            while log_tau[lo] < log_tau[i] - SLOPE_HALF_WINDOW_DECADES {
                lo += 1;
            }
            hi = hi.max(i);
            while hi + 1 < n && log_tau[hi + 1] <= log_tau[i] + SLOPE_HALF_WINDOW_DECADES {
                hi += 1;
            }
            // Sparse points (the first integer cluster sizes) take their neighbours.
            let (a, b) = (lo.min(i.saturating_sub(1)), hi.max((i + 1).min(n - 1)));
            if b > a {
                ls_slope(&log_tau[a..=b], &log_adev[a..=b])
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// The line of slope `slope` through the longest (in decades) run of usable points whose local
/// slope is within tolerance, read at `tau_ref`.
fn fit_line(log_tau: &[f64], log_adev: &[f64], slopes: &[f64], rel_err: &[f64], slope: f64, tau_ref: f64) -> LineFit {
    let ok = |i: usize| (slopes[i] - slope).abs() <= SLOPE_TOLERANCE;
    let mut best: Option<(usize, usize)> = None;
    let mut i = 0;
    while i < log_tau.len() {
        if !ok(i) {
            i += 1;
            continue;
        }
        let start = i;
        while i + 1 < log_tau.len() && ok(i + 1) {
            i += 1;
        }
        let span = log_tau[i] - log_tau[start];
        if best.is_none_or(|(a, b)| span > log_tau[b] - log_tau[a]) {
            best = Some((start, i));
        }
        i += 1;
    }
    let Some((a, b)) = best else {
        return LineFit::NONE;
    };
    // log10 σ at τ = 1 s. Points weigh the same: weighting by certainty would let the region's
    // small-τ end, where the neighbouring noise still adds to the curve, pull the line.
    let intercept = (a..=b).map(|j| log_adev[j] - slope * log_tau[j]).sum::<f64>() / (b - a + 1) as f64;
    LineFit {
        value: 10f64.powf(intercept + slope * tau_ref.log10()),
        rel_err: rel_err[a..=b].iter().copied().fold(f64::INFINITY, f64::min),
        tau_lo: 10f64.powf(log_tau[a]),
        tau_hi: 10f64.powf(log_tau[b]),
        points: b - a + 1,
    }
}

/// The standard slope fits of one axis' Allan deviation (`tau_s`, `adev`, `rel_err` of one
/// length, τ increasing).
pub fn fit_noise(tau_s: &[f64], adev: &[f64], rel_err: &[f64]) -> Result<NoiseFit> {
    if tau_s.len() != adev.len() || tau_s.len() != rel_err.len() {
        return Err(ImuError::invalid(format!(
            "tau_s, adev and rel_err differ in length: {}, {}, {}",
            tau_s.len(),
            adev.len(),
            rel_err.len()
        )));
    }
    if tau_s.windows(2).any(|w| w[1] <= w[0]) {
        return Err(ImuError::invalid("tau_s must be strictly increasing"));
    }
    // Usable points: certain enough, and a positive finite σ to take the log of.
    let keep: Vec<usize> = (0..tau_s.len())
        .filter(|&i| rel_err[i] <= MAX_REL_ERR && adev[i].is_finite() && adev[i] > 0.0 && tau_s[i] > 0.0)
        .collect();
    let log_tau: Vec<f64> = keep.iter().map(|&i| tau_s[i].log10()).collect();
    let log_adev: Vec<f64> = keep.iter().map(|&i| adev[i].log10()).collect();
    let errs: Vec<f64> = keep.iter().map(|&i| rel_err[i]).collect();
    if keep.is_empty() {
        return Ok(NoiseFit {
            white: LineFit::NONE,
            random_walk: LineFit::NONE,
            bias_instability: f64::NAN,
            tau_bias: f64::NAN,
            bias_rel_err: f64::NAN,
            bias_observed: false,
        });
    }
    let slopes = local_slopes(&log_tau, &log_adev);
    let white = fit_line(&log_tau, &log_adev, &slopes, &errs, -0.5, 1.0);
    let random_walk = fit_line(&log_tau, &log_adev, &slopes, &errs, 0.5, 3.0);
    let (jmin, _) = log_adev.iter().enumerate().fold(
        (0, f64::INFINITY),
        |(bj, bv), (j, &v)| if v < bv { (j, v) } else { (bj, bv) },
    );
    Ok(NoiseFit {
        white,
        random_walk,
        bias_instability: 10f64.powf(log_adev[jmin]) / BIAS_INSTABILITY_FACTOR,
        tau_bias: 10f64.powf(log_tau[jmin]),
        bias_rel_err: errs[jmin],
        bias_observed: jmin + 1 < keep.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cluster_sizes_are_log_spaced_unique_and_end_at_half() {
        let m = cluster_sizes(1000, 10);
        assert_eq!(m[..5], [1, 2, 3, 4, 5]);
        assert_eq!(*m.last().unwrap(), 500);
        assert!(m.windows(2).all(|w| w[1] > w[0]));
        assert!(cluster_sizes(1, 10).is_empty());
        assert_eq!(cluster_sizes(2, 10), vec![1]);
    }

    #[test]
    fn constant_input_has_zero_deviation_and_a_line_has_the_known_one() {
        let y = vec![3.0; 100];
        let d = overlapping_adev(&y, 1, 0.01, &[1, 10, 50]).unwrap();
        assert!(d.adev.iter().all(|&v| v == 0.0));
        // A ramp y_i = i: adjacent cluster means differ by m, so σ² = m² / 2.
        let ramp: Vec<f64> = (0..200).map(f64::from).collect();
        let d = overlapping_adev(&ramp, 1, 1.0, &[1, 7, 100]).unwrap();
        for (j, &m) in d.m.iter().enumerate() {
            let want = m as f64 / 2f64.sqrt();
            assert!((d.adev[j] - want).abs() < 1e-9 * want, "m={m}: {} vs {want}", d.adev[j]);
        }
    }

    #[test]
    fn blocked_sums_equal_the_plain_sum_across_block_edges() {
        // Several blocks (MIN_BLOCK 8192), cluster sizes around a block and up to N/2.
        let n = 40_001;
        let s: Vec<f64> = (0..n)
            .map(|i| ((i as f64) * 0.618).sin() * 3.0 + (i % 7) as f64)
            .collect();
        let m = [1, 2, 7, 8191, 8192, 8193, 12_345, 19_999, 20_000];
        let got = second_differences(&s, &m);
        for (j, &mi) in m.iter().enumerate() {
            let want: f64 = (0..n - 2 * mi)
                .map(|k| {
                    let d = s[k + 2 * mi] - 2.0 * s[k + mi] + s[k];
                    d * d
                })
                .sum();
            assert!((got[j] - want).abs() <= 1e-12 * want, "m={mi}: {} vs {want}", got[j]);
        }
    }

    #[test]
    fn bad_arguments_are_invalid_input() {
        for (m, p) in [
            (&[0usize][..], 0.1),
            (&[51][..], 0.1),
            (&[2, 2][..], 0.1),
            (&[1][..], 0.0),
        ] {
            assert!(matches!(
                overlapping_adev(&[0.0; 100], 1, p, m),
                Err(ImuError::InvalidInput(_))
            ));
        }
        assert!(overlapping_adev(&[0.0; 7], 2, 1.0, &[1]).is_err());
        assert!(overlapping_adev(&[0.0, f64::NAN, 0.0, 0.0], 1, 1.0, &[1]).is_err());
    }

    #[test]
    fn fits_read_exact_power_laws() {
        // σ(τ) = N/√τ + (nothing else): N found exactly, no +1/2 region, minimum at the end.
        let tau: Vec<f64> = (0..60).map(|j| 10f64.powf(-2.0 + j as f64 / 20.0)).collect();
        let err = vec![0.01; tau.len()];
        let white: Vec<f64> = tau.iter().map(|t| 2e-3 / t.sqrt()).collect();
        let f = fit_noise(&tau, &white, &err).unwrap();
        assert!((f.white.value - 2e-3).abs() < 1e-12, "{f:?}");
        assert!(!f.random_walk.found());
        assert!(!f.bias_observed);
        let rw: Vec<f64> = tau.iter().map(|t| 5e-5 * (t / 3.0).sqrt()).collect();
        let f = fit_noise(&tau, &rw, &err).unwrap();
        assert!((f.random_walk.value - 5e-5).abs() < 1e-15, "{f:?}");
        assert!(!f.white.found());
        // A flat floor: B = floor / 0.664, observed inside.
        let bowl: Vec<f64> = tau.iter().map(|t| (4e-6 / t + 1e-8 + 1e-6 * t / 3.0).sqrt()).collect();
        let f = fit_noise(&tau, &bowl, &err).unwrap();
        let min = bowl.iter().copied().fold(f64::INFINITY, f64::min);
        assert!((f.bias_instability - min / BIAS_INSTABILITY_FACTOR).abs() < 1e-15);
        assert!(f.bias_observed);
    }
}
