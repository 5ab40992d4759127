mod common;

use imu_core::align::{align, derive_velocity, AlignOptions};
use imu_core::so3::{angle_between, exp, quat_from_wxyz, quat_to_wxyz, xyzw_to_wxyz};
use imu_core::{GroundTruth, ImuError, ImuSamples, QuatWxyz, Vec3};
use nalgebra::Vector3;

const MS: i64 = 1_000_000;
/// Epoch-sized offset so the tests see the magnitudes of real stamps.
const T0: i64 = 1_403_636_580_000_000_000;

fn secs(t: i64) -> f64 {
    (t - T0) as f64 * 1e-9
}

/// p(t) = p0 + v0 t + ½ a t², so v is linear and Hermite with exact v reproduces p exactly.
fn quad_p(t: f64) -> Vec3 {
    [
        1.0 + 0.5 * t + 0.5 * 0.8 * t * t,
        -2.0 - 1.5 * t + 0.5 * 2.0 * t * t,
        0.3 + 0.1 * t - 0.5 * 0.4 * t * t,
    ]
}
fn quad_v(t: f64) -> Vec3 {
    [0.5 + 0.8 * t, -1.5 + 2.0 * t, 0.1 - 0.4 * t]
}
/// Rotation about a fixed axis at a constant rate, on top of a fixed start attitude.
fn rot_q(t: f64) -> QuatWxyz {
    let q0 = exp(&Vector3::new(0.3, -0.2, 0.5));
    let axis = Vector3::new(1.0, 2.0, -0.5).normalize();
    quat_to_wxyz(&(q0 * exp(&(axis * (1.3 * t)))))
}

fn gt_on(stamps: &[i64], with_v: bool) -> GroundTruth {
    GroundTruth {
        t_ns: stamps.to_vec(),
        p: stamps.iter().map(|&t| quad_p(secs(t))).collect(),
        q_wxyz: stamps.iter().map(|&t| rot_q(secs(t))).collect(),
        v: with_v.then(|| stamps.iter().map(|&t| quad_v(secs(t))).collect()),
        bias_gyro: None,
        bias_acc: None,
    }
}

fn imu_on(stamps: &[i64]) -> ImuSamples {
    ImuSamples {
        t_ns: stamps.to_vec(),
        gyro: stamps.iter().map(|&t| [secs(t), 0.0, 1.0]).collect(),
        acc: stamps.iter().map(|&t| [0.0, secs(t), 9.81]).collect(),
    }
}

/// Non-uniform stamps: spacing alternates between 3, 7 and 11 ms.
fn uneven_stamps(n: usize) -> Vec<i64> {
    let steps = [3 * MS, 7 * MS, 11 * MS];
    let mut t = T0;
    (0..n)
        .map(|i| {
            let out = t;
            t += steps[i % 3];
            out
        })
        .collect()
}

fn max_abs_diff(a: Vec3, b: Vec3) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max)
}

#[test]
fn imu_stamps_on_gt_stamps_reproduce_gt_exactly() {
    let gt_t: Vec<i64> = (0..50).map(|i| T0 + i * 10 * MS).collect();
    let imu_t: Vec<i64> = (0..99).map(|i| T0 + i * 5 * MS).collect();
    for with_v in [true, false] {
        let gt = gt_on(&gt_t, with_v);
        let (seqs, rep) = align(&imu_on(&imu_t), &gt, &AlignOptions::default()).unwrap();
        assert_eq!(seqs.len(), 1);
        assert_eq!(rep.velocity_derived, !with_v);
        let v_ref = match &gt.v {
            Some(v) => v.clone(),
            None => derive_velocity(&gt.t_ns, &gt.p, AlignOptions::default().velocity_half_window),
        };
        let s = &seqs[0];
        assert_eq!(s.t_ns, imu_t);
        for (g, &t) in gt_t.iter().enumerate() {
            let i = s.t_ns.iter().position(|&x| x == t).unwrap();
            assert_eq!(s.p[i], gt.p[g]);
            assert_eq!(s.q_wxyz[i], unit(gt.q_wxyz[g]));
            assert_eq!(s.v[i], v_ref[g]);
        }
        assert_eq!(s.gyro, imu_on(&imu_t).gyro);
    }
}

