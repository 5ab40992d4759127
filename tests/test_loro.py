"""Leave-one-recording-out validation (imu-learn fit --loro): folds, verdict, resume."""
from __future__ import annotations

import json

import numpy as np
import pytest

from imu_learn.cli.fit import main as fit_main
from imu_learn.train import loro
from imu_learn.train.config import build_config


def cell(rec, rot, trans, n=10, protocol="open loop"):
    return {"held_out": rec, "n": n, "protocol": protocol, "seeds": 3, "floor": {"rot_deg": 1.0, "trans_m": 1.0},
            "rot_ratio_mean": rot[0], "rot_ratio_worst": rot[1], "trans_ratio_mean": trans[0], "trans_ratio_worst": trans[1],
            "rot_model_alone_mean": rot[0], "trans_model_alone_mean": trans[0]}


def aoe(rec, ratio):
    return {"held_out": rec, "n": loro.AOE_N, "protocol": loro.AOE_PROTOCOL, "seeds": 3, "floor": {"aoe_deg": 0.5},
            "aoe_ratio_mean": ratio[0], "aoe_ratio_worst": ratio[1], "aoe_model_alone_mean": ratio[0]}


def test_verdict_ships_only_when_every_recording_and_seed_beats_the_floor():
    good = [cell("a", (0.9, 0.95), (0.8, 0.9)), cell("b", (0.95, 0.98), (0.97, 0.985)),
            aoe("a", (0.9, 0.95)), aoe("b", (0.97, 0.98))]
    assert loro.verdict(good)["ships"]
    one_seed_worse = good + [cell("c", (0.9, 1.01), (0.9, 0.95))]
    v = loro.verdict(one_seed_worse)
    assert not v["ships"] and v["recordings_not_beaten"] == ["c"]
    tie = good + [cell("d", (0.995, 0.999), (0.9, 0.95))]  # mean not below BEAT
    assert loro.verdict(tie)["recordings_not_beaten"] == ["d"]
    assert not loro.verdict([])["ships"]


def test_a_model_that_wins_every_other_cell_and_loses_the_open_loop_aoe_does_not_ship():
    wins = [cell(r, (0.66, 0.7), (0.46, 0.5), n=n, protocol=p) for r in ("train", "val") for n in (10, 200)
            for p in ("open loop", "start-up bias removed")]
    assert loro.verdict(wins + [aoe("train", (0.9, 0.95)), aoe("val", (0.95, 0.98))])["ships"]
    v = loro.verdict(wins + [aoe("train", (0.9, 0.95)), aoe("val", (1.14, 1.2))])  # Blackbird's unseen flight
    assert not v["ships"] and v["recordings_not_beaten"] == ["val"] and v["cells_lost"] == ["val n=whole open-loop AOE: aoe"]
    # the mean below 1 but one seed above it, or the mean not below BEAT: lost too
    assert not loro.verdict(wins + [aoe("train", (0.9, 0.95)), aoe("val", (0.95, 1.01))])["ships"]
    assert not loro.verdict(wins + [aoe("train", (0.9, 0.95)), aoe("val", (0.992, 0.995))])["ships"]
    md = loro.markdown(wins + [aoe("train", (0.9, 0.95)), aoe("val", (1.14, 1.2))], v, (0, 1, 2))
    assert "| val | whole | open-loop AOE | 0.5 | 1.140 (1.200) | 1.140 | - | - | - |" in md
    assert "the profile alone ships" in md and "val n=whole open-loop AOE" in md


def test_a_verdict_without_the_aoe_cell_is_incomplete_and_never_ships():
    wins = [cell(r, (0.66, 0.7), (0.46, 0.5)) for r in ("train", "val")]
    v = loro.verdict(wins + [aoe("train", (0.9, 0.95))])  # val scored before the AOE was a cell
    assert not v["ships"] and "val" in v["incomplete"] and "AOE" in v["incomplete"]
    assert "Verdict: incomplete" in loro.markdown(wins, v, (0,))


