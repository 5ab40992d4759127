"""The zero-displacement floor of the TLIO-style factors (imu_learn.baselines.zero_displacement):
its variances against a closed form, what it predicts, and the fusion input it makes. What every
method must do (shapes, save/load, determinism, too-short data) is test_baselines_contract.py."""
import numpy as np
import pytest

import imu_learn as il
from imu_learn.baselines.zero_displacement import ZeroDisplacement, displacement_variances

DT_NS = 5_000_000  # 200 Hz


def constant_velocity(v, n=1000, name="cv"):
    t = np.arange(n, dtype=np.int64) * DT_NS
    p = np.outer(t * 1e-9, v)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    return il.Segment(name, t, np.zeros((n, 3)), acc, p, np.tile(v, (n, 1)).astype(float), q)


def test_variances_are_the_mean_square_one_second_displacement():
    # every 1 s window of a constant velocity v moves v * 1 s: sigma_h^2 = (vx^2 + vy^2) / 2, sigma_v^2 = vz^2
    a, b = constant_velocity(np.array([1.0, 2.0, 0.5])), constant_velocity(np.array([0.0, 0.0, 0.0]), 500)
    vh, vv, n = displacement_variances([a, b], 200)
    assert n == (1000 - 200) + (500 - 200)
    assert vh == pytest.approx(2.5 * 800 / 1100, rel=1e-9) and vv == pytest.approx(0.25 * 800 / 1100, rel=1e-9)
    m = ZeroDisplacement()
    log = m.fit([a, b], [])
    assert m.window == 200 and m.rate_hz == pytest.approx(200.0)
    assert log["sigma_h_m"][0] == pytest.approx(np.sqrt(vh))
    with pytest.raises(ValueError, match="no training sequence longer"):
        displacement_variances([constant_velocity(np.ones(3), 100)], 200)


def test_it_predicts_no_motion_with_the_fitted_spread_in_every_heading(tmp_path):
    m = ZeroDisplacement()
    m.fit([constant_velocity(np.array([1.0, 0.0, 0.2]))], [])
    rng = np.random.default_rng(0)
    for yaw in (0.0, 1.0, -2.5):
        R = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
        d, cov = m.regress_window(rng.normal(size=(200, 6)), R)
        assert np.all(d == 0) and np.allclose(cov, np.diag([m.var_h, m.var_h, m.var_v]))
    s = constant_velocity(np.array([0.3, -0.1, 0.0]))
    pred = m.predict(s, np.array([0, 100, 700]), 200)
    assert np.array_equal(pred.p, s.p[[0, 100, 700]]) and pred.v is None
    f = tmp_path / "z.json"
    m.save(f)
    back = ZeroDisplacement().load(f)
    assert (back.window, back.var_h, back.var_v) == (m.window, m.var_h, m.var_v)
    f.write_text('{"format": "other"}')
    with pytest.raises(ValueError, match="not a zero-displacement"):
        ZeroDisplacement().load(f)


def test_zero_displacement_is_a_fusion_input_that_adds_factors(shipped, crop_split, tmp_path):
    pytest.importorskip("gtsam")
    from imu_learn.baselines.registry import method_file
    from imu_learn.fuse.experiments.batch import run_experiment
    from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec, ScenarioSpec, imu_methods, validate

    assert "zero-displacement" in imu_methods()
    m = ZeroDisplacement()
    m.fit([crop_split[0]], [])
    methods = tmp_path / "methods"
    m.save(method_file(methods, "zero-displacement"))
    crop = "euroc/MH_04_difficult"
    rec = RecordingSpec(crop, "euroc", crop + "/mav0/state_groundtruth_estimate0/data.csv")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw", "zero-displacement"],
                              recordings=[rec], methods_dir=str(methods),
                              scenarios=[ScenarioSpec("g", "position", 0.1, 0.1)]))
    res = run_experiment(cfg, tmp_path / "o", lambda msg: None)
    z, raw = res["MH_04_difficult|g|zero-displacement|s0"], res["MH_04_difficult|g|raw|s0"]
    assert z["displacement_factors"]["count"] > 0 and "displacement_factors" not in raw
    # the same raw IMU with a motion prior: a different trajectory, finite
    assert np.isfinite(z["causal"]["pos_rmse_m"]) and z["causal"]["pos_rmse_m"] != raw["causal"]["pos_rmse_m"]
