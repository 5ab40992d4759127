// Index loops mirror the B×W×6 layout being checked.
#![allow(clippy::needless_range_loop)]

use imu_core::batch::{eval_windows, make_batch, AugmentConfig, Batch, BatchConfig};
use imu_core::labels::{increment, window_starts, PAPER_FRACTIONS};
use imu_core::so3::{exp, quat_to_wxyz};
use imu_core::{ImuError, Sequence, GRAVITY};
use nalgebra::Vector3;

const T0: i64 = 1_403_636_580_000_000_000;

/// A smooth synthetic sequence whose sample intervals alternate 4 ms / 6 ms, so per-sample dt
/// matters. `phase` makes sequences distinguishable.
fn sequence(n: usize, phase: f64) -> Sequence {
    let mut t_ns = Vec::with_capacity(n);
    let mut t = T0;
    for i in 0..n {
        t_ns.push(t);
        t += if i % 2 == 0 { 4_000_000 } else { 6_000_000 };
    }
    let s = |t: i64| (t - T0) as f64 * 1e-9;
    Sequence {
        gyro: t_ns.iter().map(|&t| [(s(t) + phase).sin(), 0.2, -0.1 * s(t)]).collect(),
        acc: t_ns.iter().map(|&t| [0.3, (2.0 * s(t) + phase).cos(), 9.81]).collect(),
        p: t_ns.iter().map(|&t| [s(t) * s(t), phase, -s(t)]).collect(),
        v: t_ns.iter().map(|&t| [2.0 * s(t), 0.0, -1.0]).collect(),
        q_wxyz: t_ns
            .iter()
            .map(|&t| quat_to_wxyz(&exp(&Vector3::new(0.1, phase, 0.7 * s(t)))))
            .collect(),
        t_ns,
    }
}

fn seqs() -> Vec<Sequence> {
    vec![
        sequence(300, 0.0),
        sequence(50, 1.0),
        sequence(20, 2.0),
        sequence(500, 3.0),
    ]
}

fn cfg(augment: AugmentConfig) -> BatchConfig {
    BatchConfig {
        window: 40,
        batch_size: 256,
        fractions: PAPER_FRACTIONS.to_vec(),
        gravity: GRAVITY,
        augment,
    }
}

fn full_augment() -> AugmentConfig {
    AugmentConfig {
        gyro_noise_density: 1.7e-4,
        acc_noise_density: 2.0e-3,
        gyro_bias_max: 0.02,
        acc_bias_max: 0.1,
        gyro_bias_walk: 1.9e-5,
        acc_bias_walk: 3.0e-3,
    }
}

