//! Covariance of the preintegrated increments against oracles that do not use its closed form:
//! covariances derived by hand for motions without rotation, the left Jacobian of one sample, and
//! finite-difference Jacobians of `preintegrate` itself under aggressive rotation.

mod common;

use common::{jittered_stamps, wiggly_imu};
use imu_core::covariance::{increment_covariance, interval_covariances, Cov9, Var6};
use imu_core::error::ImuError;
use imu_core::integrate::preintegrate;
use imu_core::so3::{self, quat_from_wxyz, v3};
use imu_core::types::Vec3;
use nalgebra::{Matrix3, SMatrix, SymmetricEigen, Vector3};

type M9 = SMatrix<f64, 9, 9>;
type M93 = SMatrix<f64, 9, 3>;

fn m9(c: &Cov9) -> M9 {
    M9::from_fn(|r, k| c[r][k])
}

/// max |a − b| over entries, each scaled by sqrt(b_ii b_jj) (the scale-free measure: a
/// correlation-sized error). Blocks of `b` that are zero must be zero in `a` to 1e-300.
fn rel_err(a: &M9, b: &M9) -> f64 {
    let d: Vec<f64> = (0..9).map(|i| b[(i, i)].max(0.0).sqrt()).collect();
    let mut worst = 0.0f64;
    for r in 0..9 {
        for k in 0..9 {
            let scale = (d[r] * d[k]).max(1e-300);
            worst = worst.max((a[(r, k)] - b[(r, k)]).abs() / scale);
        }
    }
    worst
}

fn diag3(x: f64, y: f64, z: f64) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(x, y, z))
}

fn secs(a: i64, b: i64) -> f64 {
    (b - a) as f64 * 1e-9
}

/// Per-sample variances that vary over the recording (by ~100× between axes and samples).
fn varying_var(n: usize) -> Vec<Var6> {
    (0..n)
        .map(|i| {
            let s = 1.0 + 9.0 * (0.5 + 0.5 * (i as f64 * 0.37).sin());
            [1e-5 * s, 3e-5 * s * s, 2e-6 * s, 1e-3 * s, 4e-4 * s * s, 2e-3 / s]
        })
        .collect()
}

/// Hand-derived covariance without rotation (ω = 0) under a constant specific force `a`. With
/// ΔR = I and T the time since the start, gyro noise n_k of sample k gives
///   δθ = dt_k n_k,  δβ = −[a]× (T_n − T_{k+1}) dt_k n_k,  δγ = −[a]× ½(T_n − T_{k+1})² dt_k n_k
/// (the rotation error rotates the force of every later sample; Σ_{j>k} (T_j − T_{k+1}) dt_j +
/// ½dt_j² = ½(T_n − T_{k+1})² exactly), and accelerometer noise gives
///   δβ = dt_k n_k,  δγ = (T_n − T_{k+1} + dt_k/2) dt_k n_k.
fn no_rotation_oracle(t: &[i64], a: Vec3, vg: Matrix3<f64>, va: Matrix3<f64>, n: usize) -> M9 {
    let ax = v3(a).cross_matrix();
    let tn = secs(t[0], t[n]);
    let mut sum = M9::zeros();
    for k in 0..n {
        let dt = secs(t[k], t[k + 1]);
        let rest = tn - secs(t[0], t[k + 1]);
        let mut g = M93::zeros();
        g.fixed_view_mut::<3, 3>(0, 0).copy_from(&(Matrix3::identity() * dt));
        g.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-ax * rest * dt));
        g.fixed_view_mut::<3, 3>(6, 0)
            .copy_from(&(-ax * (0.5 * rest * rest) * dt));
        let mut f = M93::zeros();
        f.fixed_view_mut::<3, 3>(3, 0).copy_from(&(Matrix3::identity() * dt));
        f.fixed_view_mut::<3, 3>(6, 0)
            .copy_from(&(Matrix3::identity() * ((rest + 0.5 * dt) * dt)));
        sum += g * vg * g.transpose() + f * va * f.transpose();
    }
    sum
}

