//! `rotsums::rotation_window_sums` against independent oracles: the closed-form rotation of a
//! constant rate, and finite differences of the rotation in the model's parameters for the sums.
//! `rotsums::velocity_window_sums` against sums written out by hand: no rotation, and rotation
//! about z by the hold rule (angle ω T_k), whose unweighted columns also have a closed form.

use imu_core::error::ImuError;
use imu_core::rotsums::{rotation_window_sums, velocity_window_sums, RotSums, SUM_COLS, SUM_ROWS, THETA_LEN, VEL_COLS};
use imu_core::so3::{log, quat_from_wxyz};
use imu_core::types::{QuatWxyz, Vec3};
use nalgebra::{Matrix3, Vector3};

/// B windows of W samples, one after another.
struct Windows {
    gyro: Vec<Vec3>,
    acc: Vec<Vec3>,
    dt: Vec<f64>,
    b: usize,
    w: usize,
}

impl Windows {
    fn run(&self, theta: &[f64; THETA_LEN], horizons: &[usize], jacobian: bool) -> RotSums {
        rotation_window_sums(
            &self.gyro, &self.acc, &self.dt, self.b, self.w, theta, horizons, jacobian,
        )
        .unwrap()
    }
}

fn q_at(r: &RotSums, nh: usize, b: usize, j: usize) -> QuatWxyz {
    let e = 4 * (b * nh + j);
    r.q_wxyz[e..e + 4].try_into().unwrap()
}

/// S[b, j] as (9, 7).
fn sum_at(r: &RotSums, nh: usize, b: usize, j: usize) -> &[f64] {
    let n = SUM_ROWS * SUM_COLS;
    &r.sums.as_ref().unwrap()[n * (b * nh + j)..n * (b * nh + j + 1)]
}

fn mat(theta: &[f64], at: usize) -> Matrix3<f64> {
    Matrix3::from_row_slice(&theta[at..at + 9])
}

/// A small θ with every part nonzero.
fn some_theta() -> [f64; THETA_LEN] {
    std::array::from_fn(|i| 1e-3 * ((i * 7 + 3) % 11) as f64 - 5e-3)
}

