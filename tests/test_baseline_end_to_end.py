"""The end-to-end (IONet-style) baseline's own promises: targets against the Rust labels, training,
chained long horizons, one regressor per scored horizon. What every method must do (shapes, save/load,
determinism, too-short data) is test_baselines_contract.py."""
import numpy as np
import pytest
import torch

from imu_learn.baselines.base import FitSettings, quat_mul
from imu_learn.baselines.end_to_end import EndToEnd, EndToEndConfig, window_targets
from imu_learn.core.batches import BatchConfig, BatchSampler

torch.set_num_threads(1)

W = 50
SETTINGS = FitSettings(window=W, batch_size=16, steps=60, lr=3e-3, seed=0)


@pytest.fixture(scope="module")
def fitted(crop_split):
    m = EndToEnd(EndToEndConfig(hidden=16, layers=2, fc=16, evals=4))
    return m, m.fit([crop_split[0]], [crop_split[1]], SETTINGS)


def test_targets_match_the_rust_labels(crop_split):
    train, _ = crop_split
    b = BatchSampler([train], BatchConfig(window=W, batch_size=8)).sample(3)
    phi, dp = window_targets([train], b.seq_index, b.start, W)
    # rotation: the label's Δq at the full window
    dq = b.dq_wxyz[:, -1]
    from imu_learn.nn.so3 import so3_exp
    q = so3_exp(torch.from_numpy(phi)).numpy()
    assert np.allclose(np.abs((q * dq).sum(-1)), 1.0, atol=1e-9)
    # translation: R_kᵀ(p_{k+n} − p_k) = Δγ + R_kᵀ v_k Δt + ½ R_kᵀ g Δt²
    k = b.start.astype(int)
    qk_inv = train.q_wxyz[k] * np.array([1.0, -1.0, -1.0, -1.0])
    from imu_learn.baselines.base import quat_rotate
    T = b.label_dt[:, -1, None]
    expect = b.dp[:, -1] + quat_rotate(qk_inv, train.v[k] * T + 0.5 * np.array([0, 0, -9.81]) * T**2)
    assert np.allclose(dp, expect, atol=1e-6)


def test_training_improves_its_own_loss(fitted):
    _m, log = fitted
    tl = log["train_loss"]
    assert len(tl) == SETTINGS.steps and np.isfinite(tl).all()
    assert np.mean(tl[-8:]) < 0.9 * np.mean(tl[:8])
    assert len(log["val_loss"]) == 4 and np.isfinite(log["val_loss"]).all()


def test_predict_gives_no_velocity_and_differs_per_window(fitted, crop_split):
    m, log = fitted
    _, val = crop_split
    starts = np.arange(0, 600, 37, dtype=np.uint64)
    for n in (W, 10, 3 * W + 7):
        assert m.predict(val, starts, n).v is None
    # n == W: the untrained-by-construction mean answer is gone, predictions differ per window
    p = m.predict(val, starts, W)
    assert np.ptp(p.p - val.p[starts.astype(int)], axis=0).max() > 0


def test_chain_composes_training_length_segments(fitted, crop_split):
    m, _ = fitted
    _, val = crop_split
    starts = np.arange(0, 500, 50)
    m.config.long_horizon = "chain"
    try:
        dq, dp = m.regress(val, starts, 2 * W + 5)
        # the same composition by hand: W, W, then the 5-sample remainder
        q1, p1 = m._regress_direct(val, starts, W)
        q2, p2 = m._regress_direct(val, starts + W, W)
        q3, p3 = m._regress_direct(val, starts + 2 * W, 5)
        from imu_learn.baselines.base import quat_rotate
        q12 = quat_mul(q1, q2)
        assert np.allclose(dp, p1 + quat_rotate(q1, p2) + quat_rotate(q12, p3), atol=1e-6)
        assert np.allclose(dq, quat_mul(q12, q3), atol=1e-9)
        # at or below the training window, chain == direct
        a = m.regress(val, starts, W)
        m.config.long_horizon = "direct"
        b = m.regress(val, starts, W)
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    finally:
        m.config.long_horizon = "direct"


def test_one_regressor_per_scored_horizon(crop_split, monkeypatch, tmp_path):
    """With FitSettings.horizons, each scored n is regressed by a net trained on n-sample windows:
    the n = 10 predictions come from the net that saw only 10-sample windows in training."""
    from imu_learn.baselines import end_to_end as e2e

    train, val = crop_split
    seen = []  # (net, window length) of every training-mode forward pass
    forward = e2e.EndToEndNet.forward

    def spy(self, imu):
        if self.training:
            seen.append((self, imu.shape[1]))
        return forward(self, imu)

    monkeypatch.setattr(e2e.EndToEndNet, "forward", spy)
    m = EndToEnd(EndToEndConfig(hidden=8, layers=1, fc=8, evals=2))
    settings = FitSettings(window=W, batch_size=8, steps=6, lr=3e-3, seed=0, horizons=(W, 10))
    log = m.fit([train], [val], settings)
    assert m.horizons == [10, W] and log["horizons"] == [10, W]
    assert len(log["n10.train_loss"]) == 6 and len(log[f"n{W}.train_loss"]) == 6
    assert {n for net, n in seen if net is m.nets[10]} == {10}
    assert {n for net, n in seen if net is m.nets[W]} == {W}
    assert m.horizon_for(10) == 10 and m.horizon_for(W) == W and m.horizon_for(12) == 10 and m.horizon_for(400) == W

    starts = np.arange(0, 600, 37)
    p10 = m.predict(val, starts, 10)
    q10, d10 = m._regress_direct(val, starts, 10, horizon=10)
    q10_long, d10_long = m._regress_direct(val, starts, 10, horizon=W)
    qk = val.q_wxyz[starts]
    assert np.allclose(p10.q_wxyz, quat_mul(qk, q10) / np.linalg.norm(quat_mul(qk, q10), axis=1, keepdims=True))
    from imu_learn.baselines.base import quat_rotate
    assert np.allclose(p10.p, val.p[starts] + quat_rotate(qk, d10))
    assert not np.allclose(d10, d10_long)  # not the W-sample net fed 10 samples

    f = tmp_path / "e2e.pt"
    m.save(f)
    m2 = EndToEnd().load(f)
    assert m2.horizons == [10, W] and m2.window == W
    b = m2.predict(val, starts, 10)
    assert np.array_equal(p10.q_wxyz, b.q_wxyz) and np.array_equal(p10.p, b.p)