#[test]
fn no_rotation_and_no_force_give_the_random_walk_covariances() {
    // Uniform dt: δθ var = σ_g² dt² n, δβ var = σ_a² dt² n, and with δγ = Σ_k (n − k − ½) dt² n_k,
    // δγ var = σ_a² dt⁴ Σ_{m=1..n} (m − ½)² = σ_a² dt⁴ n(4n² − 1)/12, δβ·δγ = σ_a² dt³ n²/2.
    let n_stamps = 401;
    let t: Vec<i64> = (0..n_stamps as i64).map(|i| 7_000_000 + i * 5_000_000).collect();
    let zero = vec![[0.0; 3]; n_stamps];
    let (sg, sa) = ([1e-4, 4e-4, 9e-4], [1e-2, 4e-2, 0.25]);
    let var = vec![[sg[0], sg[1], sg[2], sa[0], sa[1], sa[2]]; n_stamps];
    let hs = [0usize, 1, 7, 200, 400];
    let got = increment_covariance(&t, &zero, &zero, &var, &hs).unwrap();
    let dt = 0.005;
    for (&n, c) in hs.iter().zip(&got) {
        let nf = n as f64;
        let mut want = M9::zeros();
        for ax in 0..3 {
            want[(ax, ax)] = sg[ax] * dt * dt * nf;
            want[(3 + ax, 3 + ax)] = sa[ax] * dt * dt * nf;
            want[(6 + ax, 6 + ax)] = sa[ax] * dt.powi(4) * nf * (4.0 * nf * nf - 1.0) / 12.0;
            want[(3 + ax, 6 + ax)] = sa[ax] * dt.powi(3) * nf * nf / 2.0;
            want[(6 + ax, 3 + ax)] = want[(3 + ax, 6 + ax)];
        }
        let got = m9(c);
        if n == 0 {
            assert_eq!(got, M9::zeros());
        } else {
            assert!(rel_err(&got, &want) < 1e-12, "n = {n}: {}", rel_err(&got, &want));
        }
    }
}

#[test]
fn constant_force_without_rotation_matches_the_hand_derived_sums_on_uneven_stamps() {
    // Every gyro-to-velocity/position coupling is the lever arm of the force: a closed form that
    // does not go through the E_h/F_k factorisation. Stamps jitter by up to ±40 %.
    let t = jittered_stamps(601, 5_000_000, 2_000_000);
    let n_stamps = t.len();
    let a = [0.7, -1.9, 9.81];
    let (gyro, acc) = (vec![[0.0; 3]; n_stamps], vec![a; n_stamps]);
    let (sg, sa) = ([2e-4, 5e-5, 1e-3], [3e-2, 1e-3, 0.2]);
    let var = vec![[sg[0], sg[1], sg[2], sa[0], sa[1], sa[2]]; n_stamps];
    let hs = [1usize, 2, 33, 300, 600];
    let got = increment_covariance(&t, &gyro, &acc, &var, &hs).unwrap();
    let (vg, va) = (diag3(sg[0], sg[1], sg[2]), diag3(sa[0], sa[1], sa[2]));
    let mut worst = 0.0f64;
    for (&n, c) in hs.iter().zip(&got) {
        let e = rel_err(&m9(c), &no_rotation_oracle(&t, a, vg, va, n));
        worst = worst.max(e);
    }
    assert!(worst < 1e-11, "worst relative error {worst:e}");
}