#[test]
fn smooth_trajectory_is_interpolated_exactly_between_uneven_gt_stamps() {
    let gt_t = uneven_stamps(40);
    let gt = gt_on(&gt_t, true);
    // IMU at 4 ms from 1 ms after the first GT stamp: almost never on a GT stamp.
    let end = *gt_t.last().unwrap();
    let imu_t: Vec<i64> = (0..).map(|i| T0 + MS + i * 4 * MS).take_while(|&t| t <= end).collect();
    let (seqs, rep) = align(&imu_on(&imu_t), &gt, &AlignOptions::default()).unwrap();
    assert_eq!(seqs.len(), 1);
    assert_eq!(rep.kept(), imu_t.len());
    let s = &seqs[0];
    for i in 0..s.len() {
        let t = secs(s.t_ns[i]);
        assert!(max_abs_diff(s.p[i], quad_p(t)) < 1e-12, "p at {t}");
        // Linear interpolation of v is exact because v of a quadratic is linear.
        assert!(max_abs_diff(s.v[i], quad_v(t)) < 1e-12, "v at {t}");
        let err = angle_between(&quat_from_wxyz(s.q_wxyz[i]), &quat_from_wxyz(rot_q(t)));
        assert!(err < 1e-12, "q at {t}: {err}");
    }
}

#[test]
fn velocity_is_interpolated_linearly_not_by_the_hermite_derivative() {
    // Given velocities that disagree with the positions, the midpoint velocity is their mean.
    let gt = GroundTruth {
        t_ns: vec![T0, T0 + 10 * MS],
        p: vec![[0.0; 3], [1.0, 0.0, 0.0]],
        q_wxyz: vec![[1.0, 0.0, 0.0, 0.0]; 2],
        v: Some(vec![[0.0; 3], [2.0, 0.0, 0.0]]),
        bias_gyro: None,
        bias_acc: None,
    };
    let (seqs, _) = align(&imu_on(&[T0, T0 + 5 * MS, T0 + 10 * MS]), &gt, &AlignOptions::default()).unwrap();
    assert_eq!(seqs[0].v[1], [1.0, 0.0, 0.0]);
}

#[test]
fn derive_velocity_is_exact_for_quadratic_positions_on_uneven_stamps() {
    let t = uneven_stamps(30);
    let p: Vec<Vec3> = t.iter().map(|&s| quad_p(secs(s))).collect();
    for hw in [0, 1, 2, 4, 7] {
        let v = derive_velocity(&t, &p, hw);
        assert_eq!(v.len(), t.len());
        for i in 0..t.len() {
            // Includes the shrunken, one-sided fits at both ends.
            let err = max_abs_diff(v[i], quad_v(secs(t[i])));
            assert!(err < 1e-9, "half window {hw}, sample {i}: {err}");
        }
    }
    // Two samples: the line through them; one: zero; none: empty.
    let v2 = derive_velocity(&t[..2], &p[..2], 4);
    let slope = (p[1][0] - p[0][0]) / secs(t[1]);
    assert!((v2[0][0] - slope).abs() < 1e-9 && (v2[1][0] - slope).abs() < 1e-9);
    assert_eq!(derive_velocity(&t[..1], &p[..1], 4), vec![[0.0; 3]]);
    assert!(derive_velocity(&[], &[], 4).is_empty());
}

