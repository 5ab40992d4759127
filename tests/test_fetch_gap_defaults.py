"""The Fetch robot's motion capture drops frames (gaps up to 70 ms at ~100 Hz): `labels` and
`groundtruth` bridge them by default (the dataset's own ground-truth gap, data.datasets.MAX_GAP_S), and
where a gap setting leaves a recording without a segment, or keeps much less of it, they say so naming
their own command-line option and the value that keeps it."""
from __future__ import annotations

from pathlib import Path

import pytest

from imu_learn.cli import main
from imu_learn.data.datasets import dataset_max_gap_s
from imu_learn.data.label_builder import dataset_options
from imu_learn.data.loading import AlignOptions

RECORDINGS = ["01_square", "03_um", "04_eight", "06_right_turn", "07_left_turn", "08_origin"]


@pytest.fixture(scope="module")
def fetch(shared) -> Path:
    root = shared / "fetch"
    if not (root / "04_eight" / "mav0" / "mocap0" / "data.csv").is_file():
        pytest.skip(f"{root} does not hold the Fetch recordings (real datasets live beside the repository)")
    return root


def run(argv, capsys):
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_fetch_has_its_own_gap_and_the_others_keep_the_loaders():
    assert dataset_max_gap_s("fetch") == 0.1 and dataset_options("fetch").max_gap_s == 0.1
    assert dataset_max_gap_s("euroc") is None and dataset_options("euroc") == AlignOptions()


def test_a_config_root_without_a_gap_takes_its_formats_own():
    """A config's data root that leaves ``max_gap_s`` unset aligns with its format's gap (Fetch's 0.1 s:
    a user's own Fetch config keeps every recording whole, as ``labels fetch`` does), an explicit one as
    written; a saved config's null reads back as unset, a string is refused."""
    from imu_learn.data.config import RootConfig
    from imu_learn.data.splits import recording_source, root_max_gap_s
    from imu_learn.errors import ConfigError
    from imu_learn.settings import from_dict

    fetch = from_dict(RootConfig, {"path": "fetch", "format": "fetch"})
    assert fetch.max_gap_s is None and root_max_gap_s(fetch) == 0.1
    assert recording_source("01_square", Path("x"), fetch, None).options.max_gap_s == 0.1
    assert root_max_gap_s(from_dict(RootConfig, {"path": "e", "format": "euroc"})) == AlignOptions().max_gap_s
    assert root_max_gap_s(from_dict(RootConfig, {"path": "f", "format": "fetch", "max_gap_s": 0.03})) == 0.03
    assert from_dict(RootConfig, {"path": "f", "format": "fetch", "max_gap_s": None}).max_gap_s is None
    with pytest.raises(ConfigError, match="max_gap_s: expected a number"):
        from_dict(RootConfig, {"path": "f", "max_gap_s": "0.1"})


def test_labels_for_fetch_need_no_option(fetch, tmp_path, capsys):
    rc, out, err = run(["labels", "fetch", "--data-root", fetch.parent, "--out", tmp_path / "c", "-q"], capsys)
    assert rc == 0, err
    lines = {line.split(":")[0]: line for line in out.splitlines()}
    for name in RECORDINGS:  # each whole, in one segment, nothing dropped in the mocap's gaps
        assert "1 segment(s)" in lines[name] and "0 in gaps" in lines[name], out


def test_a_labels_refusal_names_the_max_gap_that_keeps_the_recording(fetch, tmp_path, capsys):
    rc, out, err = run(["labels", "fetch", "--dataset-dir", fetch, "--out", tmp_path / "c", "-q",
                        "--max-gap", "0.05"], capsys)
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "04_eight" in err and "--max-gap 0.07 bridges" in err, err
    assert "min_segment_s" not in err and "--max-gap-s" not in err, err


def test_a_labels_refusal_not_from_dropouts_names_the_option_not_a_python_parameter(fetch, tmp_path, capsys):
    rec = tmp_path / "data" / "short"  # 0.6 s: no segment of 1 s whatever the gap
    for kind in ("imu0", "mocap0"):
        lines = (fetch / "04_eight" / "mav0" / kind / "data.csv").read_text().splitlines(keepends=True)
        (rec / "mav0" / kind).mkdir(parents=True)
        (rec / "mav0" / kind / "data.csv").write_text("".join(lines[:61]))
    rc, out, err = run(["labels", "fetch", "--dataset-dir", rec.parent, "--out", tmp_path / "c", "-q"], capsys)
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert "raise --max-gap (now 0.1 s)" in err and "min_segment_s" not in err, err


def test_groundtruth_of_fetch_keeps_the_recording_by_default(fetch, capsys):
    rc, out, err = run(["groundtruth", "--input", fetch / "03_um"], capsys)
    assert rc == 0, err
    assert "4911 IMU samples in 1 segment(s)" in out and "note:" not in out, out


def test_groundtruth_says_when_its_gap_keeps_much_less_than_the_recording(fetch, capsys):
    rc, out, err = run(["groundtruth", "--input", fetch / "03_um", "--max-gap-s", "0.05"], capsys)
    assert rc == 0, err
    notes = [line for line in out.splitlines() if "note:" in line]
    assert len(notes) == 1, out
    assert "kept 1537 of the 4911 IMU samples" in notes[0] and "--max-gap-s 0.07 keeps more" in notes[0], notes


def test_labels_says_where_its_gaps_leave_a_recording_without_windows(fetch, tmp_path, capsys):
    rc, out, err = run(["labels", "fetch", "--data-root", fetch.parent, "--out", tmp_path / "c", "-q",
                        "--max-gap", "0.06"], capsys)
    assert rc == 0, err
    said = [line for line in out.splitlines() if "a larger --max-gap (now 0.06 s) keeps more" in line]
    assert any(line.startswith("04_eight:") for line in said), out
    rc, out, err = run(["labels", "fetch", "--data-root", fetch.parent, "--out", tmp_path / "d", "-q"], capsys)
    assert rc == 0 and "keeps more" not in out, out
