"""The label cache: written atomically, skipped when up to date, rebuilt when stale, resumable."""
import json
import shutil

import pytest

from imu_learn.cli import labels as labels_cli
from imu_learn.data import cache
from imu_learn.data import label_builder as labels
from imu_learn.errors import CacheError
from imu_learn.util.atomic import atomic_write_bytes


@pytest.fixture()
def dataset(tmp_path, shipped):
    root = tmp_path / "euroc"
    shutil.copytree(shipped / "euroc", root)
    return root


def test_build_then_skip_then_rebuild_stale(dataset, tmp_path):
    out = tmp_path / "cache"
    m1 = labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    assert [r["name"] for r in m1["recordings"]] == ["MH_01_easy", "MH_04_difficult", "V1_01_easy"]
    pairs = cache.load_cache(out)
    seq, lab = pairs[0]
    assert lab["dq_wxyz"].shape == (len(lab["starts"]), 5, 4)
    assert seq.q_wxyz.shape == (len(seq), 4)
    secs = [r["seconds"] for r in m1["recordings"]]
    m2 = labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    assert [r["seconds"] for r in m2["recordings"]] == secs  # reused, not recomputed
    # Touch one source: only that recording is rebuilt.
    imu = dataset / "V1_01_easy" / "mav0" / "imu0" / "data.csv"
    imu.write_text(imu.read_text())
    m3 = labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    before = {r["name"]: r["fingerprint"] for r in m1["recordings"]}
    after = {r["name"]: r["fingerprint"] for r in m3["recordings"]}
    assert after["MH_01_easy"] == before["MH_01_easy"] and after["MH_04_difficult"] == before["MH_04_difficult"]
    assert after["V1_01_easy"] != before["V1_01_easy"]


def test_changed_settings_rebuild(dataset, tmp_path):
    out = tmp_path / "cache"
    labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    labels.build_cache("euroc", dataset, out, window=120, stride=50, progress=False)
    seq, lab = cache.load_cache(out)[0]
    assert int(lab["horizons"][-1]) == 120


def test_other_cache_version_is_refused_unless_rebuild(dataset, tmp_path):
    out = tmp_path / "cache"
    labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    m = json.loads((out / "manifest.json").read_text())
    m["cache_version"] = 999
    (out / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(CacheError, match="--rebuild"):
        labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False)
    labels.build_cache("euroc", dataset, out, window=100, stride=50, progress=False, rebuild=True)
    assert cache.read_manifest(out)["cache_version"] == cache.CACHE_VERSION


def test_cli_reports_and_bad_root_is_one_line_error(dataset, tmp_path, capsys):
    assert labels_cli.main(["euroc", "--dataset-dir", str(dataset), "--out", str(tmp_path / "c"), "--quiet"]) == 0
    assert "MH_01_easy" in capsys.readouterr().out
    assert labels_cli.main(["euroc", "--dataset-dir", str(tmp_path / "missing"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err == f"imu-learn labels: error: FileNotFoundError: {tmp_path / 'missing'}: No such file or directory\n"


def test_atomic_write_leaves_old_file_on_failure(tmp_path):
    p = tmp_path / "x.bin"
    p.write_bytes(b"old")

    def boom(f):
        f.write(b"partial")
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError):
        atomic_write_bytes(p, boom)
    assert p.read_bytes() == b"old"
    assert [x.name for x in tmp_path.iterdir()] == ["x.bin"]
