"""Leave-one-recording-out validation (imu-learn fit --loro): folds, verdict, resume."""
from __future__ import annotations

import json

import pytest

from imu_learn.cli.fit import main as fit_main
from imu_learn.train import loro
from imu_learn.train.config import build_config


def cell(rec, rot, trans, n=10, protocol="open loop"):
    return {"held_out": rec, "n": n, "protocol": protocol, "seeds": 3, "floor": {"rot_deg": 1.0, "trans_m": 1.0},
            "rot_ratio_mean": rot[0], "rot_ratio_worst": rot[1], "trans_ratio_mean": trans[0], "trans_ratio_worst": trans[1]}


def test_verdict_ships_only_when_every_recording_and_seed_beats_the_floor():
    good = [cell("a", (0.9, 0.95), (0.8, 0.9)), cell("b", (0.95, 0.98), (0.97, 0.985))]
    assert loro.verdict(good)["ships"]
    one_seed_worse = good + [cell("c", (0.9, 1.01), (0.9, 0.95))]
    v = loro.verdict(one_seed_worse)
    assert not v["ships"] and v["recordings_not_beaten"] == ["c"]
    tie = good + [cell("d", (0.995, 0.999), (0.9, 0.95))]  # mean not below BEAT
    assert loro.verdict(tie)["recordings_not_beaten"] == ["d"]
    assert not loro.verdict([])["ships"]


def test_summarise_means_and_worst_over_seeds():
    rows = [{"held_out": "a", "seed": s, "cells": [{"n": 10, "protocol": "open loop", "floor": {"rot_deg": 2.0, "trans_m": 0.1},
                                                     "model": {"rot_deg": r * 2.0, "trans_m": r * 0.1},
                                                     "rot_ratio": r, "trans_ratio": r}]} for s, r in enumerate((0.8, 0.9, 1.3))]
    (c,) = loro.summarise(rows)
    assert c["rot_ratio_mean"] == pytest.approx(1.0) and c["rot_ratio_worst"] == 1.3 and c["seeds"] == 3
    assert c["model_rot_deg_mean"] == pytest.approx(2.0)


def test_folds_hold_each_recording_out_whole():
    cfg = build_config({}, {})  # the shipped crops: MH_01_easy and V1_01_easy
    folds = loro.load_folds(cfg, ["MH_01_easy", "V1_01_easy"])
    assert [f.held_out for f in folds] == ["MH_01_easy", "V1_01_easy"]
    for f in folds:
        assert f.trained_on == [n for n in ("MH_01_easy", "V1_01_easy") if n != f.held_out]
        assert all(s.name.startswith(f.held_out) for s in f.test)
        assert not any(s.name.startswith(f.held_out) for s in f.train + f.val)
        assert sum(len(s) for s in f.test) > 0
    with pytest.raises(Exception, match="at least two recordings"):
        loro.load_folds(cfg, ["MH_01_easy"])


@pytest.mark.slow
def test_loro_on_the_crops_untrained_model_is_the_floor_and_rerun_continues(tmp_path, capsys):
    out = tmp_path / "loro"
    argv = ["--loro", str(out), "--seeds", "0", "--recordings", "MH_01_easy", "V1_01_easy",
            "--optim.epochs", "1", "--optim.steps_per_epoch", "3", "--quiet"]
    assert fit_main(argv) == 0
    res = json.loads((out / "loro.json").read_text())
    assert res["runs_done"] == res["runs_total"] == 2 and not res["verdict"].get("incomplete")
    for rec in ("MH_01_easy", "V1_01_easy"):
        assert (out / rec / "profile.json").exists() and (out / rec / "seed0" / "heldout.json").exists()
        prof = json.loads((out / rec / "profile.json").read_text())
        assert prof["sources"][0]["held_out"] == rec and rec not in prof["sources"][0]["recordings"]
    for row in res["runs"]:
        if row["best_epoch"] == 0:  # no epoch beat the floor: the model kept is the untrained one, the floor
            for c in row["cells"]:
                assert c["rot_ratio"] == pytest.approx(1.0, abs=2e-3) and c["trans_ratio"] == pytest.approx(1.0, abs=2e-3)
    assert "Verdict" in (out / "loro.md").read_text()
    before = (out / "MH_01_easy" / "seed0" / "heldout.json").stat().st_mtime_ns
    assert fit_main(argv) == 0  # a rerun skips finished folds
    assert (out / "MH_01_easy" / "seed0" / "heldout.json").stat().st_mtime_ns == before
