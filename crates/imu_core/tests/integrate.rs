mod common;

use common::{jittered_stamps, rot_err, synthetic_sequence, vec_err, wiggly_imu};
use imu_core::integrate::{integrate_windows, preintegrate, preintegrate_dt, Preintegrated};
use imu_core::labels::{self, Increment, PAPER_FRACTIONS};
use imu_core::so3::{self, arr3, quat_from_wxyz, quat_to_wxyz, v3};
use imu_core::types::{Vec3, GRAVITY};
use nalgebra::{Complex, Vector3};

fn row(p: &Preintegrated, j: usize) -> Increment {
    p.row(j).unwrap()
}

#[test]
fn constant_rate_gives_exp_of_rate_times_time() {
    let w = Vector3::new(0.3, -0.7, 1.1);
    let t = jittered_stamps(2001, 1_000_000, 300_000);
    let n = t.len();
    let p = preintegrate(&t, &vec![arr3(&w); n], &vec![[0.0; 3]; n]).unwrap();
    assert_eq!(p.len(), n);
    for j in (0..n).step_by(50) {
        let want = so3::exp(&(w * p.dt[j]));
        // ~2 rad after 2 s: only the round-off of 2000 quaternion products remains.
        assert!(rot_err(p.dq_wxyz[j], quat_to_wxyz(&want)) < 1e-12, "row {j}");
        assert_eq!(p.dv[j], [0.0; 3]);
        assert_eq!(p.dp[j], [0.0; 3]);
    }
}

#[test]
fn constant_force_without_rotation_is_exact_for_any_steps() {
    // Σ (T_i dt_i + ½ dt_i²) = ½ T², so the hold scheme has no discretisation error here.
    let a = [0.4, -2.5, 9.81];
    let t = jittered_stamps(1500, 2_000_000, 700_000);
    let n = t.len();
    let p = preintegrate(&t, &vec![[0.0; 3]; n], &vec![a; n]).unwrap();
    for j in 0..n {
        let s = p.dt[j];
        assert_eq!(p.dq_wxyz[j], [1.0, 0.0, 0.0, 0.0]);
        for (c, &ac) in a.iter().enumerate() {
            assert!((p.dv[j][c] - ac * s).abs() <= 1e-12 * ac.abs().max(1.0), "dv row {j}");
            assert!(
                (p.dp[j][c] - 0.5 * ac * s * s).abs() <= 1e-12 * ac.abs().max(1.0),
                "dp row {j}"
            );
        }
    }
}

/// Δβ, Δγ of a rotation about z at rate w with constant body force a, held over n steps of dt.
/// In the xy-plane (as complex numbers, z = e^{iθ}, θ = w dt) the sums are geometric:
///   Δβ_n = dt a (1 − zⁿ)/(1 − z)
///   Δγ_n = dt Σ_{i<n} Δβ_i + ½ dt Δβ_n,  Σ_{i<n} Δβ_i = dt a/(1 − z) (n − (1 − zⁿ)/(1 − z))
fn spin_z_discrete(w: f64, a: Vec3, dt: f64, n: usize) -> (Vec3, Vec3) {
    let z = Complex::from_polar(1.0, w * dt);
    let ac = Complex::new(a[0], a[1]);
    let one = Complex::new(1.0, 0.0);
    let zn = z.powu(n as u32);
    let beta = ac * dt * (one - zn) / (one - z);
    let sum_beta = ac * dt / (one - z) * (Complex::new(n as f64, 0.0) - (one - zn) / (one - z));
    let gamma = sum_beta * dt + beta * (0.5 * dt);
    let tt = n as f64 * dt;
    (
        [beta.re, beta.im, a[2] * tt],
        [gamma.re, gamma.im, 0.5 * a[2] * tt * tt],
    )
}

/// The same in continuous time: Δβ(T) = a (e^{iwT} − 1)/(iw), Δγ(T) = a/(iw) ((e^{iwT} − 1)/(iw) − T).
fn spin_z_continuous(w: f64, a: Vec3, tt: f64) -> (Vec3, Vec3) {
    let iw = Complex::new(0.0, w);
    let ac = Complex::new(a[0], a[1]);
    let e = (iw * tt).exp() - Complex::new(1.0, 0.0);
    let beta = ac * e / iw;
    let gamma = ac / iw * (e / iw - Complex::new(tt, 0.0));
    (
        [beta.re, beta.im, a[2] * tt],
        [gamma.re, gamma.im, 0.5 * a[2] * tt * tt],
    )
}

