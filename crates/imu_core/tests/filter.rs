//! `filter::filtfilt_section` against closed forms: a zero-phase filter with unit gain at DC passes
//! a constant unchanged, and away from the ends a linear ramp unchanged and a sinusoid of frequency f
//! scaled by |H(f)|². (scipy's `sosfiltfilt` is the oracle of
//! tests/test_floor_numpy.py.)

use imu_core::error::ImuError;
use imu_core::filter::{filtfilt_section, Section, PAD};
use std::f64::consts::PI;

/// `scipy.signal.butter(2, fc, fs=fs, output="sos")` in closed form (affine.py's `butter2`).
fn butter2(fc: f64, fs: f64) -> Section {
    let (k, s2) = ((PI * fc / fs).tan(), 2f64.sqrt());
    let norm = 1.0 / (1.0 + s2 * k + k * k);
    let b0 = k * k * norm;
    [
        b0,
        2.0 * b0,
        b0,
        1.0,
        2.0 * (k * k - 1.0) * norm,
        (1.0 - s2 * k + k * k) * norm,
    ]
}

/// |H(e^{iω})|² of the section at frequency f.
fn gain2(s: &Section, f: f64, fs: f64) -> f64 {
    let w = 2.0 * PI * f / fs;
    let mag2 = |c: [f64; 3]| {
        let re = c[0] + c[1] * w.cos() + c[2] * (2.0 * w).cos();
        let im = -c[1] * w.sin() - c[2] * (2.0 * w).sin();
        re * re + im * im
    };
    mag2([s[0], s[1], s[2]]) / mag2([s[3], s[4], s[5]])
}

#[test]
fn constants_and_ramps_pass_unchanged() {
    let (n, fs) = (5000, 200.0);
    for fc in [5.0, 20.0, 90.0] {
        let s = butter2(fc, fs);
        // three columns: a constant, a ramp with an offset, a steeper falling ramp
        let x: Vec<f64> = (0..n)
            .flat_map(|i| {
                let t = i as f64;
                [9.81, 0.3 + 1e-3 * t, -2.0 - 0.05 * t]
            })
            .collect();
        let y = filtfilt_section(&x, n, 3, &s).unwrap();
        // the constant everywhere; the ramps away from the ends (each pass starts in the steady state
        // of a constant, so a ramp's ends carry a transient that has decayed by 1000 samples)
        let worst = |from: usize, to: usize, c: usize| {
            (from..to)
                .map(|i| (x[3 * i + c] - y[3 * i + c]).abs())
                .fold(0.0, f64::max)
        };
        assert!(
            worst(0, n, 0) < 1e-11,
            "fc {fc}: a constant moved by {}",
            worst(0, n, 0)
        );
        for c in [1, 2] {
            let w = worst(1000, n - 1000, c);
            assert!(w < 1e-9, "fc {fc}: a ramp moved by {w}");
        }
    }
}

#[test]
fn a_sinusoid_is_scaled_by_the_squared_gain() {
    let (n, fs, fc) = (20000, 200.0, 10.0);
    let s = butter2(fc, fs);
    for f in [2.0, 10.0, 25.0] {
        let x: Vec<f64> = (0..n).map(|i| (2.0 * PI * f * i as f64 / fs).sin()).collect();
        let y = filtfilt_section(&x, n, 1, &s).unwrap();
        let g = gain2(&s, f, fs);
        // away from the ends (the transients of the padding have decayed)
        let worst = (2000..n - 2000).map(|i| (y[i] - g * x[i]).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-9, "f {f}: |y - |H|^2 x| = {worst} (|H|^2 = {g})");
    }
}

#[test]
fn columns_are_filtered_alone() {
    let (n, s) = (300, butter2(5.0, 200.0));
    let a: Vec<f64> = (0..n).map(|i| ((i * 37) % 11) as f64).collect();
    let b: Vec<f64> = (0..n).map(|i| ((i * 13) % 7) as f64 - 3.0).collect();
    let both: Vec<f64> = a.iter().zip(&b).flat_map(|(x, y)| [*x, *y]).collect();
    let yb = filtfilt_section(&both, n, 2, &s).unwrap();
    let (ya, yy) = (
        filtfilt_section(&a, n, 1, &s).unwrap(),
        filtfilt_section(&b, n, 1, &s).unwrap(),
    );
    for i in 0..n {
        assert_eq!(yb[2 * i], ya[i]);
        assert_eq!(yb[2 * i + 1], yy[i]);
    }
}

#[test]
fn bad_inputs_are_errors() {
    let s = butter2(5.0, 200.0);
    let expect = |r: imu_core::Result<Vec<f64>>, what: &str| match r {
        Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(what), "{msg:?} lacks {what:?}"),
        other => panic!("expected InvalidInput with {what:?}, got {other:?}"),
    };
    let x = vec![1.0; 30];
    expect(filtfilt_section(&x[..PAD], PAD, 1, &s), "needs more than 9");
    expect(filtfilt_section(&x, 10, 2, &s), "expected 10 rows x 2 columns");
    let mut nan = s;
    nan[1] = f64::NAN;
    expect(filtfilt_section(&x, 30, 1, &nan), "sos[1] = NaN");
    let mut a0 = s;
    a0[3] = 0.0;
    expect(filtfilt_section(&x, 30, 1, &a0), "a0");
    expect(
        filtfilt_section(&x, 30, 1, &[1.0, 0.0, 0.0, 1.0, -2.0, 1.0]),
        "pole at z = 1",
    );
}
