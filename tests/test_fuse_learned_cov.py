"""Fusion with per-sample (learned) IMU noise: GTSAM's factor with the datasheet's constant noise is
the oracle for the per-sample path, each factor carries the covariance propagated over its own
interval, and the variances change the estimate where they should."""
import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from imu_learn.data.synthetic import spin_and_climb  # noqa: E402
from imu_learn.fuse import ImuNoise, PositionFixes, fuse  # noqa: E402
from imu_learn.fuse.graph import IncrementalFusion  # noqa: E402
from imu_learn.fuse.settings import FusionSettings  # noqa: E402


def noisy_run(seed=3):
    rng = np.random.default_rng(seed)
    t, gyro, acc, p, R = spin_and_climb()
    gyro = gyro + 0.005 + rng.normal(0, 0.002, gyro.shape)
    acc = acc + 0.05 + rng.normal(0, 0.02, acc.shape)
    fixes = PositionFixes(np.arange(0, len(t), 200), p[::200] + rng.normal(0, 0.02, (10, 3)), 0.02, np.zeros(3), "noisy")
    return t, gyro, acc, p, R, fixes


def datasheet_var(t, noise: ImuNoise):
    dt = np.diff(t) * 1e-9
    dt = np.r_[dt, dt[-1]]
    return np.c_[np.repeat((noise.gyro_noise_density ** 2 / dt)[:, None], 3, 1),
                 np.repeat((noise.acc_noise_density ** 2 / dt)[:, None], 3, 1)]


def test_the_datasheet_as_per_sample_variances_gives_the_datasheet_result():
    """var = density²/dt for every sample is the same noise model as GTSAM's own constant densities:
    the whole estimate (causal and smoothed) must agree to round-off."""
    t, gyro, acc, p, R, fixes = noisy_run()
    noise = ImuNoise()
    a = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [fixes], FusionSettings(noise))
    b = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [fixes], FusionSettings(noise), var=datasheet_var(t, noise))
    assert np.abs(a.smoothed_p - b.smoothed_p).max() < 1e-9
    assert np.abs(a.causal_p - b.causal_p).max() < 1e-9
    assert np.abs(a.smoothed_bias - b.smoothed_bias).max() < 1e-9


def test_each_imu_factor_carries_the_covariance_propagated_over_its_own_interval():
    """The preintegration covariance GTSAM builds from per-sample variances (rotation and velocity
    blocks of the first keyframe interval) equals imu_core's propagation of the same variances."""
    from scipy.spatial.transform import Rotation

    from imu_learn.core.covariance import interval_covariances

    t, gyro, acc, p, R, fixes = noisy_run()
    rng = np.random.default_rng(5)
    var = np.c_[(rng.uniform(1e-3, 3e-2, (len(t), 3))) ** 2, (rng.uniform(1e-2, 3e-1, (len(t), 3))) ** 2]
    noise = ImuNoise(gyro_random_walk=1e-12, acc_random_walk=1e-12)  # no bias walk leaking into the block
    inc = IncrementalFusion(t, (R[0], p[0], np.zeros(3)), [fixes], FusionSettings(noise))
    for s in range(21):  # keyframe 1 is sample 20: the factor covers samples 0..19
        inc.add_sample(t[s], gyro[s], acc[s], var[s])
    factor = next(inc._graph.at(i) for i in range(inc._graph.size())
                  if isinstance(inc._graph.at(i), gtsam.CombinedImuFactor))
    ours = interval_covariances(t[:21], gyro[:21], acc[:21], var[:21], np.array([0, 20]))[0]
    dR = Rotation.from_rotvec(gyro[0] * 0.005 * 20).as_matrix()  # constant rate: the interval's rotation
    # Rotation block: ours is in the interval's start frame, GTSAM's right-perturbed (end frame).
    rot_g = np.linalg.inv(factor.noiseModel().information())[:3, :3]
    rot_ours = dR.T @ ours[:3, :3] @ dR
    # CombinedImuFactor preintegrates in GTSAM's tangent coordinates, which differ from the manifold
    # ones at second order in the interval's rotation (0.05 rad): 1e-3 of the block, not round-off.
    scale = np.abs(rot_ours).max()
    assert np.abs(rot_g - rot_ours).max() < 1e-3 * scale
    # ... and the test can tell this interval's variances from the next interval's.
    other = var[20:41]
    rot_other = dR.T @ interval_covariances(t[:21], gyro[:21], acc[:21], other, np.array([0, 20]))[0][:3, :3] @ dR
    assert np.abs(rot_other - rot_ours).max() > 1e-2 * scale


def test_a_large_learned_variance_lets_the_fixes_win():
    """Samples declared far noisier than the datasheet: the smoothed estimate follows the (accurate)
    fixes more closely and the IMU less; with the datasheet it trusts the biased IMU between them."""
    t, gyro, acc, p, R, fixes = noisy_run()
    exact = PositionFixes(fixes.idx, p[fixes.idx], 1e-3, np.zeros(3), "exact")
    noise = ImuNoise()
    sheet = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [exact], FusionSettings(noise))
    loose = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [exact], FusionSettings(noise), var=1e4 * datasheet_var(t, noise))
    at_fix = np.isin(sheet.kf_idx, exact.idx)
    err = lambda r: np.abs(r.smoothed_p[at_fix] - p[r.kf_idx[at_fix]]).max()  # noqa: E731
    assert err(loose) <= err(sheet)


def test_variances_of_the_wrong_shape_are_refused():
    from imu_learn.errors import InvalidInputError

    t, gyro, acc, p, R, fixes = noisy_run()
    with pytest.raises(InvalidInputError, match="var"):
        fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [fixes], var=np.ones((len(t), 3)))
