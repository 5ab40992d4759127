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


def test_refine_bias_learned_subtracts_the_estimators_answer(tmp_path, capsys):
    import json
    import math

    from imu_learn.calib.profile import Affine, Profile
    from imu_learn.cli.refine import main
    from test_still_bias import IMU_REL, write_asl

    torch.manual_seed(0)
    net = BiasNet()
    torch.nn.init.normal_(net.head.weight, std=0.1)
    save_bias_net(net, tmp_path / "b.pt", {"device": "test"})
    t, g, a = imu(45.0)
    src = write_asl(tmp_path / "in", t, g, a)
    eye = Affine(np.eye(3), np.zeros(3), "rad/s")
    prof = Profile(device="test", sample_rate_hz=200.0, time_offset_s=0.0, time_offset_s_std=math.nan, gyro=eye,
                   acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)), gravity_mps2=9.80665,
                   gravity_mps2_std=math.nan, floor={})
    prof.save(tmp_path / "profile.json")
    base = ["--profile", str(tmp_path / "profile.json"), "--input", str(src / IMU_REL)]
    assert main([*base, "--out", str(tmp_path / "o.csv"), "--bias", "learned", "--bias-model", str(tmp_path / "b.pt")]) == 0
    b = json.loads((tmp_path / "o.csv.summary.json").read_text())["bias"]
    assert b["method"] == "learned" and b["applied"] and b["trained_on"] == "test"
    _, g_out, _ = core_read(tmp_path / "o.csv")
    assert np.allclose(g_out, g - np.array(b["gyro_bias_rad_s"]), atol=1e-6)
    assert np.allclose(b["gyro_bias_rad_s"], predict_bias(net, t, g, a), atol=1e-7)
    # refused in one line: no estimator, an estimator without --bias learned, a file that is not one
    assert main([*base, "--out", str(tmp_path / "p.csv"), "--bias", "learned"]) == 2
    assert main([*base, "--out", str(tmp_path / "p.csv"), "--bias-model", str(tmp_path / "b.pt")]) == 2
    assert main([*base, "--out", str(tmp_path / "p.csv"), "--bias", "learned", "--bias-model",
                 str(tmp_path / "profile.json")]) == 2
    err = capsys.readouterr().err
    assert "--bias learned needs --bias-model" in err and "cannot be read" in err and err.count("error:") == 3


def core_read(path):
    from imu_learn import _imu_core as core

    return core.read_asl_imu(str(path))


def test_refine_warns_where_the_bias_model_was_trained_on_another_device(tmp_path, caplog):
    """A bias estimator learns its own device's bias (trained on gyro minus that device's mean): one warning
    line where the profile is another device's, none where they agree (the DATASET_SENSOR naming)."""
    import logging
    import math

    from imu_learn.calib.profile import Affine, Profile
    from imu_learn.cli.refine import main
    from test_still_bias import IMU_REL, write_asl

    t, g, a = imu(45.0)
    src = write_asl(tmp_path / "in", t, g, a)
    for device in ("fetch", "tumvi"):
        save_bias_net(BiasNet(), tmp_path / f"{device}.pt", {"device": device})
    eye = Affine(np.eye(3), np.zeros(3), "rad/s")
    prof = Profile(device="tumvi_bmi160", sample_rate_hz=200.0, time_offset_s=0.0, time_offset_s_std=math.nan,
                   gyro=eye, acc=Affine(np.eye(3), np.zeros(3), "m/s^2"), g_sensitivity=np.zeros((3, 3)),
                   gravity_mps2=9.80665, gravity_mps2_std=math.nan, floor={})
    prof.save(tmp_path / "profile.json")
    base = ["--profile", str(tmp_path / "profile.json"), "--input", str(src / IMU_REL), "--bias", "learned"]
    with caplog.at_level(logging.WARNING):
        assert main([*base, "--out", str(tmp_path / "a.csv"), "--bias-model", str(tmp_path / "fetch.pt")]) == 0
    lines = [r.getMessage() for r in caplog.records if "trained on device" in r.getMessage()]
    assert len(lines) == 1 and "'fetch'" in lines[0] and "'tumvi_bmi160'" in lines[0], lines
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        assert main([*base, "--out", str(tmp_path / "b.csv"), "--bias-model", str(tmp_path / "tumvi.pt")]) == 0
    assert not [r for r in caplog.records if "trained on device" in r.getMessage()]
