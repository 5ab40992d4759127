"""Learned displacement factors in the fusion graph (imu_learn.fuse.factors.displacement): the factor's
Jacobians, a closed-form trajectory, the causal orientation the network is fed, and the
``tlio-style`` fusion input in the experiment runner."""
import json
from pathlib import Path

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")

from gtsam.symbol_shorthand import X  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from imu_learn.fuse import fuse  # noqa: E402
from imu_learn.fuse.factors.displacement import (  # noqa: E402
    DisplacementFactors,
    displacement_error,
    displacement_factor,
    displacement_factors_for,
)

DT_NS = 5_000_000  # 200 Hz
W = 200  # 1 s windows


def random_pose(rng):
    return gtsam.Pose3(gtsam.Rot3(Rotation.random(random_state=rng.integers(1 << 30)).as_matrix()), rng.normal(size=3))


def test_factor_jacobians_match_numerical_derivatives():
    rng = np.random.default_rng(0)
    d = rng.normal(size=3)
    A = rng.normal(size=(3, 3))
    cov = A @ A.T + 0.1 * np.eye(3)
    f = displacement_factor(X(0), X(1), d, cov)
    for _ in range(3):
        pi, pj = random_pose(rng), random_pose(rng)
        v = gtsam.Values()
        v.insert(X(0), pi)
        v.insert(X(1), pj)
        e = f.unwhitenedError(v)
        assert np.allclose(e, pj.translation() - pi.translation() - d)
        assert f.error(v) == pytest.approx(0.5 * e @ np.linalg.solve(cov, e))
        _, H_i, H_j = displacement_error(pi.rotation().matrix(), pi.translation(), pj.rotation().matrix(),
                                         pj.translation(), d)
        for key, pose, H in ((X(0), pi, H_i), (X(1), pj, H_j)):
            num = np.zeros((3, 6))
            for c in range(6):
                xi = np.zeros(6)
                xi[c] = 1e-6
                vp, vm = gtsam.Values(v), gtsam.Values(v)
                vp.update(key, pose.retract(xi))
                vm.update(key, pose.retract(-xi))
                num[:, c] = (f.unwhitenedError(vp) - f.unwhitenedError(vm)) / 2e-6
            assert np.abs(num - H).max() < 1e-6
        # the linearised factor is the whitened analytic Jacobian: Aᵀ A = Hᵀ Σ⁻¹ H
        lin = f.linearize(v)
        Ai = lin.jacobian()[0][:, :6]
        assert np.allclose(Ai.T @ Ai, H_i.T @ np.linalg.solve(cov, H_i), atol=1e-8)


def constant_velocity(n=4000, w=0.3, v=(0.5, -0.2, 0.1), g=9.81):
    """Yawing at w rad/s about gravity while moving at a constant world velocity v: exact ZOH IMU
    (gyro (0, 0, w), specific force (0, 0, g) in the body frame); closed-form pose."""
    t = np.arange(n, dtype=np.int64) * DT_NS
    ts = t * 1e-9
    gyro = np.tile([0.0, 0.0, w], (n, 1))
    acc = np.tile([0.0, 0.0, g], (n, 1))
    p = np.asarray(v)[None] * ts[:, None]
    R = Rotation.from_rotvec(np.c_[np.zeros(n), np.zeros(n), w * ts]).as_matrix()
    return t, gyro, acc, p, R, np.asarray(v, dtype=np.float64)


def oracle(v, sigma, seen):
    """Exact displacements of a constant-velocity motion (window length x v x dt), isotropic sigma;
    records the world-frame IMU windows it was fed."""
    def regress(imu_world, R_last):
        seen.append((imu_world.copy(), R_last.copy()))
        return v * len(imu_world) * DT_NS * 1e-9, sigma ** 2 * np.eye(3)
    return regress


