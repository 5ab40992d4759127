//! Training batches: windows of IMU samples with ground-truth labels, augmented as in the paper
//! (Sec. IV): random window starts, added white noise and added random biases.
//!
//! Every array is flat and row-major (`Vec<f64>`, `Vec<[f64; N]>`) so the bindings hand it to
//! numpy as a B×W×6 (B×W, B×H×4, ...) array without a copy.
//!
//! Determinism: window b draws everything (its start, its bias, its noise) from its own ChaCha8
//! stream b of the batch seed. Windows are filled in parallel, but no window's numbers depend on
//! which thread ran it or on any other window, so one seed gives one batch on any thread count.
//!
//! Noise model, per sample i held for dt_i = t_{i+1} − t_i:
//!   imu_i = raw_i + bias_i + (density / √dt_i)·n_i,       n_i ~ N(0, I)
//!   bias_0 ~ U[−max, max] per axis,  bias_{i+1} = bias_i + walk·√dt_i·m_i,  m_i ~ N(0, I)
//! which is the discrete form of continuous white noise of the given density and a Wiener bias,
//! so the added noise matches a datasheet's (or Kalibr's) figures at any sample rate.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use crate::error::{ImuError, Result};
use crate::labels::{check_sequence, horizons, window_starts, Frame, GroundTruthView};
use crate::types::{QuatWxyz, Sequence, Vec3};

/// Augmentation strengths. `Default` is all zero: no augmentation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AugmentConfig {
    /// Gyro white-noise density [rad/s/√Hz].
    pub gyro_noise_density: f64,
    /// Accelerometer white-noise density [m/s²/√Hz].
    pub acc_noise_density: f64,
    /// Constant gyro bias per window, uniform per axis in [−max, max] [rad/s].
    pub gyro_bias_max: f64,
    /// Constant accelerometer bias per window, uniform per axis in [−max, max] [m/s²].
    pub acc_bias_max: f64,
    /// Gyro bias random walk [rad/s²/√Hz].
    pub gyro_bias_walk: f64,
    /// Accelerometer bias random walk [m/s³/√Hz].
    pub acc_bias_walk: f64,
}

impl AugmentConfig {
    fn check(&self) -> Result<()> {
        let fields = [
            ("gyro_noise_density", self.gyro_noise_density),
            ("acc_noise_density", self.acc_noise_density),
            ("gyro_bias_max", self.gyro_bias_max),
            ("acc_bias_max", self.acc_bias_max),
            ("gyro_bias_walk", self.gyro_bias_walk),
            ("acc_bias_walk", self.acc_bias_walk),
        ];
        for (name, x) in fields {
            if !(x.is_finite() && x >= 0.0) {
                return Err(ImuError::invalid(format!(
                    "augment.{name} = {x} must be finite and ≥ 0"
                )));
            }
        }
        Ok(())
    }
}

/// What `make_batch` draws.
#[derive(Clone, Debug, PartialEq)]
pub struct BatchConfig {
    /// IMU samples per window (W). A window starting at k needs states k..=k+W.
    pub window: usize,
    /// Windows per batch (B).
    pub batch_size: usize,
    /// Label horizons as fractions of the window (the paper: 0.2, 0.4, …, 1.0).
    pub fractions: Vec<f64>,
    /// Gravity magnitude [m/s²] for the labels (z-up world).
    pub gravity: f64,
    pub augment: AugmentConfig,
}

/// B windows of W samples with labels at H horizons. Row-major throughout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// B×W×6: gyro xyz then acc xyz, with augmentation applied.
    pub imu: Vec<f64>,
    /// B×W: dt[i] = t_{k+i+1} − t_{k+i} [s], the time sample i is held.
    pub dt: Vec<f64>,
    /// B×H ground-truth increments (`labels::increment`) from the window start.
    pub dq_wxyz: Vec<QuatWxyz>,
    pub dv: Vec<Vec3>,
    pub dp: Vec<Vec3>,
    /// B×H: time [s] spanned by each label.
    pub label_dt: Vec<f64>,
    /// B×W×6: the bias actually added to each sample (constant plus walk); zero without augmentation.
    pub bias: Vec<f64>,
    /// B: which input sequence each window came from.
    pub seq_index: Vec<u32>,
    /// B: the window's first sample index in that sequence.
    pub start: Vec<u64>,
    /// H: the horizons in samples.
    pub horizons: Vec<usize>,
}

