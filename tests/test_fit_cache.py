"""fit reads the label cache (data.cache): same data and losses as from the raw files, nothing
parsed when the cache is valid, a stale or damaged entry rebuilt (with a warning), never used."""
import logging
import shutil

import numpy as np
import pytest

from imu_learn.data import cache, splits
from imu_learn.data import label_builder as labels
from imu_learn.errors import CacheError
from imu_learn.infer.checkpoint import load_checkpoint
from imu_learn.train import trainer
from imu_learn.train.config import build_config

FIELDS = ("t_ns", "gyro", "acc", "p", "v", "q_wxyz")


@pytest.fixture()
def dataset(tmp_path, shipped):
    root = tmp_path / "euroc"
    for name in ("MH_01_easy", "V1_01_easy"):
        shutil.copytree(shipped / "euroc" / name, root / name)
    return root


def config(dataset, cache_dir=None, **data):
    """A tiny run on the copied crops (V1_01 against its 20 Hz ASL state, as configs/default.toml)."""
    v1 = dataset / "V1_01_easy"
    d = {
        "roots": [{"path": str(dataset / "MH_01_easy"), "format": "euroc"},
                  {"path": str(v1), "format": "euroc", "groundtruth": str(v1 / "groundtruth_state_20hz.csv"),
                   "max_gap_s": 0.06}],
        "window": 50, "batch_size": 8, "val_stride": 200, "split": {"test": []},
        **({"cache": str(cache_dir)} if cache_dir is not None else {}), **data,
    }
    return build_config({"data": d, "seed": 7, "threads": 1,
                         "model": {"hidden": 8, "fc": 8, "layers": 1},
                         "optim": {"steps_per_epoch": 3, "epochs": 1, "lr": 1e-3, "select": "val_pose"}}, {})


def assert_same_split(a, b):
    for k in ("train", "val", "test"):
        assert [s.name for s in a[k]] == [s.name for s in b[k]]
        for x, y in zip(a[k], b[k]):
            for f in FIELDS:
                np.testing.assert_array_equal(getattr(x, f), getattr(y, f))


def no_parsing(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("raw files parsed although the cache is valid")

    monkeypatch.setattr(splits, "load_sequence", refuse)
    monkeypatch.setattr(labels, "load_recording", refuse)


def losses(cfg, split, run_dir):
    got = []
    trainer.train(cfg, run_dir, split=split, on_step=lambda step, loss: got.append(loss), progress=False)
    rows = [{k: v for k, v in r.items() if k != "elapsed_s"} for r in load_checkpoint(run_dir / "last.pt")["extra"]["history"]]
    return got, rows


def test_fit_from_the_cache_matches_fit_from_raw_files_and_parses_nothing(dataset, tmp_path, monkeypatch, caplog):
    raw = splits.make_split(config(dataset).data)
    folder = tmp_path / "cache"
    with caplog.at_level(logging.WARNING):
        built = splits.make_split(config(dataset, folder).data)  # no cache yet: built, and said so
    assert "building MH_01_easy (not in the cache)" in caplog.text
    assert "V1_01_easy" not in caplog.text  # only what the split names (no test split here)
    assert_same_split(raw, built)
    assert built.record["cache"] == str(folder)

    no_parsing(monkeypatch)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        cached = splits.make_split(config(dataset, folder).data)
    assert caplog.text == ""
    assert_same_split(raw, cached)

    # the same batches, hence the same step and first-epoch losses (train, validation, pose score)
    loss_raw, rows_raw = losses(config(dataset), raw, tmp_path / "raw")
    loss_cache, rows_cache = losses(config(dataset, folder), cached, tmp_path / "cached")
    assert len(loss_raw) == 3 and loss_raw == loss_cache
    assert rows_raw == rows_cache and "val_pose_score" in rows_raw[0]


def test_the_labels_cache_is_read_as_built(dataset, tmp_path, monkeypatch):
    """`labels euroc` then fit: recordings read and aligned alike are taken from the cache as is."""
    folder = tmp_path / "cache"
    labels.build_cache("euroc", dataset, folder, window=100, stride=50, progress=False)
    before = (folder / cache.MANIFEST).read_bytes()
    cfg = config(dataset, folder, roots=[{"path": str(dataset), "format": "euroc"}])
    raw = splits.make_split(config(dataset, roots=[{"path": str(dataset), "format": "euroc"}]).data)
    no_parsing(monkeypatch)
    assert_same_split(raw, splits.make_split(cfg.data))
    assert (folder / cache.MANIFEST).read_bytes() == before  # nothing rewritten


def rebuilt(dataset, folder, caplog, **data):
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        split = splits.make_split(config(dataset, folder, **data).data)
    return split, caplog.text


def test_a_stale_or_damaged_entry_is_rebuilt_never_used(dataset, tmp_path, caplog):
    folder = tmp_path / "cache"
    splits.make_split(config(dataset, folder).data)

    # a source file changed: that recording (only) is rebuilt, and the split has the new data
    imu = dataset / "MH_01_easy" / "mav0" / "imu0" / "data.csv"
    lines = imu.read_text().splitlines(keepends=True)
    head = [i for i, x in enumerate(lines) if not x.startswith("#")][0]
    cols = lines[head + 5].rstrip("\r\n").split(",")
    cols[1] = repr(float(cols[1]) + 0.5)
    lines[head + 5] = ",".join(cols) + "\n"
    imu.write_text("".join(lines))
    split, log = rebuilt(dataset, folder, caplog)
    assert "building MH_01_easy (its source files" in log and "V1_01_easy" not in log
    assert_same_split(splits.make_split(config(dataset).data), split)

    # an alignment setting changed (data.roots[i].max_gap_s): rebuilt
    roots = config(dataset).data.roots
    more = [{"path": r.path, "format": r.format, "groundtruth": r.groundtruth, "max_gap_s": 0.07} for r in roots]
    _, log = rebuilt(dataset, folder, caplog, roots=more)
    assert "building MH_01_easy (its source files or how they are read and aligned changed" in log

    # a segment file damaged behind the manifest's back: named, rebuilt
    m = cache.read_manifest(folder)
    seg = folder / m["recordings"][0]["segments"][0]["file"]
    seg.write_bytes(seg.read_bytes()[:-10])
    _, log = rebuilt(dataset, folder, caplog, roots=more)
    assert f"building {m['recordings'][0]['name']} ({seg}: truncated or modified" in log


def test_a_cache_of_another_format_version_is_refused(dataset, tmp_path):
    import json

    folder = tmp_path / "cache"
    splits.make_split(config(dataset, folder).data)
    m = json.loads((folder / cache.MANIFEST).read_text())
    m["cache_version"] = 2
    (folder / cache.MANIFEST).write_text(json.dumps(m))
    with pytest.raises(CacheError, match="cache format version 2"):
        splits.make_split(config(dataset, folder).data)


def test_data_cache_defaults_to_the_raw_files():
    assert build_config({}, {}).data.cache == ""