#[test]
fn derive_velocity_smooths_position_noise() {
    // Deterministic pseudo-noise of ±0.1 mm on a static position at 200 Hz.
    let t: Vec<i64> = (0..2000).map(|i| T0 + i * 5 * MS).collect();
    let mut x: u64 = 12345;
    let p: Vec<Vec3> = t
        .iter()
        .map(|_| {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let u = (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            [2e-4 * u, 0.0, 0.0]
        })
        .collect();
    let rms = |hw: usize| {
        let v = derive_velocity(&t, &p, hw);
        (v[10..1990].iter().map(|v| v[0] * v[0]).sum::<f64>() / 1980.0).sqrt()
    };
    let (r1, r4) = (rms(1), rms(4));
    println!("velocity noise from 0.1 mm position noise: ±1 sample {r1:.4} m/s, ±4 samples {r4:.4} m/s");
    // Theory: 1/√2 vs 1/√60 times σ/Δt, a ratio of 5.5.
    assert!(r1 / r4 > 4.0, "{r1} vs {r4}");
}

#[test]
fn gaps_split_the_ground_truth_and_every_dropped_sample_is_counted() {
    let mut gt_t: Vec<i64> = (0..=100).map(|i| T0 + i * 10 * MS).collect(); // 0..=1000 ms
    gt_t.extend((0..=80).map(|i| T0 + 1200 * MS + i * 10 * MS)); // 1200..=2000 ms
    gt_t.push(T0 + 2500 * MS); // a lone pose
    let imu_t: Vec<i64> = (0..=620).map(|i| T0 - 100 * MS + i * 5 * MS).collect(); // -100..=3000 ms
    let gt = gt_on(&gt_t, false);
    let imu = imu_on(&imu_t);

    let (seqs, rep) = align(&imu, &gt, &AlignOptions::default()).unwrap();
    assert_eq!(rep.imu_samples, 621);
    assert_eq!(rep.dropped_before, 20);
    assert_eq!(rep.dropped_after, 100);
    assert_eq!(rep.dropped_in_gaps, 39 + 99 + 1);
    assert_eq!(rep.dropped_short, 0);
    assert_eq!(
        rep.gaps,
        vec![(T0 + 1000 * MS, T0 + 1200 * MS), (T0 + 2000 * MS, T0 + 2500 * MS)]
    );
    assert_eq!(seqs.len(), 2);
    assert_eq!((rep.segments[0].start_ns, rep.segments[0].end_ns), (T0, T0 + 1000 * MS));
    assert_eq!(
        (rep.segments[1].start_ns, rep.segments[1].end_ns),
        (T0 + 1200 * MS, T0 + 2000 * MS)
    );
    assert_eq!(
        rep.segments.iter().map(|s| s.samples).collect::<Vec<_>>(),
        vec![201, 161]
    );
    assert_eq!(seqs[0].len(), 201);
    assert_eq!(seqs[1].len(), 161);
    assert_eq!(rep.kept() + 20 + 100 + 139, 621);

    // Velocity is derived per segment: the positions jump by 1 m across the first gap, which a
    // fit reaching across it would turn into metres per second at the gap edges.
    let mut jumped = gt.clone();
    for p in &mut jumped.p[101..] {
        p[0] += 1.0;
    }
    let (seqs_j, _) = align(&imu, &jumped, &AlignOptions::default()).unwrap();
    for (s, i) in [(&seqs_j[0], 200), (&seqs_j[1], 0)] {
        let err = max_abs_diff(s.v[i], quad_v(secs(s.t_ns[i])));
        assert!(err < 1e-9, "velocity at the gap edge off by {err}");
    }

    // A larger minimum drops the second segment as short.
    let opts = AlignOptions {
        min_segment_samples: 180,
        ..AlignOptions::default()
    };
    let (seqs, rep) = align(&imu, &gt, &opts).unwrap();
    assert_eq!(seqs.len(), 1);
    assert_eq!(rep.dropped_short, 161);
    assert_eq!(rep.kept(), 201);

    // A wider gap tolerance bridges the 200 ms hole but not the 500 ms one.
    let opts = AlignOptions {
        max_gap_ns: 300 * MS,
        ..AlignOptions::default()
    };
    let (seqs, rep) = align(&imu, &gt, &opts).unwrap();
    assert_eq!(seqs.len(), 1);
    assert_eq!(rep.gaps.len(), 1);
    assert_eq!(seqs[0].len(), 401);
}

#[test]
fn unusable_inputs_give_clear_errors() {
    let gt_t: Vec<i64> = (0..20).map(|i| T0 + i * 10 * MS).collect();
    let gt = gt_on(&gt_t, true);
    let opts = AlignOptions::default();

    let late: Vec<i64> = (0..20).map(|i| T0 + 10_000 * MS + i * 5 * MS).collect();
    match align(&imu_on(&late), &gt, &opts) {
        Err(e @ ImuError::NoOverlap { .. }) => assert!(e.to_string().contains("never overlap"), "{e}"),
        other => panic!("expected an alignment error, got {other:?}"),
    }
    let one = gt_on(&gt_t[..1], true);
    match align(&imu_on(&gt_t), &one, &opts) {
        Err(ImuError::Alignment(m)) => assert!(m.contains("1 pose"), "{m}"),
        other => panic!("expected an alignment error, got {other:?}"),
    }
    let mut bad_imu = imu_on(&gt_t);
    bad_imu.acc.pop();
    assert!(matches!(align(&bad_imu, &gt, &opts), Err(ImuError::InvalidInput(_))));
    let mut bad_gt = gt.clone();
    bad_gt.v.as_mut().unwrap().pop();
    assert!(matches!(
        align(&imu_on(&gt_t), &bad_gt, &opts),
        Err(ImuError::InvalidInput(_))
    ));
    let mut unsorted = imu_on(&gt_t);
    unsorted.t_ns.swap(3, 4);
    assert!(matches!(align(&unsorted, &gt, &opts), Err(ImuError::InvalidInput(_))));
    assert!(matches!(
        align(&imu_on(&[]), &gt, &opts),
        Err(ImuError::InvalidInput(_))
    ));
    let zero_gap = AlignOptions {
        max_gap_ns: 0,
        ..opts.clone()
    };
    assert!(matches!(
        align(&imu_on(&gt_t), &gt, &zero_gap),
        Err(ImuError::InvalidInput(_))
    ));
    // Overlap, but every segment too short.
    let huge = AlignOptions {
        min_segment_samples: 1000,
        ..opts
    };
    match align(&imu_on(&gt_t), &gt, &huge) {
        Err(ImuError::Alignment(m)) => assert!(m.contains("at least 1000"), "{m}"),
        other => panic!("expected an alignment error, got {other:?}"),
    }
}

// ---- real data: EuRoC MH_01_easy ------------------------------------------------------------

/// "1403636580.83856" → ns, exactly (no float round trip).
fn tum_stamp_ns(s: &str) -> i64 {
    let (int, frac) = s.split_once('.').unwrap_or((s, ""));
    let frac9 = format!("{frac:0<9}");
    int.parse::<i64>().unwrap() * 1_000_000_000 + frac9[..9].parse::<i64>().unwrap()
}

fn read_euroc_imu(path: &str) -> ImuSamples {
    let mut imu = ImuSamples::default();
    for line in std::fs::read_to_string(path).unwrap().lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let x: Vec<f64> = f[1..7].iter().map(|s| s.parse().unwrap()).collect();
        imu.t_ns.push(f[0].parse().unwrap());
        imu.gyro.push([x[0], x[1], x[2]]);
        imu.acc.push([x[3], x[4], x[5]]);
    }
    imu
}