impl Batch {
    /// Number of windows (B).
    pub fn len(&self) -> usize {
        self.seq_index.len()
    }
    pub fn is_empty(&self) -> bool {
        self.seq_index.is_empty()
    }
    /// Samples per window (W); 0 for an empty batch.
    pub fn window(&self) -> usize {
        self.dt.len().checked_div(self.len()).unwrap_or(0)
    }
}

/// `batch_size` windows at random starts, augmented, with labels. Deterministic in `seed`.
///
/// A sequence is chosen with probability proportional to its number of valid windows, then a
/// start uniformly within it, so every valid window in the data is equally likely. Sequences
/// shorter than a window are skipped; it is an error only if all are.
pub fn make_batch(seqs: &[Sequence], cfg: &BatchConfig, seed: u64) -> Result<Batch> {
    let plan = BatchPlan::new(seqs, cfg)?;
    let mut out = Batch::alloc(cfg.batch_size, cfg.window, plan.horizons.clone(), "batch_size")?;
    plan.fill(seqs, cfg, seed, out.as_mut())?;
    Ok(out)
}

/// The checked, seed-independent part of `make_batch`: the horizons (which size the label
/// buffers) and the window counts that starts are drawn from. Build it, allocate a `BatchMut`
/// of `cfg.batch_size` windows, then `fill` it (the Python binding fills numpy's own arrays).
#[derive(Clone, Debug)]
pub struct BatchPlan {
    /// H: the horizons in samples.
    pub horizons: Vec<usize>,
    /// cum[i] = valid windows in seqs[..i].
    cum: Vec<u64>,
}

impl BatchPlan {
    /// Checks `seqs` and `cfg` (every error `make_batch` can give).
    pub fn new(seqs: &[Sequence], cfg: &BatchConfig) -> Result<BatchPlan> {
        if cfg.batch_size == 0 {
            return Err(ImuError::invalid("batch_size must be at least 1"));
        }
        cfg.augment.check()?;
        let horizons = check_common(seqs, cfg.window, &cfg.fractions, cfg.gravity)?;
        let w = cfg.window;
        // cum[i] = valid windows in seqs[..i]; a window at k needs k + w < len.
        let mut cum = Vec::with_capacity(seqs.len() + 1);
        cum.push(0u64);
        for s in seqs {
            let last = cum.last().copied().unwrap_or(0);
            cum.push(last + s.len().saturating_sub(w) as u64);
        }
        if cum.last().copied().unwrap_or(0) == 0 {
            return Err(too_short(seqs, w));
        }
        // The outputs are sized by batch_size × window: refuse sizes no allocation can hold here,
        // before the caller allocates them.
        batch_bytes(cfg.batch_size, w, horizons.len(), "batch_size")?;
        Ok(BatchPlan { horizons, cum })
    }

    /// Draws and fills `cfg.batch_size` windows into `out`, which must be sized for them
    /// (`BatchMut::check`). `seqs` and `cfg` must be the ones the plan was made from.
    pub fn fill(&self, seqs: &[Sequence], cfg: &BatchConfig, seed: u64, out: BatchMut<'_>) -> Result<()> {
        out.check(cfg.batch_size, cfg.window, &self.horizons)?;
        let (cum, total) = (&self.cum, self.cum.last().copied().unwrap_or(0));
        if self.cum.len() != seqs.len() + 1 || total == 0 {
            return Err(ImuError::invalid("batch plan does not belong to these sequences"));
        }
        fill_all(
            out,
            cfg.window,
            &self.horizons,
            |_b, rng| {
                let u = rng.random_range(0..total);
                let s = cum.partition_point(|&c| c <= u).saturating_sub(1);
                (s, (u - cum[s]) as usize)
            },
            seqs,
            cfg.gravity,
            Some((&cfg.augment, seed)),
        );
        Ok(())
    }
}

