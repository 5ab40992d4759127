"""The TLIO-style displacement baseline's own promises: frames, yaw equivariance, the NLL, training
phases, the rules of prediction at any n on a shipped crop, its file format and its registration in
evaluate. What every method must do (shapes, save/load, determinism, too-short data) is
test_baselines_contract.py."""
import numpy as np
import pytest
import torch

import imu_learn as il
from imu_learn.baselines.base import FitSettings, poses_from_imu
from imu_learn.baselines.tlio import (
    TlioConfig,
    TlioNet,
    TlioStyle,
    mse_loss,
    nll_loss,
    rot_z,
    to_local,
    world_imu,
    yaw_of_matrix,
    yaw_of_quat,
)
from imu_learn.core.quat import quat_mul, quat_rotate

torch.set_num_threads(1)

CFG = TlioConfig(window_s=0.25, width=8, fc=16, evals=4)  # W = 50 samples at 200 Hz
W = 50
SETTINGS = FitSettings(window=W, batch_size=16, steps=40, lr=3e-3, seed=0)


def yawed(s, psi):
    """The same motion with the world frame turned by psi about gravity (IMU unchanged)."""
    qz = np.array([np.cos(psi / 2), 0.0, 0.0, np.sin(psi / 2)])
    q = quat_mul(np.broadcast_to(qz, s.q_wxyz.shape), s.q_wxyz)
    Rz = rot_z(np.array(psi))
    return il.Segment(s.name + "_yawed", s.t_ns, s.gyro, s.acc, s.p @ Rz.T, s.v @ Rz.T, q)


@pytest.fixture(scope="module")
def fitted(crop_split):
    m = TlioStyle(CFG)
    return m, m.fit([crop_split[0]], [crop_split[1]], SETTINGS)


def test_yaw_and_frames():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    from scipy.spatial.transform import Rotation
    R = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    assert np.allclose(yaw_of_quat(q), yaw_of_matrix(R))
    g, a = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    assert np.allclose(world_imu(g, a, q), world_imu(g, a, R))
    # the local frame takes the yaw out: a world vector along the heading ends up on local x
    psi = 0.7
    v = np.array([[[np.cos(psi), np.sin(psi), 0.3] * 2]])
    loc = to_local(v, np.array([psi]))
    assert np.allclose(loc[0, 0], [1.0, 0.0, 0.3] * 2)


def test_net_shapes_and_logvar_clamp():
    net = TlioNet(width=8, fc=8, logvar_min=-3.0, logvar_max=1.0).eval()
    net.out_scale.fill_(1e-3)  # the untrained net predicts log σ² = 2 log(out_scale) < logvar_min: clamped
    d, lv = net(torch.randn(5, 60, 6))
    assert d.shape == (5, 3) and lv.shape == (5, 3)
    assert torch.all(d == 0) and torch.all(lv == -3.0)
    d, lv = net(torch.randn(2, 49, 6))  # any window length (fusion windows may be a sample off W)
    assert d.shape == (2, 3)


def test_nll_gradient_sanity():
    torch.manual_seed(0)
    d = torch.randn(7, 3, dtype=torch.float64)
    d_hat = torch.randn(7, 3, dtype=torch.float64, requires_grad=True)
    lv = torch.randn(7, 3, dtype=torch.float64, requires_grad=True)
    loss = nll_loss(d, d_hat, lv)
    loss.backward()
    r2 = (d - d_hat.detach()) ** 2
    assert torch.allclose(lv.grad, 0.5 * (1 - r2 * torch.exp(-lv.detach())) / 7)
    assert torch.allclose(d_hat.grad, -(d - d_hat.detach()) * torch.exp(-lv.detach()) / 7)
    # the NLL's optimum variance is the squared residual; there the log-variance gradient vanishes
    lv0 = torch.log(r2).requires_grad_(True)
    nll_loss(d, d_hat.detach(), lv0).backward()
    assert lv0.grad.abs().max() < 1e-12
    assert float(mse_loss(d, d)) == 0.0


def test_training_phases_and_selection(fitted):
    m, log = fitted
    assert m.window == W and log["window"] == [W]
    assert log["phase"] == ["mse"] * 20 + ["nll"] * 20 and log["mse_steps"] == [20] and log["nll_steps"] == [20]
    assert len(log["train_loss"]) == SETTINGS.steps and np.isfinite(log["train_loss"]).all()
    assert len(log["val_nll"]) == 4 and np.isfinite(log["val_nll"]).all()
    assert log["best_step"][0] > 20  # kept weights come from the NLL phase
    assert np.mean(log["train_loss"][:3]) > np.mean(log["train_loss"][17:20])  # MSE went down


