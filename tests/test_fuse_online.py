"""imu_learn.fuse online: the stream (IncrementalFusion + causal model step) against the batch fuse(),
the per-sample state, the CLI's --online runs, its typed errors and its --help."""
import json
import shutil

import numpy as np
import pytest
import torch

gtsam = pytest.importorskip("gtsam")

from imu_learn.cli.fuse import main as fuse_main  # noqa: E402
from imu_learn.cli.fuse import parser  # noqa: E402
from imu_learn.errors import ConfigError, InvalidInputError  # noqa: E402
from imu_learn.fuse import PositionFixes, apply_outages, fuse, simulate_relative_pose  # noqa: E402
from imu_learn.fuse.experiments.online import stream  # noqa: E402
from imu_learn.fuse.graph import IncrementalFusion  # noqa: E402
from imu_learn.fuse.settings import FusionSettings  # noqa: E402
from imu_learn.infer.checkpoint import save_checkpoint  # noqa: E402
from imu_learn.infer.refiner import refine_arrays  # noqa: E402
from imu_learn.infer.streaming import CausalStepper, WindowedStepper, load_causal_model, load_learned_model  # noqa: E402
from imu_learn.nn.model import ImuRefiner, ModelConfig  # noqa: E402

torch.set_num_threads(1)

# The closed-form trajectory (imu_learn.data.synthetic); the shipped crop is conftest.py's `crop` fixture.
from crops import CROP, REPO  # noqa: E402
from imu_learn.data.synthetic import spin_and_climb  # noqa: E402


def noisy_case(seed=3):
    rng = np.random.default_rng(seed)
    t, gyro, acc, p, R = spin_and_climb()
    gyro = gyro + 0.005 + rng.normal(0, 0.002, gyro.shape)
    acc = acc + 0.05 + rng.normal(0, 0.02, acc.shape)
    fixes = apply_outages(PositionFixes(np.arange(0, len(t), 200), p[::200] + rng.normal(0, 0.02, (10, 3)), 0.02,
                                        np.zeros(3), "noisy"), t, [(4.0, 3.0)])
    return t, gyro, acc, (R[0], p[0], np.zeros(3)), fixes


def tiny_model(causal=True, seed=0, mean=None, std=None):
    torch.manual_seed(seed)
    m = ImuRefiner(ModelConfig(causal=causal, hidden=8, fc=8), mean=mean, std=std)
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
        torch.nn.init.normal_(m.head.bias, std=0.1)
    return m.eval()


# --------------------------------------------------------------------------------------------
# the stream against the batch run


def test_online_raw_equals_the_batch_causal_output_with_fixes_and_an_outage():
    t, gyro, acc, start, fixes = noisy_case()
    batch = fuse(t, gyro, acc, start, [fixes])
    online = stream(t, gyro, acc, start, [fixes])
    assert np.array_equal(online.kf_idx, batch.kf_idx)
    assert np.abs(online.causal_p - batch.causal_p).max() <= 1e-9
    assert np.abs(online.causal_R - batch.causal_R).max() <= 1e-9
    # one latency per sample; updates only at the fixes that survived the outage and at the end
    assert len(online.latency_ns) == len(t) and (online.latency_ns > 0).all()
    assert online.updated.sum() == len(fixes) + 1 - int(fixes.idx[0] == 0)
    assert np.array_equal(np.flatnonzero(online.keyframe), batch.kf_idx)
    st = online.stats()
    assert st["samples"] == len(t) and st["per_sample"]["p99_us"] <= st["per_sample"]["max_us"]
    assert st["real_time_factor"] == pytest.approx(online.duration_s / online.wall_s)
    # the queued delay: a sample starts at its stamp or when the previous one is done
    finish, delay = 0, []
    for s in range(len(t)):
        finish = max(int(t[s] - t[0]), finish) + int(online.latency_ns[s])
        delay.append(finish - int(t[s] - t[0]))
    assert np.array_equal(online.delay_ns(), delay) and st["delay"]["max_us"] == max(delay) * 1e-3


def test_online_raw_equals_the_batch_with_relative_poses_on_a_real_crop(crop):
    n = 3000  # 15 s of the crop, VO-like aiding at 10 Hz
    t, g, a = crop.t_ns[:n], crop.gyro[:n], crop.acc[:n]
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    start = (Rotation.from_quat(wxyz_to_xyzw(crop.q_wxyz[0])).as_matrix(), crop.p[0], crop.v[0])
    rel = simulate_relative_pose(t, crop.p[:n], crop.q_wxyz[:n], 10.0, 0.1, 0.01, np.random.default_rng(0))
    batch = fuse(t, g, a, start, [rel])
    online = stream(t, g, a, start, [rel])
    assert np.abs(online.causal_p - batch.causal_p).max() <= 1e-9
    assert np.abs(online.causal_R - batch.causal_R).max() <= 1e-9
    assert online.counts["relative_pose_factors"] == batch.counts["relative_pose_factors"] == len(rel)