#[test]
fn one_sample_gives_the_left_jacobian_and_the_hold_terms() {
    // After one sample: δθ = R_1 J_r(φ) dt n_g = J_l(φ) dt n_g (φ = ω dt, R_1 = Exp φ), and with
    // R_0 = I: δβ = dt n_a, δγ = ½ dt² n_a; gyro noise of the only sample moves neither.
    let dt = 0.013;
    let t = [1_000, 1_000 + 13_000_000];
    let w = Vector3::new(2.5, -3.0, 1.2); // θ = 0.05 rad: the series branch
    for scale in [1.0, 4.0] {
        // 4×: θ = 0.21 rad, the closed-form branch
        let gyro = [[w[0] * scale, w[1] * scale, w[2] * scale], [9.0, 9.0, 9.0]];
        let acc = [[0.3, 9.0, -2.0], [1.0, 1.0, 1.0]];
        let var: [Var6; 2] = [[1e-4, 2e-4, 3e-4, 1e-2, 2e-2, 3e-2], [5.0; 6]];
        let c = m9(&increment_covariance(&t, &gyro, &acc, &var, &[1]).unwrap()[0]);
        let phi = w * scale * dt;
        let th = phi.norm();
        let k = phi.cross_matrix();
        let jl = Matrix3::identity() + k * ((1.0 - th.cos()) / (th * th)) + k * k * ((th - th.sin()) / th.powi(3));
        let mut want = M9::zeros();
        let va = diag3(1e-2, 2e-2, 3e-2);
        want.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(jl * diag3(1e-4, 2e-4, 3e-4) * jl.transpose() * (dt * dt)));
        want.fixed_view_mut::<3, 3>(3, 3).copy_from(&(va * (dt * dt)));
        want.fixed_view_mut::<3, 3>(3, 6).copy_from(&(va * (0.5 * dt.powi(3))));
        want.fixed_view_mut::<3, 3>(6, 3).copy_from(&(va * (0.5 * dt.powi(3))));
        want.fixed_view_mut::<3, 3>(6, 6).copy_from(&(va * (0.25 * dt.powi(4))));
        assert!(rel_err(&c, &want) < 1e-13, "scale {scale}: {:e}", rel_err(&c, &want));
    }
}

/// (Log(Δq Δq_ref⁻¹), Δβ, Δγ) at row n, as one 9-vector relative to a reference integration.
fn residual(
    t: &[i64],
    gyro: &[Vec3],
    acc: &[Vec3],
    reference: &[Vector3<f64>; 2],
    q_ref: [f64; 4],
    n: usize,
) -> [f64; 9] {
    let p = preintegrate(t, gyro, acc).unwrap();
    let dq = quat_from_wxyz(p.dq_wxyz[n]) * quat_from_wxyz(q_ref).inverse();
    let th = so3::log(&dq);
    let dv = v3(p.dv[n]) - reference[0];
    let dp = v3(p.dp[n]) - reference[1];
    [th[0], th[1], th[2], dv[0], dv[1], dv[2], dp[0], dp[1], dp[2]]
}

#[test]
fn matches_finite_difference_jacobians_of_preintegrate_under_aggressive_rotation() {
    // Σ = J Q Jᵀ with J the central-difference Jacobian of the increments with respect to every
    // gyro and accelerometer component (δθ as Log(Δq(x + h) Δq(x)⁻¹), the left perturbation).
    // |ω| up to ~4 rad/s, stamps jittered, per-sample variances varying.
    let t = jittered_stamps(13, 10_000_000, 3_000_000);
    let n_stamps = t.len();
    let gyro: Vec<Vec3> = (0..n_stamps)
        .map(|i| {
            let s = i as f64;
            [
                2.5 * (0.9 * s).sin(),
                -3.0 * (0.4 * s + 1.0).cos(),
                1.5 + 0.8 * (1.3 * s).sin(),
            ]
        })
        .collect();
    let acc: Vec<Vec3> = (0..n_stamps)
        .map(|i| {
            let s = i as f64;
            [
                3.0 * (0.7 * s).cos(),
                1.0 - 2.0 * (0.5 * s).sin(),
                9.81 + (1.1 * s).sin(),
            ]
        })
        .collect();
    let var = varying_var(n_stamps);
    let hs = [1usize, 5, 12];
    let got = increment_covariance(&t, &gyro, &acc, &var, &hs).unwrap();
    let base = preintegrate(&t, &gyro, &acc).unwrap();
    let h = 1e-6;
    let mut worst = 0.0f64;
    for (&n, c) in hs.iter().zip(&got) {
        let reference = [v3(base.dv[n]), v3(base.dp[n])];
        let q_ref = base.dq_wxyz[n];
        let mut want = M9::zeros();
        for k in 0..n {
            for comp in 0..6 {
                let (mut g, mut a) = (gyro.clone(), acc.clone());
                let x = if comp < 3 { &mut g[k][comp] } else { &mut a[k][comp - 3] };
                *x += h;
                let plus = residual(&t, &g, &a, &reference, q_ref, n);
                let x = if comp < 3 { &mut g[k][comp] } else { &mut a[k][comp - 3] };
                *x -= 2.0 * h;
                let minus = residual(&t, &g, &a, &reference, q_ref, n);
                let col = SMatrix::<f64, 9, 1>::from_fn(|r, _| (plus[r] - minus[r]) / (2.0 * h));
                want += col * col.transpose() * var[k][comp];
            }
        }
        worst = worst.max(rel_err(&m9(c), &want));
    }
    // Central differences: truncation ~h², round-off ~1e-16/h relative.
    assert!(worst < 1e-7, "worst relative error {worst:e}");
}