def test_exact_displacements_recover_a_constant_velocity_trajectory_without_aiding():
    t, gyro, acc, p, R, v = constant_velocity()
    acc_biased = acc + np.array([0.05, -0.04, 0.03])  # dead reckoning drifts ~0.5 * 0.07 * 20^2 = 14 m
    start = (R[0], p[0], v)
    free = fuse(t, gyro, acc_biased, start, [])
    seen = []
    hook = DisplacementFactors(oracle(v, 1e-3, seen), t, gyro, acc_biased, W, update_s=1.0)
    aided = fuse(t, gyro, acc_biased, start, [], extra_factors=hook)
    assert hook.count == 19 and hook.skipped == 0 and aided.counts["extra_factors"] == 19
    assert all(b - a == W for a, b in hook.windows) and [b for _, b in hook.windows] == list(range(200, 4000, 200))
    err_free = np.linalg.norm(free.causal_p - p[free.kf_idx], axis=1).max()
    err_causal = np.linalg.norm(aided.causal_p - p[aided.kf_idx], axis=1).max()
    err_smoothed = np.linalg.norm(aided.smoothed_p - p[aided.kf_idx], axis=1).max()
    assert err_free > 5.0
    assert err_causal < 0.05 and err_smoothed < 0.01
    # the accelerometer bias becomes observable through the displacements
    assert np.abs(aided.smoothed_bias[-1, 3:] - [0.05, -0.04, 0.03]).max() < 0.01
    # the network was fed the raw IMU rotated by the graph's causal orientation (tilted by the biased
    # accelerometer a few mrad at most): the yaw rate about world z, gravity (plus bias) on world z
    for imu_world, _ in seen:
        assert np.abs(imu_world[:, :3] - [0.0, 0.0, 0.3]).max() < 0.01
        assert np.abs(imu_world[:, 3:] - [0.0, 0.0, 9.81]).max() < 0.15
    assert Rotation.from_matrix(seen[-1][1].T @ R[hook.windows[-1][1] - 1]).magnitude() < 0.02


def test_exact_imu_and_exact_displacements_agree_to_machine_precision():
    t, gyro, acc, p, R, v = constant_velocity(n=1200)
    hook = DisplacementFactors(oracle(v, 1e-2, []), t, gyro, acc, W, update_s=0.2)
    res = fuse(t, gyro, acc, (R[0], p[0], v), [], extra_factors=hook)
    assert hook.count == len(range(200, 1200, 40))  # every 0.2 s from the first full window, overlapping
    for est in (res.causal_p, res.smoothed_p):
        assert np.abs(est - p[res.kf_idx]).max() < 1e-6
    assert np.abs(res.causal_R - R[res.kf_idx]).max() < 1e-7


def test_a_window_far_from_the_network_length_is_skipped():
    t, gyro, acc, p, R, v = constant_velocity(n=800)
    hook = DisplacementFactors(oracle(v, 1e-2, []), t, gyro, acc, 230, update_s=1.0, tolerance=2)
    fuse(t, gyro, acc, (R[0], p[0], v), [], extra_factors=hook)
    assert hook.count == 0 and hook.skipped == 3  # keyframes are 20 samples apart: no 230-sample window


@pytest.fixture(scope="module")
def tiny_tlio(crop_split, tmp_path_factory):
    """A tlio-style model fitted for a few steps on a shipped crop, saved as evaluate would."""
    import torch

    from imu_learn.baselines.base import FitSettings
    from imu_learn.baselines.tlio import TlioConfig, TlioStyle

    torch.set_num_threads(1)
    tr = crop_split[0]  # the first 15 s of MH_01_easy
    m = TlioStyle(TlioConfig(width=8, fc=8, evals=1))
    m.fit([tr], [], FitSettings(window=200, batch_size=8, steps=6, lr=1e-3))
    d = tmp_path_factory.mktemp("methods")
    m.save(d / "tlio-style.pt")
    return m, d