fn raw_row(s: &Sequence, k: usize) -> [f64; 6] {
    let (g, a) = (s.gyro[k], s.acc[k]);
    [g[0], g[1], g[2], a[0], a[1], a[2]]
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Raw samples and labels of a batch match its sequences at the recorded starts.
fn check_raw_and_labels(b: &Batch, seqs: &[Sequence], w: usize) {
    let h = b.horizons.len();
    for j in 0..b.len() {
        let s = &seqs[b.seq_index[j] as usize];
        let k = b.start[j] as usize;
        assert!(k + w < s.len());
        for i in 0..w {
            let dt = (s.t_ns[k + i + 1] - s.t_ns[k + i]) as f64 * 1e-9;
            assert_eq!(b.dt[j * w + i], dt);
        }
        for (hh, &n) in b.horizons.iter().enumerate() {
            let inc = increment(s, k, n, GRAVITY).unwrap();
            assert_eq!(b.dq_wxyz[j * h + hh], inc.dq_wxyz);
            assert_eq!(b.dv[j * h + hh], inc.dv);
            assert_eq!(b.dp[j * h + hh], inc.dp);
            assert_eq!(b.label_dt[j * h + hh], inc.dt);
        }
    }
}

#[test]
fn same_seed_gives_the_same_batch_on_one_or_two_threads() {
    let seqs = seqs();
    let c = cfg(full_augment());
    let one = in_pool(1, || make_batch(&seqs, &c, 42)).unwrap();
    let two = in_pool(2, || make_batch(&seqs, &c, 42)).unwrap();
    let again = in_pool(2, || make_batch(&seqs, &c, 42)).unwrap();
    assert_eq!(one, two);
    assert_eq!(two, again);
    let other = make_batch(&seqs, &c, 43).unwrap();
    assert_ne!(one.start, other.start);
    assert_ne!(one.imu, other.imu);
}

#[test]
fn without_augmentation_windows_are_the_raw_samples_with_gt_labels() {
    let seqs = seqs();
    let c = cfg(AugmentConfig::default());
    let b = make_batch(&seqs, &c, 7).unwrap();
    let w = c.window;
    assert_eq!(b.len(), 256);
    assert_eq!(b.window(), w);
    assert_eq!(b.horizons, vec![8, 16, 24, 32, 40]);
    assert_eq!(
        (b.imu.len(), b.bias.len(), b.dt.len(), b.dq_wxyz.len()),
        (256 * w * 6, 256 * w * 6, 256 * w, 256 * 5)
    );
    for j in 0..b.len() {
        let s = &seqs[b.seq_index[j] as usize];
        let k = b.start[j] as usize;
        for i in 0..w {
            assert_eq!(b.imu[(j * w + i) * 6..(j * w + i) * 6 + 6], raw_row(s, k + i));
        }
    }
    assert!(b.bias.iter().all(|&x| x == 0.0));
    check_raw_and_labels(&b, &seqs, w);
    // Sequence 2 (20 samples) holds no 40-sample window; the others are drawn roughly in
    // proportion to their window counts 260 : 10 : 0 : 460.
    let count = |i: u32| b.seq_index.iter().filter(|&&s| s == i).count();
    assert_eq!(count(2), 0);
    assert!(
        count(0) > 50 && count(3) > 110 && count(3) > count(0),
        "{} {}",
        count(0),
        count(3)
    );
}

#[test]
fn bias_only_adds_a_bounded_constant_per_window() {
    let seqs = seqs();
    let aug = AugmentConfig {
        gyro_bias_max: 0.02,
        acc_bias_max: 0.1,
        ..AugmentConfig::default()
    };
    let c = BatchConfig {
        batch_size: 2000,
        ..cfg(aug)
    };
    let b = make_batch(&seqs, &c, 1).unwrap();
    let w = c.window;
    let mut seen_max = [0.0f64; 6];
    let mut mean = [0.0f64; 6];
    for j in 0..b.len() {
        let s = &seqs[b.seq_index[j] as usize];
        let k = b.start[j] as usize;
        let first: Vec<f64> = b.bias[j * w * 6..j * w * 6 + 6].to_vec();
        for i in 0..w {
            let r = (j * w + i) * 6;
            let raw = raw_row(s, k + i);
            for c in 0..6 {
                assert!((b.imu[r + c] - raw[c] - b.bias[r + c]).abs() < 1e-12);
                assert_eq!(b.bias[r + c], first[c], "bias not constant over the window");
            }
        }
        for c in 0..6 {
            let bound = if c < 3 { 0.02 } else { 0.1 };
            assert!(first[c].abs() <= bound);
            seen_max[c] = seen_max[c].max(first[c].abs() / bound);
            mean[c] += first[c] / bound / b.len() as f64;
        }
    }
    // Uniform on [-max, max]: 2000 draws reach past 0.99·max, mean 0 ± ~0.013.
    for c in 0..6 {
        assert!(seen_max[c] > 0.99, "axis {c}: {}", seen_max[c]);
        assert!(mean[c].abs() < 0.05, "axis {c}: {}", mean[c]);
    }
    check_raw_and_labels(&b, &seqs, w);
}

#[test]
fn white_noise_has_std_density_over_sqrt_dt_per_sample() {
    let seqs = seqs();
    let (gd, ad) = (1.7e-4, 2.0e-3);
    let aug = AugmentConfig {
        gyro_noise_density: gd,
        acc_noise_density: ad,
        ..AugmentConfig::default()
    };
    let c = BatchConfig {
        batch_size: 1000,
        ..cfg(aug)
    };
    let b = make_batch(&seqs, &c, 3).unwrap();
    let w = c.window;
    // Normalised residuals z = (imu − raw)·√dt/density should be N(0, 1); check by dt class so a
    // wrong dt (e.g. a mean dt for all samples) would show as 4 ms and 6 ms disagreeing.
    let mut sums = [[0.0f64; 3]; 2]; // [short/long dt][n, Σz, Σz²]
    for j in 0..b.len() {
        let s = &seqs[b.seq_index[j] as usize];
        let k = b.start[j] as usize;
        for i in 0..w {
            let r = (j * w + i) * 6;
            let dt = b.dt[j * w + i];
            let raw = raw_row(s, k + i);
            let class = usize::from(dt > 0.005);
            for c in 0..6 {
                let d = if c < 3 { gd } else { ad };
                let z = (b.imu[r + c] - raw[c]) * dt.sqrt() / d;
                sums[class][0] += 1.0;
                sums[class][1] += z;
                sums[class][2] += z * z;
            }
        }
    }
    for (class, [n, s1, s2]) in sums.iter().enumerate() {
        let mean = s1 / n;
        let std = (s2 / n - mean * mean).sqrt();
        println!("dt class {class}: {n} samples, mean {mean:.4}, std {std:.4}");
        // n = 120,000 per class: std of the std estimate ≈ 0.002.
        assert!(mean.abs() < 0.02, "{mean}");
        assert!((std - 1.0).abs() < 0.02, "{std}");
    }
    assert!(b.bias.iter().all(|&x| x == 0.0));
}

#[test]
fn bias_walk_spreads_like_sqrt_time() {
    let seqs = seqs();
    let (gw, aw) = (1.9e-5, 3.0e-3);
    let aug = AugmentConfig {
        gyro_bias_walk: gw,
        acc_bias_walk: aw,
        ..AugmentConfig::default()
    };
    let c = BatchConfig {
        window: 80,
        batch_size: 4000,
        ..cfg(aug)
    };
    let b = make_batch(&seqs, &c, 11).unwrap();
    let w = c.window;
    for &i in &[10usize, 40, 79] {
        let mut z2 = 0.0;
        let mut n = 0.0;
        for j in 0..b.len() {
            // Elapsed time from the window start to sample i.
            let t: f64 = b.dt[j * w..j * w + i].iter().sum();
            for c in 0..6 {
                let r0 = j * w * 6 + c;
                assert_eq!(b.bias[r0], 0.0, "no constant part configured");
                let d = b.bias[r0 + i * 6] - b.bias[r0];
                let z = d / ((if c < 3 { gw } else { aw }) * t.sqrt());
                z2 += z * z;
                n += 1.0;
            }
        }
        let rms = (z2 / n).sqrt();
        println!("walk at sample {i}: normalised rms {rms:.4}");
        assert!((rms - 1.0).abs() < 0.03, "sample {i}: {rms}");
    }
}

#[test]
fn eval_windows_lists_every_strided_window_unaugmented() {
    let seqs = seqs();
    let (w, stride) = (40, 7);
    let b = eval_windows(&seqs, w, stride, &PAPER_FRACTIONS, GRAVITY).unwrap();
    let mut expect = Vec::new();
    for (i, s) in seqs.iter().enumerate() {
        expect.extend(
            window_starts(s.len(), w, stride)
                .unwrap()
                .into_iter()
                .map(|k| (i as u32, k as u64)),
        );
    }
    let got: Vec<(u32, u64)> = b.seq_index.iter().copied().zip(b.start.iter().copied()).collect();
    assert_eq!(got, expect);
    for j in 0..b.len() {
        let s = &seqs[b.seq_index[j] as usize];
        let k = b.start[j] as usize;
        for i in 0..w {
            assert_eq!(b.imu[(j * w + i) * 6..(j * w + i) * 6 + 6], raw_row(s, k + i));
        }
    }
    assert!(b.bias.iter().all(|&x| x == 0.0));
    check_raw_and_labels(&b, &seqs, w);
    assert_eq!(
        in_pool(1, || eval_windows(&seqs, w, stride, &PAPER_FRACTIONS, GRAVITY)).unwrap(),
        b
    );
}

#[test]
fn bad_requests_are_invalid_input() {
    let seqs = seqs();
    let invalid = |r: Result<Batch, ImuError>| match r {
        Err(ImuError::InvalidInput(m)) => m,
        other => panic!("expected InvalidInput, got {other:?}"),
    };
    let m = invalid(make_batch(
        &seqs,
        &BatchConfig {
            window: 500,
            ..cfg(AugmentConfig::default())
        },
        0,
    ));
    assert!(m.contains("longest") && m.contains("500"), "{m}");
    invalid(make_batch(
        &seqs,
        &BatchConfig {
            batch_size: 0,
            ..cfg(AugmentConfig::default())
        },
        0,
    ));
    invalid(make_batch(&[], &cfg(AugmentConfig::default()), 0));
    invalid(make_batch(
        &seqs,
        &BatchConfig {
            window: 0,
            ..cfg(AugmentConfig::default())
        },
        0,
    ));
    invalid(make_batch(
        &seqs,
        &BatchConfig {
            fractions: vec![],
            ..cfg(AugmentConfig::default())
        },
        0,
    ));
    invalid(make_batch(
        &seqs,
        &BatchConfig {
            fractions: vec![1.5],
            ..cfg(AugmentConfig::default())
        },
        0,
    ));
    let neg = AugmentConfig {
        acc_noise_density: -1.0,
        ..AugmentConfig::default()
    };
    invalid(make_batch(&seqs, &cfg(neg), 0));
    let mut broken = seqs.clone();
    broken[1].v.pop();
    invalid(make_batch(&broken, &cfg(AugmentConfig::default()), 0));
    let mut unsorted = seqs.clone();
    unsorted[0].t_ns.swap(5, 6);
    invalid(make_batch(&unsorted, &cfg(AugmentConfig::default()), 0));
    invalid(eval_windows(&seqs, 500, 1, &PAPER_FRACTIONS, GRAVITY));
    invalid(eval_windows(&seqs, 40, 0, &PAPER_FRACTIONS, GRAVITY));
    invalid(eval_windows(&[], 40, 1, &PAPER_FRACTIONS, GRAVITY));
}

#[test]
fn a_batch_too_large_to_allocate_is_an_error_not_an_abort() {
    let s = seqs();
    for batch_size in [1usize << 40, 1 << 62, usize::MAX] {
        let c = BatchConfig {
            batch_size,
            ..cfg(AugmentConfig::default())
        };
        match make_batch(&s, &c, 0) {
            Err(ImuError::InvalidInput(msg)) => {
                // Past isize::MAX bytes it is refused outright; below, the allocation is tried and
                // fails as an error (never an abort).
                assert!(msg.starts_with("batch_size:"), "{msg}");
                assert!(
                    msg.contains("more than one allocation") || msg.contains("cannot be allocated"),
                    "{msg}"
                );
            }
            other => panic!("batch_size {batch_size}: expected InvalidInput, got {other:?}"),
        }
    }
    assert_eq!(
        imu_core::batch::batch_bytes(2, 3, 4, "x").unwrap(),
        2 * 3 * 13 * 8 + 2 * 4 * 11 * 8 + 2 * 12
    );
    // A huge window is "too short", and its message does not overflow computing window + 1.
    for window in [1usize << 40, usize::MAX] {
        let c = BatchConfig {
            window,
            ..cfg(AugmentConfig::default())
        };
        match make_batch(&s, &c, 0) {
            Err(ImuError::InvalidInput(msg)) => assert!(msg.contains("needs"), "{msg}"),
            other => panic!("window {window}: expected InvalidInput, got {other:?}"),
        }
        assert!(eval_windows(&s, window, 1, &PAPER_FRACTIONS, GRAVITY).is_err());
    }
}