fn read_tum(path: &str) -> GroundTruth {
    let mut gt = GroundTruth::default();
    for line in std::fs::read_to_string(path).unwrap().lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let x: Vec<f64> = f[1..8].iter().map(|s| s.parse().unwrap()).collect();
        gt.t_ns.push(tum_stamp_ns(f[0]));
        gt.p.push([x[0], x[1], x[2]]);
        gt.q_wxyz.push(xyzw_to_wxyz([x[3], x[4], x[5], x[6]]));
    }
    gt
}

#[test]
fn euroc_mh01_aligns_over_the_whole_ground_truth_span() {
    let (imu_rel, gt_rel) = (
        "euroc/MH_01_easy/mav0/imu0/data.csv",
        "euroc/MH_01_easy/groundtruth_pose.tum",
    );
    if !(common::have(imu_rel) && common::have(gt_rel)) {
        return;
    }
    let imu = read_euroc_imu(common::data(imu_rel).to_str().unwrap());
    let gt = read_tum(common::data(gt_rel).to_str().unwrap());
    let (seqs, rep) = align(&imu, &gt, &AlignOptions::default()).unwrap();
    println!(
        "MH_01: {} IMU samples, {} GT poses; kept {} in {} segment(s); dropped {} before, {} after, \
         {} in {} gap(s), {} in short segments",
        rep.imu_samples,
        gt.len(),
        rep.kept(),
        rep.segments.len(),
        rep.dropped_before,
        rep.dropped_after,
        rep.dropped_in_gaps,
        rep.gaps.len(),
        rep.dropped_short
    );
    assert!(rep.velocity_derived);
    assert_eq!(
        rep.kept() + rep.dropped_before + rep.dropped_after + rep.dropped_in_gaps + rep.dropped_short,
        imu.len()
    );
    let (g0, g1) = (gt.t_ns[0], *gt.t_ns.last().unwrap());
    let first = rep.segments.first().unwrap();
    let last = rep.segments.last().unwrap();
    // The IMU runs at 200 Hz across the whole GT span, so the kept samples reach within one IMU
    // period of both GT ends.
    assert!(first.start_ns >= g0 && first.start_ns - g0 < 5 * MS + MS / 10);
    assert!(last.end_ns <= g1 && g1 - last.end_ns < 5 * MS + MS / 10);
    let s = &seqs[0];
    // GT and IMU share the 5 ms grid here: on-grid samples copy the GT rows.
    let g = gt.t_ns.partition_point(|&t| t < s.t_ns[0]);
    if gt.t_ns[g] == s.t_ns[0] {
        assert_eq!(s.p[0], gt.p[g]);
        assert_eq!(s.q_wxyz[0], unit(gt.q_wxyz[g]));
    }
    // Derived speeds of a hand-flown MAV stay well below 5 m/s.
    let vmax = seqs
        .iter()
        .flat_map(|s| s.v.iter())
        .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .fold(0.0, f64::max);
    println!("MH_01: max derived speed {vmax:.3} m/s");
    assert!(vmax > 0.1 && vmax < 5.0, "{vmax}");
}

/// What alignment stores for a file quaternion: the same rotation, normalised.
fn unit(q: [f64; 4]) -> [f64; 4] {
    imu_core::so3::quat_to_wxyz(&imu_core::so3::quat_from_wxyz(q))
}