/// Every window of every sequence at starts 0, stride, 2·stride, …, in sequence order, with no
/// augmentation (`bias` all zero): the fixed set for validation. Same layout as `make_batch`.
pub fn eval_windows(seqs: &[Sequence], window: usize, stride: usize, fractions: &[f64], gravity: f64) -> Result<Batch> {
    let hs = check_common(seqs, window, fractions, gravity)?;
    let mut picks = Vec::new();
    for (i, s) in seqs.iter().enumerate() {
        picks.extend(window_starts(s.len(), window, stride)?.into_iter().map(|k| (i, k)));
    }
    if picks.is_empty() {
        return Err(too_short(seqs, window));
    }
    let mut out = Batch::alloc(picks.len(), window, hs, "eval_windows")?;
    let hs = out.horizons.clone();
    fill_all(out.as_mut(), window, &hs, |b, _| picks[b], seqs, gravity, None);
    Ok(out)
}

/// Bytes the outputs of `b` windows of `w` samples at `h` horizons take (imu and bias B×W×6, dt
/// B×W, labels B×H×11, seq_index and start B), or an error naming `what` (the argument that set
/// `b`) when that is more than one allocation can hold. Checked before anything is allocated.
pub fn batch_bytes(b: usize, w: usize, h: usize, what: &str) -> Result<usize> {
    // b, w, h < 2^64, so b·w and b·h fit in u128; the sums and scalings are checked.
    let (b, w, h) = (b as u128, w as u128, h as u128);
    let bytes = (b * w)
        .checked_mul(13 * 8)
        .zip((b * h).checked_mul(11 * 8))
        .and_then(|(x, y)| x.checked_add(y))
        .and_then(|x| x.checked_add(b * 12));
    bytes
        .and_then(|n| usize::try_from(n).ok())
        .filter(|&n| n <= isize::MAX as usize)
        .ok_or_else(|| {
            let need = bytes.map_or("more than 2^128".to_string(), |n| n.to_string());
            ImuError::invalid(format!(
                "{what}: {b} windows of {w} samples at {h} horizons need {need} bytes, more than one \
                 allocation can hold"
            ))
        })
}

/// A zero-filled Vec of `n` entries, or the reservation error instead of aborting when memory runs
/// out: the one fallible allocation the core and the bindings share (each names its own error).
pub(crate) fn try_zeroed_vec<T: Clone + Default>(
    n: usize,
) -> std::result::Result<Vec<T>, std::collections::TryReserveError> {
    let mut v = Vec::new();
    v.try_reserve_exact(n)?;
    v.resize(n, T::default());
    Ok(v)
}

/// [`try_zeroed_vec`] with the core's error, naming `what`.
fn zeroed<T: Clone + Default>(n: usize, what: &str) -> Result<Vec<T>> {
    try_zeroed_vec(n).map_err(|e| {
        ImuError::invalid(format!(
            "{what}: {n} entries of {} bytes cannot be allocated ({e})",
            std::mem::size_of::<T>()
        ))
    })
}

impl Batch {
    /// Zeroed outputs, checked (`batch_bytes`) and allocated fallibly: a huge `batch_size` is an
    /// error, never an abort.
    fn alloc(b: usize, w: usize, horizons: Vec<usize>, what: &str) -> Result<Batch> {
        let h = horizons.len();
        batch_bytes(b, w, h, what)?;
        // Cannot overflow: batch_bytes bounded the largest product.
        let (bw6, bw, bh) = (b * w * 6, b * w, b * h);
        Ok(Batch {
            imu: zeroed(bw6, what)?,
            dt: zeroed(bw, what)?,
            dq_wxyz: zeroed(bh, what)?,
            dv: zeroed(bh, what)?,
            dp: zeroed(bh, what)?,
            label_dt: zeroed(bh, what)?,
            bias: zeroed(bw6, what)?,
            seq_index: zeroed(b, what)?,
            start: zeroed(b, what)?,
            horizons,
        })
    }