def test_tlio_style_is_a_fusion_input_that_adds_factors(shipped, tiny_tlio, tmp_path):
    from imu_learn.fuse.experiments.batch import run_experiment
    from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec, ScenarioSpec, imu_methods, validate

    m, methods = tiny_tlio
    assert "tlio-style" in imu_methods()
    crop = "euroc/MH_04_difficult"
    rec = RecordingSpec(crop, "euroc", crop + "/mav0/state_groundtruth_estimate0/data.csv")
    scn = ScenarioSpec("g", "position", 1.0, 0.1)
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["raw", "tlio-style"], recordings=[rec],
                              methods_dir=str(methods), scenarios=[scn]))
    out = tmp_path / "o"
    said = []
    res = run_experiment(cfg, out, said.append, only_inputs=["raw"])
    assert list(res) == ["MH_04_difficult|g|raw|s0"]
    assert [x for x in said if x.startswith("[")][0].startswith("[1/1] ")  # the runs asked for, not every input's
    res = run_experiment(cfg, out, lambda msg: None, only_inputs=["tlio-style"])
    assert set(res) == {"MH_04_difficult|g|raw|s0", "MH_04_difficult|g|tlio-style|s0"}  # raw kept
    r = res["MH_04_difficult|g|tlio-style|s0"]
    assert r["displacement_factors"]["count"] > 0 and np.isfinite(r["smoothed"]["pos_rmse_m"])
    assert "displacement_factors" not in res["MH_04_difficult|g|raw|s0"]
    # a changed update grid reruns only the tlio-style run
    cfg.displacement_update_s = 0.5
    logs = []
    run_experiment(cfg, out, logs.append)
    saved = json.loads((out / "results.json").read_text())["runs"]
    assert saved["MH_04_difficult|g|tlio-style|s0"]["displacement_factors"]["update_s"] == 0.5
    assert sum("tlio-style" in x and "position RMSE" in x for x in logs) == 1
    assert not any("|raw|" in x and "position RMSE" in x for x in logs)
    with pytest.raises(Exception, match="not among"):
        run_experiment(cfg, out, lambda msg: None, only_inputs=["proposed"])


def test_the_hook_on_a_real_model_feeds_windows_of_its_length(crop, tiny_tlio):
    m, _ = tiny_tlio
    seq = crop
    t, gyro, acc = seq.t_ns[:2000], seq.gyro[:2000], seq.acc[:2000]  # the first 10 s
    hook = displacement_factors_for(m, t, gyro, acc, update_s=1.0)
    R0 = Rotation.from_quat(seq.q_wxyz[0, [1, 2, 3, 0]]).as_matrix()
    res = fuse(t, gyro, acc, (R0, seq.p[0], seq.v[0]), [], extra_factors=hook)
    assert hook.count == 9 and all(abs((b - a) - m.window) <= 2 for a, b in hook.windows)
    assert np.isfinite(res.smoothed_p).all()


def test_learned_input_is_refined_samples_with_learned_variances_plus_displacements(shipped, tiny_tlio, tmp_path):
    """`learned`: the covariance checkpoint's refined samples and variances, plus the tlio-style factors
    where <methods_dir>/tlio-style.pt exists (regressed from the raw samples); without that model, no
    displacement factors and the same samples."""
    from imu_learn.fuse.experiments.batch import run_experiment
    from imu_learn.fuse.experiments.config import FuseConfig, RecordingSpec, ScenarioSpec, imu_methods, validate

    m, methods = tiny_tlio
    assert "learned" in imu_methods()
    crop = "euroc/MH_04_difficult"
    rec = RecordingSpec(crop, "euroc", crop + "/mav0/state_groundtruth_estimate0/data.csv")
    scn = ScenarioSpec("g", "position", 1.0, 0.1)
    cov = str(Path(__file__).resolve().parent.parent / "models" / "euroc_adis16448_cov.pt")
    cfg = validate(FuseConfig(init="groundtruth", name="t", data_root=str(shipped), inputs=["learned", "proposed+learned-cov"],
                              recordings=[rec], methods_dir=str(methods), covariance_checkpoint=cov, scenarios=[scn]))
    res = run_experiment(cfg, tmp_path / "with", lambda msg: None)
    r, plain = res["MH_04_difficult|g|learned|s0"], res["MH_04_difficult|g|proposed+learned-cov|s0"]
    assert r["displacement_factors"]["count"] > 0 and "displacement_factors" not in plain
    assert r["noise"] == plain["noise"] == "learned per-sample variances"
    assert r["smoothed"]["pos_rmse_m"] != plain["smoothed"]["pos_rmse_m"]  # the factors act
    cfg.methods_dir = str(tmp_path / "none")  # a device without a displacement model
    res = run_experiment(cfg, tmp_path / "without", lambda msg: None)
    r = res["MH_04_difficult|g|learned|s0"]
    assert "displacement_factors" not in r
    assert r["smoothed"]["pos_rmse_m"] == pytest.approx(res["MH_04_difficult|g|proposed+learned-cov|s0"]["smoothed"]["pos_rmse_m"], abs=1e-12)
