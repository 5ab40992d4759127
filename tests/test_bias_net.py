"""The long-context gyro-bias estimator (imu_learn.nn.bias_net) and its trainer's examples
(imu_learn.train.bias_train): untrained it says no bias is left, a recording shorter than a window
gets no estimate, a saved estimator loads back the same, and a training example's rotation turns the
gyro, the accelerometer and the target together."""
from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from imu_learn.nn.bias_net import BiasNet, BiasNetConfig, block_means, load_bias_net, predict_bias, save_bias_net  # noqa: E402
from imu_learn.train.bias_train import batch  # noqa: E402


def imu(seconds, rate=200.0, seed=0):
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    return t, rng.normal(0, 0.1, (n, 3)), np.array([0, 0, 9.80665]) + rng.normal(0, 0.5, (n, 3))


def test_untrained_says_zero_and_short_recordings_get_none():
    net = BiasNet()
    t, g, a = imu(70.0)
    assert np.array_equal(predict_bias(net, t, g, a), np.zeros(3))
    assert predict_bias(net, *imu(29.0)) is None
    x = block_means(t, g, a, 20.0)
    assert x.shape == (1400, 6) and np.allclose(x[0, :3], g[:10].mean(0)) and abs(x[:, 5].mean() - 1) < 0.01


def test_save_and_load_give_the_same_estimate(tmp_path):
    torch.manual_seed(0)
    net = BiasNet()
    torch.nn.init.normal_(net.head.weight, std=0.1)
    t, g, a = imu(45.0)
    save_bias_net(net, tmp_path / "b.pt", {"device": "test"})
    again = load_bias_net(tmp_path / "b.pt")
    assert np.allclose(predict_bias(net, t, g, a), predict_bias(again, t, g, a), atol=0)
    assert np.any(predict_bias(again, t, g, a) != 0)


def test_a_training_example_turns_signal_and_target_together():
    cfg = BiasNetConfig()
    t, g, a = imu(40.0)
    x = block_means(t, g, a, cfg.rate_hz)
    res = np.array([0.001, -0.002, 0.003])
    xs, ys = batch([(x, res)], cfg, 4, 0.0, np.random.default_rng(1))  # nothing injected: the target is res turned
    assert xs.shape == (4, cfg.steps, 6) and ys.shape == (4, 3)
    assert np.allclose(np.linalg.norm(ys.numpy(), axis=1), np.linalg.norm(res), rtol=1e-5)
    assert np.allclose(np.linalg.norm(xs[:, :, 3:].numpy(), axis=2).mean(), np.linalg.norm(x[:, 3:], axis=1).mean(),
                       rtol=0.02)
