"""imu_learn.infer.exporters: TorchScript and ONNX reproduce the torch model on real IMU windows."""
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from imu_learn import _imu_core as core
from imu_learn.cli.export import main
from imu_learn.infer.checkpoint import load_model, save_checkpoint
from imu_learn.nn.model import ImuRefiner, ModelConfig

torch.set_num_threads(1)

REPO = Path(__file__).resolve().parent.parent
IMU = REPO / "datasets" / "euroc" / "V1_01_easy" / "mav0" / "imu0" / "data.csv"
TRACE_W = 200


@pytest.fixture(scope="module", params=[False, True], ids=["bidirectional", "causal"])
def exported(request, tmp_path_factory):
    causal = request.param
    tmp = tmp_path_factory.mktemp("export_causal" if causal else "export_bi")
    _t, g, a = core.read_asl_imu(str(IMU))
    raw = np.c_[g, a]
    torch.manual_seed(3)
    m = ImuRefiner(ModelConfig(causal=causal), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
    ckpt = tmp / "ckpt.pt"
    save_checkpoint(ckpt, m, {}, epoch=0, step=0, best_metric=None)
    assert main(["--checkpoint", str(ckpt), "--out", str(tmp / "out"), "--window", str(TRACE_W)]) == 0
    return load_model(ckpt), tmp / "out", raw.astype(np.float32)


def windows(raw):
    """Real windows: the trace length, a different length, and a batch of 3 of another length."""
    return [raw[None, 1000 : 1000 + TRACE_W], raw[None, 5000 : 5000 + 517], np.stack([raw[i : i + 333] for i in (0, 4000, 9000)])]


def reference(model, x):
    with torch.no_grad():
        y = model(torch.from_numpy(np.ascontiguousarray(x))).numpy()
    assert np.abs(y - x).max() > 1e-4  # the head is non-zero: the check is not identity vs identity
    return y


def test_torchscript_reproduces_torch(exported):
    model, out, raw = exported
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ts = torch.jit.load(str(out / "model.ts"))
    for x in windows(raw):
        with torch.no_grad():
            y = ts(torch.from_numpy(np.ascontiguousarray(x))).numpy()
        np.testing.assert_allclose(y, reference(model, x), atol=1e-5, rtol=0)


def test_onnx_reproduces_torch_with_dynamic_batch_and_time(exported):
    ort = pytest.importorskip("onnxruntime")
    model, out, raw = exported
    sess = ort.InferenceSession(str(out / "model.onnx"), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["imu"] and [o.name for o in sess.get_outputs()] == ["refined"]
    shape = sess.get_inputs()[0].shape
    assert isinstance(shape[0], str) and isinstance(shape[1], str) and shape[2] == 6  # dynamic batch and time
    for x in windows(raw):
        y = sess.run(["refined"], {"imu": np.ascontiguousarray(x)})[0]
        np.testing.assert_allclose(y, reference(model, x), atol=1e-5, rtol=0)


def test_card_describes_the_export(exported):
    model, out, _raw = exported
    card = json.loads((out / "model.json").read_text())
    assert card["inputs"][0]["shape"] == ["batch", "time", 6] and card["inputs"][0]["dtype"] == "float32"
    assert card["outputs"][0]["name"] == "refined"
    np.testing.assert_allclose(card["normalisation"]["mean"], model.mean.numpy(), rtol=1e-6)
    np.testing.assert_allclose(card["normalisation"]["std"], model.std.numpy(), rtol=1e-6)
    assert card["model_args"] == model.model_args() and card["causal"] == model.cfg.causal
    assert card["trace_window"] == TRACE_W
    assert card["dynamic_axes"] == {"batch": True, "time": True}
    for name in ("torchscript", "onnx"):
        assert card["checks"][name]["max_abs_diff_other_shape"] < 1e-5


def test_bad_checkpoint_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"garbage")
    assert main(["--checkpoint", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("imu-learn export: error: CheckpointError: ")


def test_a_covariance_head_is_exported_as_a_second_output(tmp_path):
    """TorchScript and ONNX of a model with a covariance head return (refined, variance), both equal
    to the torch model's on real windows; the card names the output and its units."""
    _t, g, a = core.read_asl_imu(str(IMU))
    raw = np.c_[g, a].astype(np.float32)
    torch.manual_seed(4)
    m = ImuRefiner(ModelConfig(covariance=True), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
        for p in m.cov_head.parameters():
            torch.nn.init.normal_(p, std=0.5)
    ckpt = tmp_path / "ckpt.pt"
    save_checkpoint(ckpt, m, {}, epoch=0, step=0, best_metric=None)
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--out", str(out), "--window", str(TRACE_W)]) == 0
    model = load_model(ckpt)
    x = raw[None, 5000:5000 + 517]
    with torch.no_grad():
        ref_y, ref_v = (t.numpy() for t in model.forward_with_variance(torch.from_numpy(x)))
    assert ref_v.std() > 0.1 * ref_v.mean()  # the variances vary: the check is not constant vs constant
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ts = torch.jit.load(str(out / "model.ts"))
    with torch.no_grad():
        y, v = (t.numpy() for t in ts(torch.from_numpy(x)))
    assert np.abs(y - ref_y).max() < 1e-4 and (np.abs(v - ref_v) / ref_v).max() < 1e-4
    ort = pytest.importorskip("onnxruntime")
    sess = ort.InferenceSession(str(out / "model.onnx"), providers=["CPUExecutionProvider"])
    y, v = sess.run(["refined", "variance"], {"imu": x})
    assert np.abs(y - ref_y).max() < 1e-4 and (np.abs(v - ref_v) / ref_v).max() < 1e-4
    card = json.loads((out / "model.json").read_text())
    assert [o["name"] for o in card["outputs"]] == ["refined", "variance"]
    assert card["outputs"][1]["units"][0] == "(rad/s)^2"


def _small_checkpoint(tmp_path):
    torch.manual_seed(0)
    m = ImuRefiner(ModelConfig(), mean=torch.zeros(6), std=torch.ones(6))
    ckpt = tmp_path / "ckpt.pt"
    save_checkpoint(ckpt, m, {}, epoch=0, step=0, best_metric=None)
    return ckpt


def test_an_opset_the_exporter_cannot_write_is_refused_before_any_file(tmp_path, capsys):
    ckpt = _small_checkpoint(tmp_path)
    for opset in ("5", "30"):
        out = tmp_path / f"o{opset}"
        assert main(["--checkpoint", str(ckpt), "--out", str(out), "--opset", opset]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--opset {opset}" in err and not out.exists()


def test_an_export_stopped_half_way_leaves_the_folder_as_it_was(tmp_path, monkeypatch):
    """Ctrl-C (or any failure) after model.ts is written: the previous export stays whole, no new file."""
    import imu_learn.infer.exporters as ex

    ckpt = _small_checkpoint(tmp_path)
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--out", str(out), "--window", "20"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert set(before) == {"model.ts", "model.onnx", "model.json"}

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(ex, "onnx_checked", interrupted)
    with pytest.raises(KeyboardInterrupt):
        ex.export(ckpt, out, window=30)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".staging")]


def test_the_card_says_how_to_window_the_export_to_get_refines_samples(tmp_path):
    """A model trained on 100-sample windows, exported (traced at 200): the card names the window and overlap
    refine applies it with (not the trace window), and the ONNX graph run by the card's rule, written here
    from its text, gives refine's samples on a 3000-sample real recording; other windows do not."""
    ort = pytest.importorskip("onnxruntime")
    from imu_learn.infer.windowing import apply

    _t, g, a = core.read_asl_imu(str(IMU))
    raw = np.c_[g, a][:3000]
    torch.manual_seed(5)
    m = ImuRefiner(ModelConfig(), mean=torch.tensor(raw.mean(0)), std=torch.tensor(raw.std(0)))
    with torch.no_grad():
        torch.nn.init.normal_(m.head.weight, std=0.5)
    ckpt = tmp_path / "ckpt.pt"
    save_checkpoint(ckpt, m, {"data": {"window": 100}}, epoch=0, step=0, best_metric=None)
    out = tmp_path / "out"
    assert main(["--checkpoint", str(ckpt), "--out", str(out), "--window", str(TRACE_W)]) == 0
    card = json.loads((out / "model.json").read_text())
    assert (card["windowing"]["window"], card["windowing"]["overlap"]) == (100, 50) and card["trace_window"] == TRACE_W
    gr, ar, _ = apply(load_model(ckpt), raw[:, :3], raw[:, 3:])
    refined = np.c_[gr, ar]
    sess = ort.InferenceSession(str(out / "model.onnx"), providers=["CPUExecutionProvider"])

    def by_rule(w, o):
        n, stride = len(raw), w - o
        starts = list(range(0, n - w + 1, stride))
        starts += [n - w] if starts[-1] + w < n else []
        y = np.empty_like(raw)
        for k, s in enumerate(starts):
            lo = 0 if k == 0 else (s + starts[k - 1] + w) // 2
            hi = n if k == len(starts) - 1 else (starts[k + 1] + s + w) // 2
            x = raw[None, s:s + w].astype(np.float32)
            y[lo:hi] = raw[lo:hi] + (sess.run(["refined"], {"imu": x})[0][0] - x[0])[lo - s:hi - s]
        return y

    ours = by_rule(card["windowing"]["window"], card["windowing"]["overlap"])
    assert np.abs(ours - refined).max() < 1e-4
    # the window matters (a random model forgets within tens of samples, so a much shorter one): the check can fail
    assert np.abs(by_rule(10, 5) - refined).max() > 1e-3
