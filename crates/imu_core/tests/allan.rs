//! The Allan deviation against noise of known strength: white noise of density σ has
//! σ_A(τ) = σ/√τ, a rate random walk of strength K has σ_A(τ) = K √(τ/3), and the slope fits of
//! their sum read back both.

use imu_core::allan::{cluster_sizes, fit_noise, overlapping_adev, DEFAULT_PER_DECADE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

const PERIOD_S: f64 = 0.01;

/// White noise of density `sigma` [unit √s] plus a random walk of strength `k` [unit/√s], two axes
/// (the second the first scaled by 2, so per-axis results can be told apart).
fn noise(n: usize, sigma: f64, k: f64, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut walk = 0.0;
    let mut out = Vec::with_capacity(2 * n);
    for _ in 0..n {
        let w: f64 = rng.sample(StandardNormal);
        let r: f64 = rng.sample(StandardNormal);
        let y = sigma / PERIOD_S.sqrt() * w + walk + 0.7;
        walk += k * PERIOD_S.sqrt() * r;
        out.push(y);
        out.push(2.0 * y);
    }
    out
}

#[test]
fn white_noise_follows_minus_half_slope() {
    let (n, sigma) = (400_000, 1e-3);
    let y = noise(n, sigma, 0.0, 1);
    let d = overlapping_adev(&y, 2, PERIOD_S, &cluster_sizes(n, DEFAULT_PER_DECADE)).unwrap();
    for (j, &tau) in d.tau_s.iter().enumerate() {
        if d.rel_err[j] > 0.1 {
            continue;
        }
        let want = sigma / tau.sqrt();
        // Three standard errors of the estimate.
        assert!(
            (d.adev[2 * j] / want - 1.0).abs() < 3.0 * d.rel_err[j],
            "tau {tau}: {} vs {want}",
            d.adev[2 * j]
        );
        assert!((d.adev[2 * j + 1] - 2.0 * d.adev[2 * j]).abs() < 1e-12 * d.adev[2 * j + 1]);
    }
    let col: Vec<f64> = d.adev.iter().step_by(2).copied().collect();
    let fit = fit_noise(&d.tau_s, &col, &d.rel_err).unwrap();
    assert!((fit.white.value / sigma - 1.0).abs() < 0.03, "{fit:?}");
    assert!(fit.white.tau_lo <= 0.011, "white region starts at the first τ: {fit:?}");
}

#[test]
fn white_noise_plus_random_walk_recovers_both() {
    // Crossover √3 σ/K ≈ 17 s; 2e6 samples at 100 Hz (5.6 h) reach τ = 10^4 s.
    let (n, sigma, k) = (2_000_000, 1e-3, 1e-4);
    let y = noise(n, sigma, k, 7);
    let d = overlapping_adev(&y, 2, PERIOD_S, &cluster_sizes(n, DEFAULT_PER_DECADE)).unwrap();
    for axis in 0..2 {
        let col: Vec<f64> = d.adev.iter().skip(axis).step_by(2).copied().collect();
        let fit = fit_noise(&d.tau_s, &col, &d.rel_err).unwrap();
        let scale = (axis + 1) as f64;
        assert!((fit.white.value / (scale * sigma) - 1.0).abs() < 0.05, "{fit:?}");
        assert!((fit.random_walk.value / (scale * k) - 1.0).abs() < 0.25, "{fit:?}");
        assert!(fit.white.tau_hi < 10.0 && fit.random_walk.tau_lo > 30.0, "{fit:?}");
        // The minimum sits near the crossover, at about √2 × either line there.
        assert!(
            fit.bias_observed && fit.tau_bias > 3.0 && fit.tau_bias < 100.0,
            "{fit:?}"
        );
    }
}