#[test]
fn spin_about_z_with_constant_force_matches_the_geometric_sum_and_the_continuous_limit() {
    let (w, a) = (2.3, [1.2, -0.7, 9.81]);
    let horizon = 1.5;
    let mut cont_err = Vec::new();
    for &rate in &[100i64, 1000] {
        let period = 1_000_000_000 / rate;
        let dt = period as f64 * 1e-9;
        let n = (horizon / dt).round() as usize;
        let t: Vec<i64> = (0..=n as i64).map(|i| i * period).collect();
        let p = preintegrate(&t, &vec![[0.0, 0.0, w]; n + 1], &vec![a; n + 1]).unwrap();
        for j in (0..=n).step_by(n / 10) {
            let (db, dg) = spin_z_discrete(w, a, dt, j);
            assert!(
                vec_err(p.dv[j], db) < 1e-11,
                "{rate} Hz row {j}: dv {:?} vs {db:?}",
                p.dv[j]
            );
            assert!(
                vec_err(p.dp[j], dg) < 1e-11,
                "{rate} Hz row {j}: dp {:?} vs {dg:?}",
                p.dp[j]
            );
            let want_q = so3::exp(&Vector3::new(0.0, 0.0, w * j as f64 * dt));
            assert!(rot_err(p.dq_wxyz[j], quat_to_wxyz(&want_q)) < 1e-12);
        }
        let (cb, cg) = spin_z_continuous(w, a, n as f64 * dt);
        let e = vec_err(p.dv[n], cb).max(vec_err(p.dp[n], cg));
        // First order in dt (measured: 1.37·dt for these numbers).
        assert!(e < 2.0 * dt, "{rate} Hz: continuous error {e}");
        cont_err.push(e);
    }
    let ratio = cont_err[0] / cont_err[1];
    assert!(
        (9.0..11.0).contains(&ratio),
        "error ratio 100 Hz / 1 kHz = {ratio}, expected ~10"
    );
}

#[test]
fn rows_cover_t0_to_tj_with_samples_before_j() {
    let t = jittered_stamps(40, 5_000_000, 1_900_000);
    let (gyro, acc) = wiggly_imu(&t);
    let p = preintegrate(&t, &gyro, &acc).unwrap();
    assert_eq!(p.len(), t.len());
    assert_eq!(
        row(&p, 0),
        Increment {
            dq_wxyz: [1.0, 0.0, 0.0, 0.0],
            dv: [0.0; 3],
            dp: [0.0; 3],
            dt: 0.0
        }
    );
    for j in 1..t.len() {
        assert_eq!(p.dt[j], (t[j] - t[0]) as f64 * 1e-9);
        // Row j depends only on stamps ..=j and samples ..j: cut there and change the last sample.
        let mut g = gyro[..=j].to_vec();
        let mut a = acc[..=j].to_vec();
        g[j] = [100.0, -50.0, 7.0];
        a[j] = [-3.0, 1e3, 0.0];
        let cut = preintegrate(&t[..=j], &g, &a).unwrap();
        assert_eq!(row(&cut, j), row(&p, j), "row {j}");
    }
}

