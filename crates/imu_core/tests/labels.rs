mod common;

use common::{jittered_stamps, rot_err, synthetic_sequence, vec_err};
use imu_core::integrate::integrate_windows;
use imu_core::labels::{
    check_sequence, check_windows, horizons, increment, labels_at, window_labels, window_starts, PAPER_FRACTIONS,
};
use imu_core::so3::{self, arr3, quat_to_wxyz, v3};
use imu_core::types::{Sequence, GRAVITY};
use imu_core::ImuError;
use nalgebra::Vector3;

fn invalid<T: std::fmt::Debug>(r: imu_core::Result<T>, needle: &str) {
    match r {
        Err(ImuError::InvalidInput(msg)) => assert!(msg.contains(needle), "{msg:?} lacks {needle:?}"),
        other => panic!("expected InvalidInput containing {needle:?}, got {other:?}"),
    }
}

fn small_seq(n: usize) -> Sequence {
    let t = jittered_stamps(n, 10_000_000, 2_000_000);
    synthetic_sequence(&t, GRAVITY)
}

#[test]
fn horizons_round_to_nearest_and_stay_within_one_and_the_window() {
    assert_eq!(horizons(200, &PAPER_FRACTIONS).unwrap(), vec![40, 80, 120, 160, 200]);
    // 1.4, 2.8, 4.2, 5.6, 7 samples.
    assert_eq!(horizons(7, &PAPER_FRACTIONS).unwrap(), vec![1, 3, 4, 6, 7]);
    // A tiny fraction would round to 0 samples; the shortest horizon is one sample.
    assert_eq!(horizons(10, &[0.01, 1e-300]).unwrap(), vec![1, 1]);
    assert_eq!(horizons(1, &PAPER_FRACTIONS).unwrap(), vec![1; 5]);
    assert_eq!(horizons(10, &[]).unwrap(), Vec::<usize>::new());
    invalid(horizons(0, &[0.5]), "window must be at least 1");
    for bad in [0.0, -0.2, 1.0 + 1e-12, f64::NAN, f64::INFINITY] {
        invalid(horizons(10, &[0.5, bad]), "is not in (0, 1]");
    }
}

#[test]
fn window_starts_cover_exactly_the_windows_that_fit() {
    // A window of 3 samples needs states k..=k+3, so the last start in 10 stamps is 6.
    assert_eq!(window_starts(10, 3, 2).unwrap(), vec![0, 2, 4, 6]);
    assert_eq!(window_starts(10, 3, 1).unwrap(), (0..=6).collect::<Vec<_>>());
    assert_eq!(window_starts(10, 3, 4).unwrap(), vec![0, 4]);
    assert_eq!(window_starts(4, 3, 1).unwrap(), vec![0]);
    assert_eq!(window_starts(3, 3, 1).unwrap(), Vec::<usize>::new());
    assert_eq!(window_starts(0, 3, 1).unwrap(), Vec::<usize>::new());
    assert_eq!(window_starts(10, 3, 100).unwrap(), vec![0]);
    assert_eq!(window_starts(2, 1, 1).unwrap(), vec![0]);
    assert_eq!(window_starts(5, usize::MAX, 1).unwrap(), Vec::<usize>::new());
    invalid(window_starts(10, 3, 0), "stride");
    invalid(window_starts(10, 0, 1), "window");
}

#[test]
fn labels_at_rejects_windows_past_the_end_without_overflowing() {
    let seq = small_seq(20);
    assert!(labels_at(&seq, &[0, 10], &[9], GRAVITY).is_ok());
    invalid(
        labels_at(&seq, &[0, 10], &[10, 2], GRAVITY),
        "window start 10 + horizon 10",
    );
    invalid(labels_at(&seq, &[usize::MAX], &[1], GRAVITY), "past the sequence end");
    invalid(labels_at(&seq, &[20], &[], GRAVITY), "window start 20");
    let empty = labels_at(&seq, &[], &[3], GRAVITY).unwrap();
    assert!(empty.dt.is_empty() && empty.starts.is_empty());
}