def test_an_old_loro_json_reads_as_incomplete(tmp_path):
    """A loro.json written before the AOE was a cell: readable, its verdict recomputed as incomplete."""
    rows = [{"held_out": h, "seed": s, "cells": [{"n": 10, "protocol": "open loop", "floor": {"rot_deg": 1.0, "trans_m": 1.0},
                                                  "model": {"rot_deg": 0.9, "trans_m": 0.9}, "rot_ratio": 0.9,
                                                  "trans_ratio": 0.9}]} for h in ("a", "b") for s in (0, 1)]
    old = {"runs_total": 4, "runs_done": 4, "verdict": {"ships": True}, "runs": rows}
    (tmp_path / "loro.json").write_text(json.dumps(old))
    res = loro.read_loro(tmp_path / "loro.json")
    assert not res["verdict"]["ships"] and "AOE" in res["verdict"]["incomplete"]
    assert {c["held_out"] for c in res["cells"]} == {"a", "b"} and res["cells"][0]["rot_ratio_mean"] == pytest.approx(0.9)


def test_recipe_cells_give_the_profile_in_the_aoe_cell_too():
    model_cells = [{"n": 10, "protocol": "open loop", "floor": {"rot_deg": 1.0, "trans_m": 1.0},
                    "model": {"rot_deg": 0.9, "trans_m": 0.8}, "rot_ratio": 0.9, "trans_ratio": 0.8},
                   {"n": "whole", "protocol": loro.AOE_PROTOCOL, "floor": {"aoe_deg": 0.56}, "model": {"aoe_deg": 0.65},
                    "aoe_ratio": 0.65 / 0.56}]
    assert loro.recipe_cells(model_cells, True) == model_cells
    kept = loro.recipe_cells(model_cells, False)
    assert kept[1]["aoe_ratio"] == 1.0 and kept[1]["model"] == {"aoe_deg": 0.56} and "rot_ratio" not in kept[1]
    rows = [{"held_out": "a", "seed": 0, "cells": kept, "model_cells": model_cells}]
    c = {x["protocol"]: x for x in loro.summarise(rows)}[loro.AOE_PROTOCOL]
    assert c["aoe_ratio_mean"] == 1.0 and c["aoe_model_alone_mean"] == pytest.approx(0.65 / 0.56)


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
        # the AOE integrates the held-out recording's two parts as the one stretch they were cut from
        (whole,) = loro.whole_stretches(f.test)
        assert len(whole) == sum(len(s) for s in f.test) and (np.diff(whole.t_ns) > 0).all()
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
        assert [c["protocol"] for c in row["model_cells"]].count(loro.AOE_PROTOCOL) == 1
        (a,) = [c for c in row["model_cells"] if c["protocol"] == loro.AOE_PROTOCOL]
        assert a["floor"]["aoe_deg"] > 0 and a["stretches"] == 1
        if row["best_epoch"] == 0:  # no epoch beat the floor: the model kept is the untrained one, the floor
            for c in row["model_cells"]:
                for t, _ in loro.cell_terms(c):
                    assert c[f"{t}_ratio"] == pytest.approx(1.0, abs=2e-3), (t, c)
    assert {(c["held_out"], c["protocol"]) for c in res["cells"]} >= {(r, loro.AOE_PROTOCOL) for r in ("MH_01_easy", "V1_01_easy")}
    assert "Verdict" in (out / "loro.md").read_text() and "| open-loop AOE |" in (out / "loro.md").read_text()
    held = out / "MH_01_easy" / "seed0" / "heldout.json"
    before = held.stat().st_mtime_ns
    assert fit_main(argv) == 0  # a rerun skips finished folds
    assert held.stat().st_mtime_ns == before
    # a fold scored before the AOE was a cell: the rerun scores it from the saved run, no retraining
    row = json.loads(held.read_text())
    want = [c for c in row["model_cells"] if c["protocol"] == loro.AOE_PROTOCOL][0]
    old = {**row, "cells": [c for c in row["cells"] if c["protocol"] != loro.AOE_PROTOCOL],
           "model_cells": [c for c in row["model_cells"] if c["protocol"] != loro.AOE_PROTOCOL]}
    held.write_text(json.dumps(old))
    last = (out / "MH_01_easy" / "seed0" / "fit" / "last.pt").stat().st_mtime_ns
    assert fit_main(argv) == 0
    row = json.loads(held.read_text())
    (got,) = [c for c in row["model_cells"] if c["protocol"] == loro.AOE_PROTOCOL]
    assert got["aoe_ratio"] == pytest.approx(want["aoe_ratio"], rel=1e-9) and "aoe_scored_later_s" in row
    assert (out / "MH_01_easy" / "seed0" / "fit" / "last.pt").stat().st_mtime_ns == last
    res = json.loads((out / "loro.json").read_text())
    assert not res["verdict"].get("incomplete")