    /// Mutable views of every per-window buffer.
    pub fn as_mut(&mut self) -> BatchMut<'_> {
        BatchMut {
            imu: &mut self.imu,
            dt: &mut self.dt,
            dq_wxyz: &mut self.dq_wxyz,
            dv: &mut self.dv,
            dp: &mut self.dp,
            label_dt: &mut self.label_dt,
            bias: &mut self.bias,
            seq_index: &mut self.seq_index,
            start: &mut self.start,
        }
    }
}

/// Caller-owned buffers for B windows of W samples at H horizons, laid out as in `Batch`.
pub struct BatchMut<'a> {
    /// B×W×6.
    pub imu: &'a mut [f64],
    /// B×W.
    pub dt: &'a mut [f64],
    /// B×H.
    pub dq_wxyz: &'a mut [QuatWxyz],
    pub dv: &'a mut [Vec3],
    pub dp: &'a mut [Vec3],
    pub label_dt: &'a mut [f64],
    /// B×W×6.
    pub bias: &'a mut [f64],
    /// B.
    pub seq_index: &'a mut [u32],
    pub start: &'a mut [u64],
}

impl BatchMut<'_> {
    /// Every buffer has the size of `b` windows of `w` samples at `horizons`.
    pub fn check(&self, b: usize, w: usize, horizons: &[usize]) -> Result<()> {
        let h = horizons.len();
        let got = [
            self.imu.len(),
            self.dt.len(),
            self.dq_wxyz.len(),
            self.dv.len(),
            self.dp.len(),
            self.label_dt.len(),
            self.bias.len(),
            self.seq_index.len(),
            self.start.len(),
        ];
        let want = [b * w * 6, b * w, b * h, b * h, b * h, b * h, b * w * 6, b, b];
        if got != want {
            return Err(ImuError::invalid(format!(
                "batch buffers have sizes {got:?}, {b} windows × {w} samples × {h} horizons need {want:?}"
            )));
        }
        Ok(())
    }
}

/// Checks shared by both entry points; returns the horizons.
fn check_common(seqs: &[Sequence], window: usize, fractions: &[f64], gravity: f64) -> Result<Vec<usize>> {
    if seqs.is_empty() {
        return Err(ImuError::invalid("no sequences to draw windows from"));
    }
    if fractions.is_empty() {
        return Err(ImuError::invalid(
            "fractions is empty: at least one label horizon is needed",
        ));
    }
    if !gravity.is_finite() {
        return Err(ImuError::invalid(format!("gravity = {gravity} is not finite")));
    }
    if u32::try_from(seqs.len()).is_err() {
        return Err(ImuError::invalid(format!(
            "{} sequences is more than seq_index can hold",
            seqs.len()
        )));
    }
    let hs = horizons(window, fractions)?;
    for (i, s) in seqs.iter().enumerate() {
        check_sequence(s).map_err(|e| ImuError::invalid(format!("sequence {i}: {e}")))?;
        // Noise scales with 1/√dt, so a zero or negative interval would poison a whole window.
        if let Some(k) = s.t_ns.windows(2).position(|p| p[1] <= p[0]) {
            return Err(ImuError::invalid(format!(
                "sequence {i}: stamps must be strictly increasing, but sample {} ({}) follows {}",
                k + 1,
                s.t_ns[k + 1],
                s.t_ns[k]
            )));
        }
    }
    Ok(hs)
}

fn too_short(seqs: &[Sequence], window: usize) -> ImuError {
    let longest = seqs.iter().map(Sequence::len).max().unwrap_or(0);
    ImuError::invalid(format!(
        "a window of {window} samples needs {} states, but the longest of {} sequence(s) has {longest}",
        window as u128 + 1,
        seqs.len()
    ))
}