#[test]
fn constant_rate_gives_exp_of_rate_times_time() {
    // Per window constant g and a, so ω = M (g − b) − G a is constant and Q after h samples is
    // Exp(ω h dt) exactly; rates from 0 to a step of 0.125 rad (past the series' switch at 0.1).
    let (w, dt) = (200, 0.005);
    let rates = [
        [0.0; 3],
        [1e-3, 0.0, 0.0],
        [0.0, 2.0, 0.0],
        [0.0, 0.0, -3.0],
        [0.4, -1.2, 0.9],
        [25.0, 0.0, 0.0],
    ];
    let a = [0.3, -0.2, 9.81];
    let n = rates.len();
    let ws = Windows {
        gyro: rates.iter().flat_map(|&g| vec![g; w]).collect(),
        acc: vec![a; n * w],
        dt: vec![dt; n * w],
        b: n,
        w,
    };
    let horizons = [1, 40, 200, 7];
    for theta in [[0.0; THETA_LEN], some_theta()] {
        let (m, bias, g) = (
            Matrix3::identity() + mat(&theta, 0),
            Vector3::from_row_slice(&theta[9..12]),
            mat(&theta, 12),
        );
        let r = ws.run(&theta, &horizons, false);
        assert!(r.sums.is_none());
        for (bi, &rate) in rates.iter().enumerate() {
            let omega = m * (Vector3::from(rate) - bias) - g * Vector3::from(a);
            for (j, &h) in horizons.iter().enumerate() {
                let phi = omega * (h as f64 * dt);
                let angle = phi.norm();
                let s = if angle > 0.0 { (0.5 * angle).sin() / angle } else { 0.5 };
                let want = [(0.5 * angle).cos(), s * phi[0], s * phi[1], s * phi[2]];
                let got = q_at(&r, horizons.len(), bi, j);
                for c in 0..4 {
                    assert!(
                        (got[c] - want[c]).abs() < 1e-12,
                        "window {bi} h {h}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }
}

/// ∂ψ/∂θ_p from the sums: perturbing θ_p moves ω_k by δ_k (affine in θ), and Q_h by Exp(ψ) with
/// ψ = Σ_{k<h} A_k δ_k. M_ic: δ_k = e_i (g_k − b)_c; b_c: δ_k = −M e_c; G_ic: δ_k = −e_i a_kc.
fn dpsi(s: &[f64], theta: &[f64; THETA_LEN], p: usize) -> Vector3<f64> {
    let at = |row: usize, col: usize| s[SUM_COLS * row + col];
    Vector3::from_fn(|r, _| match p {
        0..9 => {
            let (i, c) = (p / 3, p % 3);
            at(3 * r + i, c) - at(3 * r + i, 6) * theta[9 + c]
        }
        9..12 => {
            let (c, m) = (p - 9, mat(theta, 0) + Matrix3::identity());
            -(0..3).map(|i| at(3 * r + i, 6) * m[(i, c)]).sum::<f64>()
        }
        _ => {
            let (i, c) = ((p - 12) / 3, (p - 12) % 3);
            -at(3 * r + i, 3 + c)
        }
    })
}

#[test]
fn sums_are_the_derivatives_of_the_rotation() {
    // Central differences of Log(Q_h(θ + ε e_p) ⊗ Q_h(θ)⁻¹) against the sums, for all 21
    // parameters: constant rates (one with steps past the series' switch), a varying specific
    // force (the G columns) and jittered dt.
    let w = 60;
    let rates = [[0.3, -2.0, 1.1], [0.0, 0.0, 15.0]];
    let b = rates.len();
    let ws = Windows {
        gyro: rates.iter().flat_map(|&g| vec![g; w]).collect(),
        acc: (0..b * w)
            .map(|k| {
                let s = k as f64 * 0.1;
                [1.5 * s.cos(), 0.4 + 0.7 * (1.3 * s).sin(), 9.81 + 0.9 * (0.6 * s).sin()]
            })
            .collect(),
        dt: (0..b * w).map(|k| 0.01 + 1e-4 * ((k * 7) % 5) as f64).collect(),
        b,
        w,
    };
    let horizons = [10, 35, 60];
    let nh = horizons.len();
    let eps = 1e-6;
    for theta in [[0.0; THETA_LEN], some_theta()] {
        let r = ws.run(&theta, &horizons, true);
        assert_eq!(r.q_wxyz, ws.run(&theta, &horizons, false).q_wxyz);
        for p in 0..THETA_LEN {
            let shifted = |d: f64| {
                let mut t = theta;
                t[p] += d;
                ws.run(&t, &horizons, false)
            };
            let (plus, minus) = (shifted(eps), shifted(-eps));
            for bi in 0..b {
                for (j, &h) in horizons.iter().enumerate() {
                    let q0 = quat_from_wxyz(q_at(&r, nh, bi, j)).inverse();
                    let log_at = |x: &RotSums| log(&(quat_from_wxyz(q_at(x, nh, bi, j)) * q0));
                    let fd = (log_at(&plus) - log_at(&minus)) / (2.0 * eps);
                    let want = dpsi(sum_at(&r, nh, bi, j), &theta, p);
                    assert!(
                        (fd - want).norm() < 1e-7 * want.norm().max(1.0),
                        "θ_{p}, window {bi}, h {h}: {fd:?} vs {want:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn horizons_in_any_order_and_repeated_land_in_their_own_slots() {
    let (b, w) = (3, 30);
    let ws = Windows {
        gyro: (0..b * w).map(|k| [0.01 * k as f64, -0.5, 0.2]).collect(),
        acc: (0..b * w).map(|k| [0.1, 0.02 * k as f64, 9.8]).collect(),
        dt: vec![0.005; b * w],
        b,
        w,
    };
    let theta = some_theta();
    let sorted = [5, 12, 30];
    let shuffled = [30, 5, 12, 5];
    let (rs, ru) = (ws.run(&theta, &sorted, true), ws.run(&theta, &shuffled, true));
    for bi in 0..b {
        for (j, h) in shuffled.iter().enumerate() {
            let js = sorted.iter().position(|s| s == h).unwrap();
            assert_eq!(q_at(&ru, 4, bi, j), q_at(&rs, 3, bi, js));
            assert_eq!(sum_at(&ru, 4, bi, j), sum_at(&rs, 3, bi, js));
        }
    }
}

#[test]
fn threads_do_not_change_the_result() {
    let (b, w) = (64, 50);
    let ws = Windows {
        gyro: (0..b * w).map(|k| [(k as f64 * 0.01).sin(), 0.3, -0.2]).collect(),
        acc: (0..b * w).map(|k| [0.5, (k as f64 * 0.02).cos(), 9.81]).collect(),
        dt: vec![0.005; b * w],
        b,
        w,
    };
    let pool = |k| rayon::ThreadPoolBuilder::new().num_threads(k).build().unwrap();
    let run = || ws.run(&some_theta(), &[10, 20, 50], true);
    assert_eq!(pool(1).install(run), pool(3).install(run));
}

#[test]
fn bad_inputs_are_errors() {
    let (b, w) = (2, 5);
    let z = [0.0; 3];
    let (g, a, d) = (vec![z; b * w], vec![z; b * w], vec![0.005; b * w]);
    let theta = [0.0; THETA_LEN];
    let expect = |r: imu_core::Result<RotSums>, what: &str| match r {
        Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(what), "{msg:?} lacks {what:?}"),
        other => panic!("expected InvalidInput with {what:?}, got {other:?}"),
    };
    let run = |g: &[Vec3], a: &[Vec3], d: &[f64], b: usize, w: usize, t: &[f64; THETA_LEN], hs: &[usize]| {
        rotation_window_sums(g, a, d, b, w, t, hs, true)
    };
    expect(run(&g, &a, &d, b, w, &theta, &[3, 0]), "horizons[1] = 0");
    expect(
        run(&g, &a, &d, b, w, &theta, &[6]),
        "horizons[0] = 6: a horizon must be in 1..=5",
    );
    expect(run(&g, &a, &d, b, w, &theta, &[]), "horizons is empty");
    expect(run(&g[1..], &a, &d, b, w, &theta, &[1]), "gyro has 9 samples");
    expect(run(&g, &a[1..], &d, b, w, &theta, &[1]), "acc has 9 samples");
    expect(run(&g, &a, &d[1..], b, w, &theta, &[1]), "dt has 9 samples");
    expect(
        run(&g, &a, &d, 3, w, &theta, &[1]),
        "expected 3 windows x 5 samples = 15",
    );
    expect(run(&g, &a, &d, usize::MAX, 2, &theta, &[1]), "overflow");
    for (i, bad) in [(0, f64::NAN), (11, f64::INFINITY), (20, f64::NEG_INFINITY)] {
        let mut t = theta;
        t[i] = bad;
        expect(
            run(&g, &a, &d, b, w, &t, &[1]),
            &format!("theta[{i}] = {bad} is not finite"),
        );
    }
    // No windows is not an error: empty outputs.
    let r = run(&[], &[], &[], 0, w, &theta, &[5]).unwrap();
    assert!(r.q_wxyz.is_empty() && r.sums.unwrap().is_empty());
}

/// V[b, j] as (9, 8) of a velocity_window_sums result with `nh` horizons.
fn vel_at(v: &[f64], nh: usize, b: usize, j: usize) -> &[f64] {
    let n = SUM_ROWS * VEL_COLS;
    &v[n * (b * nh + j)..n * (b * nh + j + 1)]
}

/// Σ_{k<h} R_k dt_k c_k written out for one window, R_k a given function of the sample index and
/// T_k; c_k = (a_k, 1, s_k a_k, s_k) with s_k = T_{k+1} − ½ dt_k.
fn vel_by_hand(acc: &[Vec3], dt: &[f64], h: usize, rot: impl Fn(usize, f64) -> Matrix3<f64>) -> Vec<f64> {
    let mut out = vec![0.0; SUM_ROWS * VEL_COLS];
    let mut t = 0.0;
    for k in 0..h {
        let r = rot(k, t) * dt[k];
        t += dt[k];
        let s = t - 0.5 * dt[k];
        let a = acc[k];
        let c = [a[0], a[1], a[2], 1.0, s * a[0], s * a[1], s * a[2], s];
        for row in 0..3 {
            for i in 0..3 {
                for (f, &cf) in c.iter().enumerate() {
                    out[VEL_COLS * (3 * row + i) + f] += r[(row, i)] * cf;
                }
            }
        }
    }
    out
}

fn assert_close(got: &[f64], want: &[f64], tol: f64, what: &str) {
    assert_eq!(got.len(), want.len());
    for (e, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= tol, "{what}, entry {e}: {g} vs {w}");
    }
}

fn rot_z(angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
}

#[test]
fn zero_rate_puts_the_plain_sums_on_the_identity_rows() {
    // No rotation: rows 3r + r hold Σ dt_k c_k, the others zero, to round-off of the sums.
    let (b, w) = (2, 50);
    let acc: Vec<Vec3> = (0..b * w)
        .map(|k| {
            let x = k as f64 * 0.13;
            [x.sin(), 0.5 * x.cos(), 9.81 + 0.1 * x]
        })
        .collect();
    let dt: Vec<f64> = (0..b * w).map(|k| 0.005 + 1e-5 * ((k * 3) % 7) as f64).collect();
    let horizons = [50, 1, 17];
    let v = velocity_window_sums(&vec![[0.0; 3]; b * w], &acc, &dt, b, w, &horizons).unwrap();
    assert_eq!(v.len(), b * horizons.len() * SUM_ROWS * VEL_COLS);
    for bi in 0..b {
        let (a, d) = (&acc[bi * w..(bi + 1) * w], &dt[bi * w..(bi + 1) * w]);
        for (j, &h) in horizons.iter().enumerate() {
            let got = vel_at(&v, horizons.len(), bi, j);
            let mut plain = [0.0; VEL_COLS];
            let mut t = 0.0;
            for k in 0..h {
                t += d[k];
                let s = t - 0.5 * d[k];
                let c = [a[k][0], a[k][1], a[k][2], 1.0, s * a[k][0], s * a[k][1], s * a[k][2], s];
                for f in 0..VEL_COLS {
                    plain[f] += d[k] * c[f];
                }
            }
            for row in 0..SUM_ROWS {
                let want = if row % 4 == 0 { plain } else { [0.0; VEL_COLS] };
                let what = format!("window {bi} h {h} row {row}");
                assert_close(&got[VEL_COLS * row..VEL_COLS * (row + 1)], &want, 1e-15, &what);
            }
        }
    }
}

#[test]
fn rotation_about_z_follows_the_hold_rule() {
    // A constant rate ω about z: the rotation held over sample k is Rz(ω T_k) exactly. Rates from
    // slow to a step of 0.125 rad (past the series' switch at 0.1), jittered dt, varying acc.
    let w = 200;
    let omegas = [1e-3, 0.7, -3.0, 25.0];
    let b = omegas.len();
    let rates: Vec<Vec3> = omegas.iter().flat_map(|&o| vec![[0.0, 0.0, o]; w]).collect();
    let acc: Vec<Vec3> = (0..b * w)
        .map(|k| {
            let x = k as f64 * 0.07;
            [2.0 * x.cos(), -1.0 + (1.7 * x).sin(), 9.81 + 0.3 * (0.4 * x).sin()]
        })
        .collect();
    let dt: Vec<f64> = (0..b * w)
        .map(|k| 0.005 * (1.0 + 0.01 * ((k * 5) % 9) as f64 - 0.04))
        .collect();
    let horizons = [40, 200, 1, 120];
    let v = velocity_window_sums(&rates, &acc, &dt, b, w, &horizons).unwrap();
    for (bi, &o) in omegas.iter().enumerate() {
        let (a, d) = (&acc[bi * w..(bi + 1) * w], &dt[bi * w..(bi + 1) * w]);
        for (j, &h) in horizons.iter().enumerate() {
            let want = vel_by_hand(a, d, h, |_, t| rot_z(o * t));
            // The quaternion chain drifts by round-off per sample; the sums are O(10).
            let what = format!("ω {o} h {h}");
            assert_close(vel_at(&v, horizons.len(), bi, j), &want, 1e-12, &what);
        }
    }
}

#[test]
fn constant_rate_and_dt_match_the_geometric_sums() {
    // Constant ω about z, constant dt and a: R_k = Rz(kθ), θ = ω dt, so Σ_{k<h} R_k dt a has
    // Σ cos kθ = sin(hθ/2) cos((h−1)θ/2) / sin(θ/2) and Σ sin kθ = sin(hθ/2) sin((h−1)θ/2) /
    // sin(θ/2); with s_k = (k + ½) dt the weighted columns are the same sums of k cos kθ etc.,
    // checked here by the rotation at each sample from sin and cos.
    let (w, dt) = (200, 0.005);
    let omegas = [0.5, 3.0, 30.0];
    let b = omegas.len();
    let a = [0.4, -0.3, 9.81];
    let rates: Vec<Vec3> = omegas.iter().flat_map(|&o| vec![[0.0, 0.0, o]; w]).collect();
    let horizons = [1, 2, 77, 200];
    let v = velocity_window_sums(&rates, &vec![a; b * w], &vec![dt; b * w], b, w, &horizons).unwrap();
    for (bi, &o) in omegas.iter().enumerate() {
        let th = o * dt;
        for (j, &h) in horizons.iter().enumerate() {
            let got = vel_at(&v, horizons.len(), bi, j);
            let hf = h as f64;
            let common = (0.5 * hf * th).sin() / (0.5 * th).sin();
            let (sc, ss) = (
                common * (0.5 * (hf - 1.0) * th).cos(),
                common * (0.5 * (hf - 1.0) * th).sin(),
            );
            // Σ R_k dt = dt [[Σc, −Σs, 0], [Σs, Σc, 0], [0, 0, h]], then times (a, 1).
            let rsum = Matrix3::new(sc, -ss, 0.0, ss, sc, 0.0, 0.0, 0.0, hf) * dt;
            let mut want = vec![0.0; SUM_ROWS * VEL_COLS];
            for row in 0..3 {
                for i in 0..3 {
                    let e = VEL_COLS * (3 * row + i);
                    for f in 0..3 {
                        want[e + f] = rsum[(row, i)] * a[f];
                    }
                    want[e + 3] = rsum[(row, i)];
                }
            }
            let what = format!("ω {o} h {h}");
            // Unweighted columns from the closed form.
            for row in 0..SUM_ROWS {
                let e = VEL_COLS * row;
                assert_close(&got[e..e + 4], &want[e..e + 4], 1e-12, &what);
            }
            let by_hand = vel_by_hand(&vec![a; h], &vec![dt; h], h, |k, _| rot_z(k as f64 * th));
            assert_close(got, &by_hand, 1e-12, &what);
        }
    }
}

#[test]
fn velocity_sums_do_not_depend_on_threads_or_horizon_order() {
    let (b, w) = (64, 50);
    let rates: Vec<Vec3> = (0..b * w).map(|k| [(k as f64 * 0.01).sin(), 0.3, -2.0]).collect();
    let acc: Vec<Vec3> = (0..b * w).map(|k| [0.5, (k as f64 * 0.02).cos(), 9.81]).collect();
    let dt: Vec<f64> = (0..b * w).map(|k| 0.005 + 1e-5 * (k % 3) as f64).collect();
    let pool = |k| rayon::ThreadPoolBuilder::new().num_threads(k).build().unwrap();
    let run = |hs: &[usize]| velocity_window_sums(&rates, &acc, &dt, b, w, hs).unwrap();
    let sorted = [10, 20, 50];
    let one = pool(1).install(|| run(&sorted));
    assert_eq!(one, pool(3).install(|| run(&sorted)));
    let shuffled = [50, 10, 20, 10];
    let ru = run(&shuffled);
    for bi in 0..b {
        for (j, h) in shuffled.iter().enumerate() {
            let js = sorted.iter().position(|s| s == h).unwrap();
            assert_eq!(vel_at(&ru, 4, bi, j), vel_at(&one, 3, bi, js));
        }
    }
}

#[test]
fn velocity_bad_inputs_are_errors() {
    let (b, w) = (2, 5);
    let z = [0.0; 3];
    let (r, a, d) = (vec![z; b * w], vec![z; b * w], vec![0.005; b * w]);
    let expect = |res: imu_core::Result<Vec<f64>>, what: &str| match res {
        Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(what), "{msg:?} lacks {what:?}"),
        other => panic!("expected InvalidInput with {what:?}, got {other:?}"),
    };
    expect(velocity_window_sums(&r, &a, &d, b, w, &[3, 0]), "horizons[1] = 0");
    expect(
        velocity_window_sums(&r, &a, &d, b, w, &[6]),
        "horizons[0] = 6: a horizon must be in 1..=5",
    );
    expect(velocity_window_sums(&r, &a, &d, b, w, &[]), "horizons is empty");
    expect(velocity_window_sums(&r[1..], &a, &d, b, w, &[1]), "rates has 9 samples");
    expect(velocity_window_sums(&r, &a[1..], &d, b, w, &[1]), "acc has 9 samples");
    expect(velocity_window_sums(&r, &a, &d[1..], b, w, &[1]), "dt has 9 samples");
    expect(
        velocity_window_sums(&r, &a, &d, 3, w, &[1]),
        "expected 3 windows x 5 samples = 15",
    );
    expect(velocity_window_sums(&r, &a, &d, usize::MAX, 2, &[1]), "overflow");
    expect(velocity_window_sums(&[], &[], &[], 0, 0, &[1]), "1..=0");
    // No windows is not an error: an empty output.
    assert!(velocity_window_sums(&[], &[], &[], 0, w, &[5]).unwrap().is_empty());
}