#[test]
fn increment_checks_its_indices() {
    let seq = small_seq(10);
    assert!(increment(&seq, 3, 6, GRAVITY).is_ok());
    invalid(increment(&seq, 3, 7, GRAVITY), "past the sequence end");
    invalid(increment(&seq, usize::MAX, 1, GRAVITY), "past the sequence end");
    let id = increment(&seq, 4, 0, GRAVITY).unwrap();
    assert_eq!((id.dv, id.dp, id.dt), ([0.0; 3], [0.0; 3], 0.0));
    assert!(rot_err(id.dq_wxyz, [1.0, 0.0, 0.0, 0.0]) < 1e-15);
}

#[test]
fn check_sequence_names_the_lengths() {
    let good = small_seq(5);
    assert!(check_sequence(&good).is_ok());
    let mut variants = Vec::new();
    let mut s = good.clone();
    s.gyro.pop();
    variants.push(s);
    let mut s = good.clone();
    s.acc.push([0.0; 3]);
    variants.push(s);
    let mut s = good.clone();
    s.p.clear();
    variants.push(s);
    let mut s = good.clone();
    s.v.pop();
    variants.push(s);
    let mut s = good.clone();
    s.q_wxyz.pop();
    variants.push(s);
    let mut s = good.clone();
    s.t_ns.pop();
    variants.push(s);
    for s in &variants {
        invalid(check_sequence(s), "sequence arrays differ in length");
        invalid(labels_at(s, &[0], &[1], GRAVITY), "differ in length");
        invalid(increment(s, 0, 1, GRAVITY), "differ in length");
    }
    invalid(check_sequence(&variants[0]), "t_ns 5, gyro/acc/p/v/q [4, 5, 5, 5, 5]");
}

#[test]
fn window_labels_are_row_major_over_windows_and_horizons() {
    let seq = small_seq(60);
    let l = window_labels(&seq, 20, 7, &PAPER_FRACTIONS, GRAVITY).unwrap();
    assert_eq!(l.starts, vec![0, 7, 14, 21, 28, 35]);
    assert_eq!(l.horizons, vec![4, 8, 12, 16, 20]);
    assert_eq!(l.dt.len(), 30);
    for (w, &k) in l.starts.iter().enumerate() {
        for (h, &n) in l.horizons.iter().enumerate() {
            let e = w * l.horizons.len() + h;
            let inc = increment(&seq, k, n, GRAVITY).unwrap();
            assert_eq!(
                (l.dq_wxyz[e], l.dv[e], l.dp[e], l.dt[e]),
                (inc.dq_wxyz, inc.dv, inc.dp, inc.dt)
            );
            assert_eq!(l.dt[e], (seq.t_ns[k + n] - seq.t_ns[k]) as f64 * 1e-9);
        }
    }
}

#[test]
fn a_resting_tilted_imu_reads_minus_gravity_and_the_labels_agree() {
    // At rest the accelerometer measures Rᵀ(0 − g) = Rᵀ[0, 0, 9.81]; integrating that reproduces
    // Δβ = R_kᵀ(−g Δt) and Δγ = R_kᵀ(−½ g Δt²) with no discretisation error.
    let n = 50;
    let t = jittered_stamps(n, 5_000_000, 1_000_000);
    let q = so3::exp(&Vector3::new(0.4, -0.9, 2.0));
    let f = q.inverse() * Vector3::new(0.0, 0.0, GRAVITY);
    let seq = Sequence {
        t_ns: t.clone(),
        gyro: vec![[0.0; 3]; n],
        acc: vec![arr3(&f); n],
        p: vec![[1.0, 2.0, 3.0]; n],
        v: vec![[0.0; 3]; n],
        q_wxyz: vec![quat_to_wxyz(&q); n],
    };
    let gt = window_labels(&seq, 10, 3, &PAPER_FRACTIONS, GRAVITY).unwrap();
    let imu = integrate_windows(&seq.t_ns, &seq.gyro, &seq.acc, &gt.starts, &gt.horizons).unwrap();
    for i in 0..gt.dt.len() {
        let s = gt.dt[i];
        assert!(vec_err(gt.dv[i], arr3(&(f * s))) < 1e-13);
        assert!(vec_err(gt.dv[i], imu.dv[i]) < 1e-13, "{i}");
        assert!(vec_err(gt.dp[i], imu.dp[i]) < 1e-13, "{i}");
        assert!(rot_err(gt.dq_wxyz[i], imu.dq_wxyz[i]) < 1e-15);
        assert!(v3(gt.dp[i]).norm() > 0.0);
    }
}