#[test]
fn covariances_are_exactly_symmetric_and_positive_semidefinite() {
    let t = jittered_stamps(2001, 5_000_000, 1_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let var = varying_var(t.len());
    let hs: Vec<usize> = (1..=20).map(|k| k * 100).collect();
    for (&n, c) in hs
        .iter()
        .zip(increment_covariance(&t, &gyro, &acc, &var, &hs).unwrap().iter())
    {
        let m = m9(c);
        assert_eq!(m, m.transpose(), "n = {n}");
        let eig = SymmetricEigen::new(m).eigenvalues;
        let (lo, hi) = (eig.min(), eig.max());
        assert!(hi > 0.0 && lo >= -1e-12 * hi, "n = {n}: eigenvalues {lo:e}..{hi:e}");
        for i in 0..9 {
            assert!(m[(i, i)] > 0.0, "n = {n}: variance {i} is {}", m[(i, i)]);
        }
    }
}

#[test]
fn intervals_equal_increment_covariances_from_their_own_start() {
    let t = jittered_stamps(501, 5_000_000, 1_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let var = varying_var(t.len());
    let last = t.len() - 1;
    // One interval over everything is the last row, bit for bit.
    let one = interval_covariances(&t, &gyro, &acc, &var, &[0, last]).unwrap();
    let inc = increment_covariance(&t, &gyro, &acc, &var, &[last]).unwrap();
    assert_eq!(one, inc);
    // Every interval is the covariance of the samples from its own start, bit for bit.
    let bounds = [3usize, 50, 51, 400, last];
    let got = interval_covariances(&t, &gyro, &acc, &var, &bounds).unwrap();
    assert_eq!(got.len(), bounds.len() - 1);
    for (i, w) in bounds.windows(2).enumerate() {
        let k = w[0];
        let want = increment_covariance(&t[k..], &gyro[k..], &acc[k..], &var[k..], &[w[1] - k]).unwrap();
        assert_eq!(got[i], want[0], "interval {i}");
    }
    // Fewer than two boundaries: no intervals.
    assert!(interval_covariances(&t, &gyro, &acc, &var, &[]).unwrap().is_empty());
    assert!(interval_covariances(&t, &gyro, &acc, &var, &[7]).unwrap().is_empty());
}

#[test]
fn horizons_in_any_order_and_repeated_land_in_their_own_entries() {
    let t = jittered_stamps(60, 5_000_000, 1_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let var = varying_var(t.len());
    let hs = [40usize, 0, 7, 40, 59];
    let got = increment_covariance(&t, &gyro, &acc, &var, &hs).unwrap();
    assert_eq!(got[1], [[0.0; 9]; 9]);
    for (h, &n) in hs.iter().enumerate() {
        assert_eq!(
            got[h],
            increment_covariance(&t, &gyro, &acc, &var, &[n]).unwrap()[0],
            "horizon {n}"
        );
    }
    assert!(increment_covariance(&t, &gyro, &acc, &var, &[]).unwrap().is_empty());
    assert!(increment_covariance(&[], &[], &[], &[], &[]).unwrap().is_empty());
}

#[test]
fn covariance_is_linear_in_the_variances() {
    let t = jittered_stamps(300, 5_000_000, 1_000_000);
    let (gyro, acc) = wiggly_imu(&t);
    let v1 = varying_var(t.len());
    let v2: Vec<Var6> = v1.iter().rev().map(|r| r.map(|x| 3.0 * x)).collect();
    let sum: Vec<Var6> = v1
        .iter()
        .zip(&v2)
        .map(|(a, b)| std::array::from_fn(|i| a[i] + b[i]))
        .collect();
    let hs = [10usize, 299];
    let (c1, c2, c12) = (
        increment_covariance(&t, &gyro, &acc, &v1, &hs).unwrap(),
        increment_covariance(&t, &gyro, &acc, &v2, &hs).unwrap(),
        increment_covariance(&t, &gyro, &acc, &sum, &hs).unwrap(),
    );
    for h in 0..hs.len() {
        assert!(rel_err(&(m9(&c1[h]) + m9(&c2[h])), &m9(&c12[h])) < 1e-13);
    }
}

fn is_invalid<T: std::fmt::Debug>(r: Result<T, ImuError>, needle: &str) {
    match r {
        Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(needle), "{msg:?} lacks {needle:?}"),
        other => panic!("expected InvalidInput containing {needle:?}, got {other:?}"),
    }
}

#[test]
fn rejects_inconsistent_inputs_with_typed_errors() {
    let t: Vec<i64> = (0..5).map(|i| i * 5_000_000).collect();
    let z = vec![[0.0; 3]; 5];
    let var = vec![[1e-4; 6]; 5];
    let inc = |t: &[i64], g: &[Vec3], a: &[Vec3], v: &[Var6], h: &[usize]| increment_covariance(t, g, a, v, h);
    let ivl = |v: &[Var6], b: &[usize]| interval_covariances(&t, &z, &z, v, b);
    // Lengths.
    is_invalid(inc(&t, &z, &z, &var[..4], &[1]), "var has 4 rows but t_ns has 5");
    is_invalid(ivl(&var[..4], &[0, 1]), "var has 4 rows");
    is_invalid(inc(&t, &z[..4], &z, &var, &[1]), "gyro has 4");
    // Values: NaN, ±inf and negative variances, named by row and column, even in the last row
    // (which enters no horizon) and in rows past the horizons asked for.
    for (row, col, bad) in [
        (1, 0, f64::NAN),
        (2, 4, f64::INFINITY),
        (4, 5, -1e-30),
        (3, 2, f64::NEG_INFINITY),
    ] {
        let mut v = var.clone();
        v[row][col] = bad;
        is_invalid(inc(&t, &z, &z, &v, &[1]), &format!("var[{row}][{col}]"));
        is_invalid(ivl(&v, &[0, 1]), &format!("var[{row}][{col}]"));
    }
    let mut g = z.clone();
    g[2][1] = f64::NAN;
    is_invalid(inc(&t, &g, &z, &var, &[1]), "gyro[2]");
    is_invalid(inc(&[0, 1, 1, 2, 3], &z, &z, &var, &[1]), "strictly increasing");
    // Horizons and boundaries.
    is_invalid(inc(&t, &z, &z, &var, &[1, 5]), "horizon 5 is past the last stamp");
    is_invalid(inc(&[], &[], &[], &[], &[0]), "horizon 0 is past the last stamp");
    is_invalid(ivl(&var, &[0, 5]), "boundary 5");
    is_invalid(ivl(&var, &[usize::MAX]), "boundary");
    is_invalid(
        ivl(&var, &[0, 2, 2]),
        "boundaries[2] = 2 is not after boundaries[1] = 2",
    );
    is_invalid(ivl(&var, &[3, 1]), "strictly increasing");
    // Zero variances are valid (a noiseless axis).
    let mut v = var.clone();
    v[0] = [0.0; 6];
    assert!(inc(&t, &z, &z, &v, &[4]).is_ok());
}