def test_training_windows_are_yaw_invariant_without_augmentation(crop_split):
    train, _ = crop_split
    m = TlioStyle(CFG)
    m.window = W
    seqs = [train, yawed(train, 2.5)]
    world = [world_imu(s.gyro, s.acc, s.q_wxyz) for s in seqs]
    starts = np.array([0, 400, 1200])
    x0, d0 = m._windows(world, seqs, np.zeros(3, int), starts, None)
    x1, d1 = m._windows(world, seqs, np.ones(3, int), starts, None)
    assert np.allclose(x0, x1, atol=1e-9) and np.allclose(d0, d1, atol=1e-9)
    # a random yaw rotates input and target together: target length and input norms unchanged
    xr, dr = m._windows(world, seqs, np.zeros(3, int), starts, np.random.default_rng(1))
    assert np.allclose(np.linalg.norm(dr, axis=1), np.linalg.norm(d0, axis=1))
    assert np.allclose(xr[..., 2], x0[..., 2]) and np.allclose(xr[..., 5], x0[..., 5])  # z untouched
    assert not np.allclose(xr, x0)


def test_prediction_is_yaw_equivariant(fitted, crop_split):
    m, _ = fitted
    _, val = crop_split
    starts = np.arange(0, 700, 23)
    psi = 2.0
    d = m.window_displacements(val, starts)
    d_yawed = m.window_displacements(yawed(val, psi), starts)
    assert np.abs(d_yawed - d @ rot_z(np.array(psi)).T).max() < 1e-5
    # the fusion entry point gives the same displacement from the same world-frame samples
    wi = world_imu(val.gyro[100:100 + W], val.acc[100:100 + W], val.q_wxyz[100:100 + W])
    from scipy.spatial.transform import Rotation
    R_last = Rotation.from_quat(val.q_wxyz[100 + W - 1, [1, 2, 3, 0]]).as_matrix()
    dw, cov = m.regress_window(wi, R_last)
    assert np.allclose(dw, m.window_displacements(val, np.array([100]))[0], atol=1e-6)
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_predict_n_rules(fitted, crop_split):
    m, _ = fitted
    _, val = crop_split
    starts = np.arange(60, 700, 37, dtype=np.uint64)
    k = starts.astype(int)
    for n in (10, W, 3 * W + 7):
        p = m.predict(val, starts, n)
        assert p.v is None
        # rotation: the gyro integrated from the ground-truth start
        assert np.allclose(p.q_wxyz, poses_from_imu(val, val.gyro, val.acc, starts, n).q_wxyz)
    D = lambda s: m.window_displacements(val, s)  # noqa: E731
    assert np.allclose(m.predict(val, starts, W).p, val.p[k] + D(k))
    assert np.allclose(m.predict(val, starts, 10).p, val.p[k] + (10 / W) * D(k + 10 - W))
    n = 3 * W + 7
    assert np.allclose(m.predict(val, starts, n).p, val.p[k] + D(k) + D(k + W) + D(k + 2 * W) + (7 / W) * D(k + n - W))
    # before the first full window the first window stands in
    assert np.allclose(m.predict(val, np.array([0]), 10).p, val.p[[0]] + (10 / W) * D(np.array([0])))
    # predictions differ per window (the net is not constant)
    assert np.ptp(D(k), axis=0).max() > 0
    # the world-frame IMU ground truth tells: rotated samples have gravity on +z at rest on average
    assert 9.0 < world_imu(val.gyro, val.acc, val.q_wxyz)[:, 5].mean() < 10.6
    assert np.allclose(quat_rotate(val.q_wxyz[:1], val.acc[:1]), world_imu(val.gyro[:1], val.acc[:1], val.q_wxyz[:1])[:, 3:])


def test_the_file_keeps_window_rate_and_config_and_no_other_file_loads(fitted, tmp_path):
    m, _ = fitted
    f = tmp_path / "tlio.pt"
    m.save(f)
    m2 = TlioStyle().load(f)
    assert m2.window == W and m2.config.width == 8 and m2.rate_hz == pytest.approx(200.0, rel=1e-3)
    torch.save({"format": "x"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="tlio-style"):
        TlioStyle().load(tmp_path / "other.pt")


def test_registered_in_evaluate_as_a_regressor():
    from imu_learn.eval.run import DEFAULT_METHODS, REGISTRY, is_refiner, load_method_class

    assert "tlio-style" in REGISTRY and "tlio-style" not in DEFAULT_METHODS
    cls = load_method_class("tlio-style")
    assert cls is TlioStyle and not is_refiner(cls())