#[test]
fn labels_are_independent_of_the_world_origin_and_heading() {
    // Δq, Δβ, Δγ live in the body frame at t_k: moving the world origin or turning it about the
    // gravity axis (with velocities turned too) must leave them unchanged.
    let seq = small_seq(40);
    let yaw = so3::exp(&Vector3::new(0.0, 0.0, 1.234));
    let shift = Vector3::new(-50.0, 7.0, 3.0);
    let mut moved = seq.clone();
    for i in 0..seq.len() {
        moved.p[i] = arr3(&(yaw * v3(seq.p[i]) + shift));
        moved.v[i] = arr3(&(yaw * v3(seq.v[i])));
        moved.q_wxyz[i] = quat_to_wxyz(&(yaw * so3::quat_from_wxyz(seq.q_wxyz[i])));
    }
    let a = window_labels(&seq, 10, 5, &PAPER_FRACTIONS, GRAVITY).unwrap();
    let b = window_labels(&moved, 10, 5, &PAPER_FRACTIONS, GRAVITY).unwrap();
    for i in 0..a.dt.len() {
        assert!(rot_err(a.dq_wxyz[i], b.dq_wxyz[i]) < 1e-14);
        assert!(vec_err(a.dv[i], b.dv[i]) < 1e-12);
        assert!(vec_err(a.dp[i], b.dp[i]) < 1e-12);
    }
}

#[test]
fn window_arguments_are_checked_before_any_buffer_is_sized() {
    let seq = small_seq(20);
    // No starts still checks the horizons: a huge one used to size buffers before any check.
    invalid(
        labels_at(&seq, &[], &[1 << 40], GRAVITY),
        "horizons[0] = 1099511627776 is past the sequence end",
    );
    invalid(labels_at(&seq, &[], &[2, usize::MAX], GRAVITY), "horizons[1]");
    invalid(
        labels_at(&seq, &[0], &[0], GRAVITY),
        "horizons[0] = 0: a horizon must be at least 1 sample",
    );
    invalid(labels_at(&seq, &[0], &[20], GRAVITY), "allows horizons 1..=19");
    invalid(
        labels_at(&seq, &[0, 3, 15], &[5], GRAVITY),
        "starts[2]: window start 15 + horizon 5",
    );
    assert_eq!(check_windows(20, &[0, 14], &[5, 2]).unwrap(), 5);
    assert_eq!(check_windows(0, &[], &[]).unwrap(), 0);
    invalid(check_windows(1, &[], &[1]), "no horizon fits");
    // The same checks, in the same words, for the IMU side.
    invalid(
        integrate_windows(&seq.t_ns, &seq.gyro, &seq.acc, &[], &[1 << 40]),
        "horizons[0] = 1099511627776 is past the sequence end",
    );
    // window_labels on a sequence shorter than its window: no windows, not an error.
    let short = window_labels(&seq, 1 << 40, 1, &PAPER_FRACTIONS, GRAVITY).unwrap();
    assert!(short.starts.is_empty() && short.dt.is_empty());
    assert_eq!(short.horizons.len(), PAPER_FRACTIONS.len());
}
