"""Traditional baseline (low-pass + intrinsic model fitted through the integration), its own
promises: the fast paths against the integration, the filter, recovering an injected distortion.
What every method must do (shapes, save/load, determinism) is test_baselines_contract.py."""
import json

import numpy as np

import imu_learn as il
from imu_learn.baselines.base import FitSettings
from imu_learn.baselines.traditional import Traditional, _Data, _VelResiduals, lowpass
from imu_learn.core.integration import rotation_window_sums
from imu_learn.data.types import Segment

SETTINGS = FitSettings(window=100, seed=0)


def small() -> Traditional:
    return Traditional(cutoffs_hz=(None, 20.0), max_windows=150)


def test_fast_paths_match_integration(crop_split):
    """The fit's rotations and its velocity/position residuals against the core's integration of the
    same windows (Rust, sample by sample)."""
    d = _Data([crop_split[0]], 100, 50, 9.81)
    w = d.windows(None, None)
    core = il.integrate_windows(crop_split[0], d.items[0][3].starts, d.items[0][3].horizons)
    q = rotation_window_sums(w.gyro, w.acc_g, w.dt, np.zeros(21), w.horizons, False)["q_wxyz"]
    np.testing.assert_allclose(q, core.dq_wxyz, atol=1e-12)
    r = _VelResiduals(w.gyro, w)(np.zeros(12))
    ref = np.concatenate(((w.dv - core.dv).reshape(-1), (w.dp - core.dp).reshape(-1)))
    np.testing.assert_allclose(r, ref, atol=1e-12)


def test_lowpass():
    fs = 200.0
    t = np.arange(2000) / fs
    x = np.stack([np.sin(2 * np.pi * 1.0 * t), np.sin(2 * np.pi * 60.0 * t)], 1)
    y = lowpass(x, fs, 10.0)
    assert np.abs(y[200:-200, 0] - x[200:-200, 0]).max() < 0.01  # pass band, zero phase
    assert np.abs(y[200:-200, 1]).max() < 0.01  # stop band
    np.testing.assert_array_equal(lowpass(x, fs, None), x)


def test_fit_improves_training_loss(crop_split):
    m = small()
    log = m.fit([crop_split[0]], [crop_split[1]], SETTINGS)
    assert log["train_loss"][-1] < 0.5 * log["train_loss"][0]
    assert log["gyro_loss"][-1] < log["gyro_loss"][0] and log["acc_loss"][-1] < log["acc_loss"][0]
    assert len(log["val_rot_rmse"]) == len(log["cutoffs_hz"]) == 2


def test_recovers_injected_gyro_distortion(crop_split):
    """Distort the recorded gyro with known scale/misalignment/bias; the fitted model must undo it:
    its output on the distorted data matches the fit on the undistorted data (the device's own
    bias and errors are in both), far closer than the distortion itself."""
    tr, va = crop_split
    S = np.array([[1.03, 0.010, -0.015], [-0.008, 0.97, 0.012], [0.02, -0.01, 1.02]])
    b = np.array([0.05, -0.04, 0.03])

    def distort(s: Segment) -> Segment:
        return Segment(s.name, s.t_ns, s.gyro @ S.T + b, s.acc, s.p, s.v, s.q_wxyz)

    clean, dist = Traditional(cutoffs_hz=(None,), max_windows=150), Traditional(cutoffs_hz=(None,), max_windows=150)
    clean.fit([tr], [va], SETTINGS)
    dist.fit([distort(tr)], [distort(va)], SETTINGS)
    g_clean, _ = clean.refine(va)
    g_dist, _ = dist.refine(distort(va))
    injected = np.sqrt(np.mean((distort(va).gyro - va.gyro) ** 2))
    recovered = np.sqrt(np.mean((g_dist - g_clean) ** 2))
    assert injected > 0.04
    assert recovered < 0.05 * injected, (recovered, injected)
    # parameters: M_dist ≈ M_clean S⁻¹ and b_dist ≈ S b_clean + b (up to the small g-sensitivity terms)
    np.testing.assert_allclose(dist.params.M_g, clean.params.M_g @ np.linalg.inv(S), atol=3e-3)
    np.testing.assert_allclose(dist.params.b_g, S @ clean.params.b_g + b, atol=2e-3)


def test_traditional_timing_fits_a_known_delay_then_the_model(crop_split, tmp_path):
    """traditional+timing: the recorded IMU delayed by 1.4 samples (by linear interpolation); the
    temporal calibration is the timing baseline's search on the same windows, and it finds the
    delay on top of the crop's own offset (to within what interpolating twice smooths); plain
    traditional keeps 0 and loads fits saved before the offset existed."""
    from imu_learn.baselines.timing import Timing, shifted
    from imu_learn.baselines.traditional import TraditionalTiming

    tr, va = crop_split
    own = Timing(max_windows=750)
    own.fit([tr], [va], SETTINGS)
    late = [shifted(s, -1.4) for s in (tr, va)]
    m = TraditionalTiming(cutoffs_hz=(None,), max_windows=150)
    log = m.fit([late[0]], [late[1]], SETTINGS)
    same = Timing(max_windows=750)  # traditional: 5 × max_windows short windows
    same.fit([late[0]], [late[1]], SETTINGS)
    assert m.params.time_offset == same.tau
    assert abs(m.params.time_offset - (own.tau + 1.4)) < 0.15, (m.params.time_offset, own.tau)
    assert log["tau_samples"] == [m.params.time_offset]
    m.save(tmp_path / "tt.json")
    m2 = TraditionalTiming().load(tmp_path / "tt.json")
    np.testing.assert_array_equal(m2.refine(va)[0], m.refine(va)[0])
    # plain traditional: no offset; a fit saved before the offset existed loads with tau = 0
    t = Traditional(cutoffs_hz=(None,), max_windows=150)
    t.fit([tr], [va], SETTINGS)
    assert t.params.time_offset == 0.0
    d = t.to_dict()
    del d["time_offset"]
    (tmp_path / "old.json").write_text(json.dumps(d))
    old = Traditional().load(tmp_path / "old.json")
    assert old.params.time_offset == 0.0
    np.testing.assert_array_equal(old.refine(va)[0], t.refine(va)[0])