/// Fill every window of `out` in parallel. `pick(b, rng)` gives (sequence, start) of window b;
/// with augmentation, `rng` is window b's own stream and `pick` draws from it first.
fn fill_all<P>(
    out: BatchMut<'_>,
    w: usize,
    hs: &[usize],
    pick: P,
    seqs: &[Sequence],
    gravity: f64,
    aug: Option<(&AugmentConfig, u64)>,
) where
    P: Fn(usize, &mut ChaCha8Rng) -> (usize, usize) + Sync,
{
    let h = hs.len();
    if w == 0 || h == 0 {
        return; // not reachable: check_common demands a window and a horizon
    }
    out.imu
        .par_chunks_mut(w * 6)
        .zip(out.bias.par_chunks_mut(w * 6))
        .zip(out.dt.par_chunks_mut(w))
        .zip(out.dq_wxyz.par_chunks_mut(h))
        .zip(out.dv.par_chunks_mut(h))
        .zip(out.dp.par_chunks_mut(h))
        .zip(out.label_dt.par_chunks_mut(h))
        .zip(out.seq_index.par_iter_mut())
        .zip(out.start.par_iter_mut())
        .enumerate()
        .for_each(|(b, ((((((((imu, bias), dt), dq), dv), dp), ldt), si), st))| {
            let mut rng = ChaCha8Rng::seed_from_u64(aug.map_or(0, |a| a.1));
            rng.set_stream(b as u64);
            let (s, k) = pick(b, &mut rng);
            let seq = &seqs[s];
            *si = s as u32; // checked against u32::MAX in check_common
            *st = k as u64;
            let t = &seq.t_ns[k..=k + w];
            for (d, p) in dt.iter_mut().zip(t.windows(2)) {
                *d = (p[1] - p[0]) as f64 * 1e-9;
            }
            for ((row, g), a) in imu.chunks_exact_mut(6).zip(&seq.gyro[k..k + w]).zip(&seq.acc[k..k + w]) {
                row[..3].copy_from_slice(g);
                row[3..].copy_from_slice(a);
            }
            if let Some((a, _)) = aug {
                augment(imu, bias, dt, a, &mut rng);
            }
            // Ranges were checked when the sequences were validated and the start drawn.
            let gt = GroundTruthView::of(seq);
            let f = Frame::at(&gt, k, gravity);
            for (j, &n) in hs.iter().enumerate() {
                let inc = f.to(&gt, k + n);
                dq[j] = inc.dq_wxyz;
                dv[j] = inc.dv;
                dp[j] = inc.dp;
                ldt[j] = inc.dt;
            }
        });
}

/// Add a constant-plus-walk bias and white noise to one window in place; record the bias.
fn augment(imu: &mut [f64], bias: &mut [f64], dt: &[f64], a: &AugmentConfig, rng: &mut ChaCha8Rng) {
    let per_axis = |gyro: f64, acc: f64| [gyro, gyro, gyro, acc, acc, acc];
    let bias_max = per_axis(a.gyro_bias_max, a.acc_bias_max);
    let walk = per_axis(a.gyro_bias_walk, a.acc_bias_walk);
    let has_walk = walk.iter().any(|&x| x > 0.0);
    let has_noise = a.gyro_noise_density > 0.0 || a.acc_noise_density > 0.0;
    let mut b = [0.0; 6];
    for (bc, &m) in b.iter_mut().zip(&bias_max) {
        let u: f64 = rng.random();
        *bc = (2.0 * u - 1.0) * m;
    }
    let rows = imu.chunks_exact_mut(6).zip(bias.chunks_exact_mut(6)).zip(dt);
    for ((x, bias_row), &dti) in rows {
        bias_row.copy_from_slice(&b);
        let sqrt_dt = dti.sqrt();
        if has_noise {
            // density / √dt per sensor (two divisions, not six), noise drawn in axis order.
            let (sg, sa) = (a.gyro_noise_density / sqrt_dt, a.acc_noise_density / sqrt_dt);
            let scale = [sg, sg, sg, sa, sa, sa];
            for c in 0..6 {
                let n: f64 = rng.sample(StandardNormal);
                x[c] = (x[c] + b[c]) + scale[c] * n;
            }
        } else {
            for c in 0..6 {
                x[c] += b[c];
            }
        }
        // The walk step over sample i's interval moves the bias of the next sample.
        if has_walk {
            for c in 0..6 {
                let m: f64 = rng.sample(StandardNormal);
                b[c] += walk[c] * sqrt_dt * m;
            }
        }
    }
}