#[test]
fn stamps_and_hold_times_give_the_same_increments() {
    let t = jittered_stamps(300, 2_500_000, 1_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let p = preintegrate(&t, &gyro, &acc).unwrap();
    let holds: Vec<f64> = t.windows(2).map(|w| (w[1] - w[0]) as f64 * 1e-9).collect();
    let n = holds.len();
    let q = preintegrate_dt(&holds, &gyro[..n], &acc[..n]).unwrap();
    assert_eq!(q.len(), p.len());
    for j in 0..p.len() {
        // Same per-step dt, same arithmetic: identical bits; only Δt differs (sum vs difference).
        assert_eq!(p.dq_wxyz[j], q.dq_wxyz[j]);
        assert_eq!(p.dv[j], q.dv[j]);
        assert_eq!(p.dp[j], q.dp[j]);
        assert!((p.dt[j] - q.dt[j]).abs() < 1e-14, "row {j}");
    }
}

#[test]
fn windows_equal_preintegration_of_the_sliced_window() {
    let t = jittered_stamps(500, 5_000_000, 2_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let window = 100;
    let hs = labels::horizons(window, &PAPER_FRACTIONS).unwrap();
    assert_eq!(hs, vec![20, 40, 60, 80, 100]);
    let starts = labels::window_starts(t.len(), window, 37).unwrap();
    let l = integrate_windows(&t, &gyro, &acc, &starts, &hs).unwrap();
    assert_eq!((l.starts.clone(), l.horizons.clone()), (starts.clone(), hs.clone()));
    assert_eq!(l.dq_wxyz.len(), starts.len() * hs.len());
    for (w, &k) in starts.iter().enumerate() {
        let p = preintegrate(&t[k..=k + window], &gyro[k..=k + window], &acc[k..=k + window]).unwrap();
        for (h, &n) in hs.iter().enumerate() {
            let e = w * hs.len() + h;
            let got = Increment {
                dq_wxyz: l.dq_wxyz[e],
                dv: l.dv[e],
                dp: l.dp[e],
                dt: l.dt[e],
            };
            assert_eq!(got, row(&p, n), "window {k} horizon {n}");
        }
    }
}

#[test]
fn increments_compose_over_adjacent_intervals() {
    let t = jittered_stamps(700, 2_000_000, 900_000);
    let (gyro, acc) = wiggly_imu(&t);
    let p0 = preintegrate(&t, &gyro, &acc).unwrap();
    for &(a, b) in &[(0usize, 1usize), (1, 2), (250, 699), (100, 101), (3, 600)] {
        let pa = preintegrate(&t[a..=b], &gyro[a..=b], &acc[a..=b]).unwrap();
        let (r0a, b0a, g0a, t0a) = (quat_from_wxyz(p0.dq_wxyz[a]), v3(p0.dv[a]), v3(p0.dp[a]), p0.dt[a]);
        let ab = b - a;
        let (rab, bab, gab, tab) = (quat_from_wxyz(pa.dq_wxyz[ab]), v3(pa.dv[ab]), v3(pa.dp[ab]), pa.dt[ab]);
        let q = r0a * rab;
        let beta = b0a + r0a * bab;
        let gamma = g0a + b0a * tab + r0a * gab;
        assert!(rot_err(quat_to_wxyz(&q), p0.dq_wxyz[b]) < 1e-13, "[{a},{b}]");
        assert!(vec_err(arr3(&beta), p0.dv[b]) < 1e-12, "[{a},{b}]");
        assert!(vec_err(arr3(&gamma), p0.dp[b]) < 1e-12, "[{a},{b}]");
        assert!((t0a + tab - p0.dt[b]).abs() < 1e-14);
    }
}

#[test]
fn quaternion_norm_stays_at_one_without_renormalising() {
    let n = 100_001;
    let t: Vec<i64> = (0..n as i64).map(|i| i * 1_000_000).collect();
    let (gyro, acc) = wiggly_imu(&t);
    let p = preintegrate(&t, &gyro, &acc).unwrap();
    let worst = p
        .dq_wxyz
        .iter()
        .map(|q| (q.iter().map(|x| x * x).sum::<f64>().sqrt() - 1.0).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-12, "norm drift {worst}");
}

/// Worst rotation / Δβ / Δγ disagreement between labels from ground truth and increments from the
/// exact IMU signal, over all windows and the paper's horizons.
fn oracle_errors(rate_hz: i64, jitter: bool) -> (f64, f64, f64) {
    let period = 1_000_000_000 / rate_hz;
    let n = 3 * rate_hz as usize + 1;
    let t = jittered_stamps(n, period, if jitter { period / 4 } else { 0 });
    let seq = synthetic_sequence(&t, GRAVITY);
    let window = rate_hz as usize; // 1 s
    let gt = labels::window_labels(&seq, window, window / 4, &PAPER_FRACTIONS, GRAVITY).unwrap();
    let imu = integrate_windows(&seq.t_ns, &seq.gyro, &seq.acc, &gt.starts, &gt.horizons).unwrap();
    assert_eq!(gt.starts.len(), 9);
    assert_eq!(gt.dt, imu.dt);
    let mut e = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..gt.dt.len() {
        e.0 = e.0.max(rot_err(gt.dq_wxyz[i], imu.dq_wxyz[i]));
        e.1 = e.1.max(vec_err(gt.dv[i], imu.dv[i]));
        e.2 = e.2.max(vec_err(gt.dp[i], imu.dp[i]));
    }
    e
}

#[test]
fn integrating_the_true_imu_signal_reproduces_the_labels() {
    let slow = oracle_errors(100, false);
    let fast = oracle_errors(1000, false);
    // At 1 kHz the zero-order hold is off by O(dt) times the signal's rate of change over a 1 s
    // window (measured: 4.1e-4 rad, 2.3e-3 m/s, 8.1e-4 m).
    assert!(fast.0 < 6e-4, "rotation {fast:?}");
    assert!(fast.1 < 3.5e-3, "velocity {fast:?}");
    assert!(fast.2 < 1.2e-3, "position {fast:?}");
    for (s, f) in [(slow.0, fast.0), (slow.1, fast.1), (slow.2, fast.2)] {
        let ratio = s / f;
        assert!(
            (9.0..11.0).contains(&ratio),
            "100 Hz / 1 kHz error ratio {ratio} ({slow:?} vs {fast:?})"
        );
    }
    // Jittered stamps change nothing in the orders of magnitude.
    let jit = oracle_errors(1000, true);
    assert!(
        jit.0 < 2.0 * fast.0 && jit.1 < 2.0 * fast.1 && jit.2 < 2.0 * fast.2,
        "{jit:?} vs {fast:?}"
    );
}
