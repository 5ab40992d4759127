//! Zero-phase filtering by one second-order section: `scipy.signal.sosfiltfilt(sos, x, axis=0)`
//! for a single section (the floor's order-2 Butterworth low-pass, `butter2` in
//! python/imu_learn/baselines/affine.py), each column of x on its own:
//!
//! * the odd extension by `PAD` = 3 · (2 · 1 + 1) = 9 samples at each end (scipy's default padding
//!   for one section): 2 x[0] − x[PAD..1], then x, then 2 x[N−1] − x[N−2..N−PAD−1];
//! * a forward pass of the section (direct form II transposed, as `sosfilt`) started in the steady
//!   state of its first sample (`sosfilt_zi(sos) · ext[0]`), then the same backward over the
//!   forward pass's output (started in the steady state of its last sample);
//! * the padding cut off again.
//!
//! The steady state of a constant input u: output d u with d = Σb / Σa (the gain at DC), and the
//! two delay states (d − b0) u and (b2 − a2 d) u (the recursion below with y = d u, x = u).
//! scipy's `sosfiltfilt` is the oracle (tests/test_floor_numpy.py); a linear ramp passes unchanged
//! and a sinusoid is scaled by |H|² (crates/imu_core/tests/filter.rs).

use crate::batch::try_zeroed_vec;
use crate::error::{ImuError, Result};

/// The padding at each end (scipy's `padlen` for one section).
pub const PAD: usize = 9;

/// One section (b0, b1, b2, a0, a1, a2), as a row of scipy's `sos`.
pub type Section = [f64; 6];

/// The section normalised by a0, checked: finite, a0 ≠ 0, a gain at DC that exists (Σa ≠ 0).
fn normalised(sos: &Section) -> Result<Section> {
    if let Some((i, v)) = sos.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(ImuError::invalid(format!("sos[{i}] = {v} is not finite")));
    }
    let a0 = sos[3];
    if a0 == 0.0 {
        return Err(ImuError::invalid("sos[3] (a0) is 0"));
    }
    let s = sos.map(|v| v / a0);
    if 1.0 + s[4] + s[5] == 0.0 {
        return Err(ImuError::invalid(
            "the section has a pole at z = 1 (1 + a1 + a2 = 0): no steady state",
        ));
    }
    Ok(s)
}

/// One pass of the section over `x` (in place), started in the steady state of x[0].
fn steady_pass(s: &Section, x: &mut [f64]) {
    let [b0, b1, b2, _, a1, a2] = *s;
    let dc = (b0 + b1 + b2) / (1.0 + a1 + a2);
    let Some(&u) = x.first() else { return };
    let (mut z0, mut z1) = ((dc - b0) * u, (b2 - a2 * dc) * u);
    for v in x.iter_mut() {
        let xn = *v;
        let y = b0 * xn + z0;
        z0 = b1 * xn - a1 * y + z1;
        z1 = b2 * xn - a2 * y;
        *v = y;
    }
}

/// x (n rows of `cols` values, row-major) filtered forward and backward by the section `sos`, each
/// column on its own (module doc). Needs n > `PAD` (scipy refuses shorter input too).
pub fn filtfilt_section(x: &[f64], n: usize, cols: usize, sos: &Section) -> Result<Vec<f64>> {
    let s = normalised(sos)?;
    if n.checked_mul(cols) != Some(x.len()) {
        return Err(ImuError::invalid(format!(
            "x has {} values, expected {n} rows x {cols} columns",
            x.len()
        )));
    }
    if n <= PAD {
        return Err(ImuError::invalid(format!(
            "x has {n} rows: the filter's padding needs more than {PAD}"
        )));
    }
    let mut out = try_zeroed_vec(x.len())
        .map_err(|e| ImuError::invalid(format!("{} floats cannot be allocated ({e})", x.len())))?;
    let mut ext = Vec::new();
    ext.try_reserve_exact(n + 2 * PAD)
        .map_err(|e| ImuError::invalid(format!("{n} rows cannot be allocated ({e})")))?;
    for c in 0..cols {
        let at = |i: usize| x[i * cols + c];
        ext.clear();
        ext.extend((0..PAD).map(|i| 2.0 * at(0) - at(PAD - i)));
        ext.extend((0..n).map(at));
        ext.extend((0..PAD).map(|i| 2.0 * at(n - 1) - at(n - 2 - i)));
        steady_pass(&s, &mut ext);
        ext.reverse();
        steady_pass(&s, &mut ext);
        ext.reverse();
        for (i, v) in ext[PAD..PAD + n].iter().enumerate() {
            out[i * cols + c] = *v;
        }
    }
    Ok(out)
}