def test_online_with_a_causal_model_equals_the_batch_on_its_refined_output(crop):
    n = 2400  # 12 s
    t, g, a = crop.t_ns[:n], crop.gyro[:n], crop.acc[:n]
    raw = np.c_[g, a]
    model = tiny_model(mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    rg, ra = refine_arrays(model, g, a)
    assert np.abs(rg - g).max() > 1e-3  # the model changes the data
    # the step-by-step forward is the whole-sequence causal forward up to float32 rounding
    stepper = CausalStepper(model)
    stepped = np.array([np.r_[stepper.step(g[i], a[i])] for i in range(n)])
    assert np.abs(stepped - np.c_[rg, ra]).max() < 1e-5
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    start = (Rotation.from_quat(wxyz_to_xyzw(crop.q_wxyz[0])).as_matrix(), crop.p[0], crop.v[0])
    fixes = PositionFixes(np.arange(0, n, 200), crop.p[:n:200], 0.1, np.zeros(3), "exact 1 Hz")
    batch = fuse(t, rg, ra, start, [fixes])
    online = stream(t, g, a, start, [fixes], model=model)
    assert np.abs(online.causal_p - batch.causal_p).max() < 1e-6
    assert np.abs(online.causal_R - batch.causal_R).max() < 1e-7


def test_the_state_between_keyframes_is_the_imu_prediction():
    """Exact IMU, no aiding: every sample's causal state is the closed-form pose."""
    t, gyro, acc, p, R = spin_and_climb(n=600)
    inc = IncrementalFusion(t, (R[0], p[0], np.zeros(3)))
    states = [inc.add_sample(t[s], gyro[s], acc[s]) for s in range(len(t))]
    assert [s.keyframe for s in states] == [int(i) in set(inc.kf_idx.tolist()) for i in range(len(t))]
    assert not any(s.updated for s in states[:-1]) and states[-1].updated  # the end of the stream
    assert np.abs(np.array([s.p for s in states]) - p).max() < 1e-6
    assert np.abs(np.array([s.R for s in states]) - R).max() < 1e-7
    res = inc.smooth()
    assert np.abs(res.smoothed_p - p[res.kf_idx]).max() < 1e-6


def test_a_stream_out_of_order_or_ended_early_is_refused():
    t, gyro, acc, p, R = spin_and_climb(n=50)
    inc = IncrementalFusion(t, (R[0], p[0], np.zeros(3)))
    inc.add_sample(t[0], gyro[0], acc[0])
    with pytest.raises(InvalidInputError, match="sample 1: stamp"):
        inc.add_sample(t[2], gyro[2], acc[2])
    with pytest.raises(InvalidInputError, match="after the last sample"):
        inc.smooth()


# --------------------------------------------------------------------------------------------
# the CLI


def short_recording(shipped, root, samples=1600):
    """The first samples of the MH_04 crop as a recording of its own under ``root``."""
    src, dst = shipped / CROP / "mav0", root / "euroc" / "MH_04_short" / "mav0"
    (dst / "imu0").mkdir(parents=True)
    (dst / "state_groundtruth_estimate0").mkdir()
    shutil.copy(src / "imu0" / "sensor.yaml", dst / "imu0" / "sensor.yaml")
    for rel, n in (("imu0/data.csv", samples), ("state_groundtruth_estimate0/data.csv", samples + 20)):
        lines = (src / rel).read_text().splitlines(keepends=True)
        (dst / rel).write_text("".join(lines[: n + 1]))


def write_config(path, root, out, checkpoint, covariance=""):
    path.write_text(f'''name = "online_test"
init = "groundtruth"
data_root = "{root}"
out_dir = "{out}"
checkpoint = "{checkpoint}"
covariance_checkpoint = "{covariance}"
[[recordings]]
path = "euroc/MH_04_short"
format = "euroc"
groundtruth = "euroc/MH_04_short/mav0/state_groundtruth_estimate0/data.csv"
[[scenarios]]
name = "gnss_1hz"
kind = "position"
rate_hz = 1.0
sigma_m = 0.1
[[scenarios]]
name = "vo_10hz"
kind = "relative_pose"
rate_hz = 10.0
''')


def test_cli_online_streams_raw_and_a_causal_model_and_writes_online_json(shipped, tmp_path, capsys):
    short_recording(shipped, tmp_path / "data")
    ckpt = tmp_path / "causal.pt"
    save_checkpoint(ckpt, tiny_model(), {"test": True}, epoch=1, step=1, best_metric=None)
    cfg_file = tmp_path / "f.toml"
    write_config(cfg_file, tmp_path / "data", tmp_path / "reports", tmp_path / "missing_bidirectional.pt")
    rc = fuse_main(["--config", str(cfg_file), "--online", "--checkpoint", str(ckpt), "--scenarios", "gnss_1hz"])
    assert rc == 0, capsys.readouterr().err
    lines = capsys.readouterr().out.strip().splitlines()
    runs = [ln for ln in lines if "real-time factor" in ln]
    assert len(runs) == 2 and "MH_04_short|gnss_1hz|raw" in runs[0] and "|proposed" in runs[1]
    saved = json.loads((tmp_path / "reports" / "online_test" / "online.json").read_text())
    assert set(saved["runs"]) == {"MH_04_short|gnss_1hz|raw|s0", "MH_04_short|gnss_1hz|proposed|s0"}
    assert saved["machine"]["torch_threads"] == 1
    raw = saved["runs"]["MH_04_short|gnss_1hz|raw|s0"]
    assert raw["samples"] == 1600 and raw["per_sample"]["count"] == 1600 and raw["real_time_factor"] > 0
    # iSAM2 updates: at every 1 Hz fix but the one at sample 0 (it joins the priors), and at the end
    assert raw["update"]["count"] == raw["aiding_count"]
    # the same causal RMSE as the batch run of this recording and aiding
    from imu_learn.fuse.experiments.batch import aiding_rng, load_recording_for_fusion, make_aiding
    from imu_learn.fuse.experiments.config import load
    from imu_learn.fuse.score import score

    cfg = load(cfg_file)
    seq, noise, leica = load_recording_for_fusion(cfg, cfg.recordings[0])
    aiding = make_aiding(cfg.scenarios[0], seq, leica, aiding_rng(0, "MH_04_short", cfg.scenarios[0]))
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    R0 = Rotation.from_quat(wxyz_to_xyzw(seq.q_wxyz[0])).as_matrix()
    batch = fuse(seq.t_ns, seq.gyro, seq.acc, (R0, seq.p[0], seq.v[0]), [aiding],
                 FusionSettings(noise, cfg.gravity, cfg.keyframe_hz))
    assert raw["causal"]["pos_rmse_m"] == pytest.approx(score(batch, seq.t_ns, seq.p, seq.q_wxyz)["causal"]["pos_rmse_m"],
                                                        abs=1e-12)


def test_a_bidirectional_checkpoint_is_a_one_line_typed_error(shipped, tmp_path, capsys):
    ckpt = tmp_path / "bi.pt"
    save_checkpoint(ckpt, tiny_model(causal=False), {"test": True}, epoch=1, step=1, best_metric=None)
    with pytest.raises(ConfigError, match="bidirectional"):
        load_causal_model(ckpt)
    with pytest.raises(ConfigError, match="causal"):
        CausalStepper(tiny_model(causal=False))
    short_recording(shipped, tmp_path / "data", samples=400)
    cfg_file = tmp_path / "f.toml"
    write_config(cfg_file, tmp_path / "data", tmp_path / "reports", ckpt)  # the config's own model
    assert fuse_main(["--config", str(cfg_file), "--online"]) == 2
    cap = capsys.readouterr()
    err = cap.err.strip().splitlines()
    assert len(err) == 1 and "ConfigError" in err[0] and "bidirectional" in err[0] and "Traceback" not in cap.err
    assert not (tmp_path / "reports" / "online_test" / "online.json").exists()  # refused before any run
    assert fuse_main(["--config", str(cfg_file), "--online", "--recordings", "nowhere"]) == 2
    assert "--recordings: nowhere not in the config" in capsys.readouterr().err


def test_online_options_without_online_are_refused(tmp_path, capsys):
    assert fuse_main(["--config", str(tmp_path / "f.toml"), "--checkpoint", "x.pt"]) == 2
    assert capsys.readouterr().err == "imu-learn fuse: error: ConfigError: --checkpoint: only with --online\n"


def test_help_documents_every_option_and_gives_an_example(capsys):
    ap = parser()
    with pytest.raises(SystemExit):
        ap.parse_args(["--help"])
    text = capsys.readouterr().out
    options = [s for a in ap._actions for s in a.option_strings if s.startswith("--")]
    assert {"--config", "--data-root", "--out", "--online", "--checkpoint", "--recordings", "--scenarios",
            "--inputs", "--threads", "--traceback", "--help"} <= set(options)
    for a in ap._actions:
        assert a.help and a.help.strip(), a.option_strings
    for o in options:
        assert o in text
    assert "examples:" in text and "imu-learn fuse --config configs/fuse_euroc.toml" in text and "--online" in text
    # at most 20 options, each with one meaning; no mode of another command, no bench script
    assert len([a for a in ap._actions if a.help != "==SUPPRESS=="]) <= 20
    assert "bench/" not in text and "imu-learn navigate" in text and "--aiding" not in text


# --------------------------------------------------------------------------------------------
# the learned input: a bidirectional covariance model streamed by windows (WindowedStepper)

LEARNED = REPO / "models" / "euroc_adis16448_cov.pt"


def tiny_cov_model(window, overlap, seed=0):
    from imu_learn.infer.windowing import Windowing, attach

    torch.manual_seed(seed)
    m = ImuRefiner(ModelConfig(causal=False, hidden=8, fc=8, covariance=True))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
    return attach(m.eval(), Windowing(window, overlap))


def stream_windows(stepper, gyro, acc):
    """Every released sample (index, gyro, acc, var) and the arrival that released it."""
    out, at = [], []
    for i in range(len(gyro)):
        r = stepper.push(gyro[i], acc[i])
        out += r
        at += [i] * len(r)
    r = stepper.finish()
    return out + r, np.array(at + [len(gyro) - 1] * len(r))


@pytest.mark.parametrize("window,overlap", [(8, 4), (7, 3), (6, 5), (9, 0), (1, 0)])
def test_windowed_stepper_follows_the_one_windowing_rule_for_every_length(window, overlap):
    """Whatever the length N (unknown while streaming; window_plan moves its last window back to end at
    N), each sample is released once, in order, and is apply()'s sample; the model runs once per window."""
    from imu_learn.infer.windowing import apply, window_plan

    model = tiny_cov_model(window, overlap)
    rng = np.random.default_rng(window)
    for n in range(1, 5 * window + 8):
        g, a = rng.normal(size=(n, 3)), rng.normal(9.8, 1.0, size=(n, 3))
        rg, ra, rv = apply(model, g, a, variance=True)
        st = WindowedStepper(model)
        out, at = stream_windows(st, g, a)
        assert [o[0] for o in out] == list(range(n)), (n, [o[0] for o in out])
        assert (at >= np.arange(n)).all() and st.model_calls == len(window_plan(n, window, overlap))
        got = np.array([np.r_[o[1], o[2]] for o in out])
        var = np.array([o[3] for o in out])
        # one window per forward here, 16 offline: the same up to float32 rounding (measured: refined
        # bit-identical, variances <= 2e-6 relative)
        assert np.abs(got - np.c_[rg, ra]).max() <= 1e-6
        assert np.abs(var / rv - 1).max() <= 1e-5


def test_learned_streamed_equals_offline_apply_on_the_crop(crop):
    """The shipped checkpoint on the 60 s crop: the streamed refined samples and variances are
    apply(model, gyro, acc, variance=True)'s (measured: refined <= 6e-8, variances <= 2e-6 relative:
    float32 rounding of a 1-window vs a 16-window forward); a sample waits at most a window, and inside
    the recording (not its first window nor the end) at most 3/4 of one."""
    from imu_learn.infer.windowing import apply, window_plan

    model = load_learned_model(LEARNED)
    W = model.windowing.window
    g, a = crop.gyro, crop.acc
    rg, ra, rv = apply(model, g, a, variance=True)
    st = WindowedStepper(model)
    out, at = stream_windows(st, g, a)
    n = len(g)
    assert [o[0] for o in out] == list(range(n)) and st.model_calls == len(window_plan(n, W, model.windowing.overlap))
    got = np.array([np.r_[o[1], o[2]] for o in out])
    var = np.array([o[3] for o in out])
    assert np.abs(got - np.c_[rg, ra]).max() <= 1e-6
    assert np.abs(var / rv - 1).max() <= 1e-5
    delay = at - np.arange(n)
    assert delay.max() <= W - 1 and delay[W : n - 2 * W].max() <= 3 * W // 4


def test_online_learned_equals_the_batch_on_the_offline_refined_input_and_variances(crop):
    n = 2400  # 12 s of the crop, 1 Hz fixes
    t, g, a = crop.t_ns[:n], crop.gyro[:n], crop.acc[:n]
    from scipy.spatial.transform import Rotation

    from imu_learn.core.quat import wxyz_to_xyzw
    from imu_learn.infer.windowing import apply, window_plan
    model = load_learned_model(LEARNED)
    rg, ra, rv = apply(model, g, a, variance=True)
    start = (Rotation.from_quat(wxyz_to_xyzw(crop.q_wxyz[0])).as_matrix(), crop.p[0], crop.v[0])
    fixes = PositionFixes(np.arange(0, n, 200), crop.p[:n:200], 0.1, np.zeros(3), "exact 1 Hz")
    batch = fuse(t, rg, ra, start, [fixes], var=rv)
    assert np.abs(rg - g).max() > 1e-3 and np.abs(ra - a).max() > 1e-2  # the model changes the data
    online = stream(t, g, a, start, [fixes], model=model)
    assert np.array_equal(online.kf_idx, batch.kf_idx)
    # measured: 1.0e-9 m and 3.2e-10 (the refined inputs differ by float32 rounding, above)
    assert np.abs(online.causal_p - batch.causal_p).max() < 1e-7
    assert np.abs(online.causal_R - batch.causal_R).max() < 1e-8
    # each sample is fused once its window settled it; the model's calls are in the latency of the
    # samples that completed a window
    idx = online.released_index()
    assert (idx >= np.arange(n)).all() and (np.diff(idx) >= 0).all() and idx[-1] == n - 1
    st = online.stats()
    assert st["algorithmic_delay"]["max_samples"] == int((idx - np.arange(n)).max()) > 0
    w = model.windowing
    assert st["model_run"]["count"] == online.model_ran.sum() == len(window_plan(n, w.window, w.overlap))
    assert np.array_equal(online.algorithmic_delay_ns(), t[idx] - t)


def test_learned_without_a_covariance_head_or_causal_is_a_config_error(tmp_path):
    bi = tmp_path / "bi.pt"
    save_checkpoint(bi, tiny_model(causal=False), {"test": True}, epoch=1, step=1, best_metric=None)
    with pytest.raises(ConfigError, match="covariance head"):
        load_learned_model(bi)
    with pytest.raises(ConfigError, match="covariance head"):
        WindowedStepper(tiny_model(causal=False))
    t, gyro, acc, start, fixes = noisy_case()
    with pytest.raises(ConfigError, match="covariance head"):
        stream(t, gyro, acc, start, [fixes], model=tiny_model(causal=False))
    causal = tmp_path / "causal.pt"
    save_checkpoint(causal, tiny_model(), {"test": True}, epoch=1, step=1, best_metric=None)
    with pytest.raises(ConfigError, match="causal"):
        load_learned_model(causal)


def test_cli_online_streams_learned_with_its_variances(shipped, tmp_path, capsys):
    short_recording(shipped, tmp_path / "data")
    cov = tmp_path / "cov.pt"
    save_checkpoint(cov, tiny_cov_model(200, 100), {"test": True}, epoch=1, step=1, best_metric=None)
    cfg_file = tmp_path / "f.toml"
    write_config(cfg_file, tmp_path / "data", tmp_path / "reports", tmp_path / "unused.pt", cov)
    rc = fuse_main(["--config", str(cfg_file), "--online", "--inputs", "learned", "--scenarios", "gnss_1hz"])
    assert rc == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "MH_04_short|gnss_1hz|learned" in out and "algorithmic delay median" in out
    run = json.loads((tmp_path / "reports" / "online_test" / "online.json").read_text())["runs"][
        "MH_04_short|gnss_1hz|learned|s0"]
    assert run["checkpoint"] == str(cov) and run["displacement"] == ""
    assert run["samples"] == 1600 and 0 < run["algorithmic_delay"]["max_samples"] < 200
    assert run["model_run"]["count"] == 15  # windows of 200 samples starting every 100: 0, 100, ..., 1400
    # a model without a covariance head is refused before any run
    write_config(cfg_file, tmp_path / "data", tmp_path / "reports2", tmp_path / "unused.pt", tmp_path / "bi.pt")
    save_checkpoint(tmp_path / "bi.pt", tiny_model(causal=False), {"test": True}, epoch=1, step=1, best_metric=None)
    assert fuse_main(["--config", str(cfg_file), "--online", "--inputs", "raw,learned"]) == 2
    err = capsys.readouterr().err
    assert "ConfigError" in err and "covariance head" in err
    assert not (tmp_path / "reports2" / "online_test" / "online.json").exists()
