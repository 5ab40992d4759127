"""The evaluation report (imu_learn.eval.report): quoted paper figures, tables, summary, files."""
import csv
import json
import math
import re
from pathlib import Path

import pytest

from imu_learn.eval import report

REPO = Path(__file__).resolve().parent.parent
PAPER = REPO.parent / "shared" / "paper" / "imu_rnn_navigation.tex"


# ---------------------------------------------------------------------------------------------
# the paper's Table II, parsed from its LaTeX source


def _cell_text(s: str) -> str:
    s = re.sub(r"\\cite\{[^}]*\}", "", s)
    s = re.sub(r"\{\\bf\s+([^}]*)\}", r"\1", s)
    s = s.replace("\\quad", "").replace("\\_", "_").replace("~", " ")
    return " ".join(s.split())


def paper_table2():
    """(methods, {sequence: {method: (translation or None, rotation)}}, sequence order) from the tex."""
    if not PAPER.exists():
        pytest.skip(f"{PAPER} not present")
    tex = PAPER.read_text()
    at = tex.index("\\label{table:delta_pose_error}")
    body = tex[at:tex.index("\\bottomrule", at)]
    head, rows = body.split("\\midrule")
    head_line = next(x for x in head.splitlines() if "Sequence" in x and "&" in x)
    methods = [_cell_text(c) for c in head_line.rstrip().rstrip("\\").split("&")][1:]
    table, order = {}, []
    for line in rows.splitlines():
        if "&" not in line:
            continue
        cells = [_cell_text(c) for c in line.strip().rstrip("\\").split("&")]
        seq, vals = cells[0], cells[1:]
        assert len(vals) == len(methods), line
        row = {}
        for m, v in zip(methods, vals):
            t, r = (x.strip() for x in v.split("/"))
            row[m] = (None if t == "-" else float(t), float(r))
        table[seq] = row
        order.append(seq)
    return methods, table, order


def test_parser_reads_the_whole_table():
    methods, table, order = paper_table2()
    assert len(methods) == 5 and len(order) == 6
    assert table["MH_02_easy"]["Tr."] == (0.0108, 0.0093)  # a spot check of the parser itself


def test_quoted_table2_matches_the_paper():
    methods, table, order = paper_table2()
    assert report.PAPER_TABLE2_METHODS == methods
    assert report.PAPER_TABLE2_SEQUENCES == order
    assert set(report.PAPER_TABLE2) == set(order)
    for seq in order:
        assert set(report.PAPER_TABLE2[seq]) == set(methods), seq
        for m in methods:
            assert report.PAPER_TABLE2[seq][m] == table[seq][m], (seq, m)


def test_quoted_rows_are_marked_and_match_the_paper():
    methods, table, order = paper_table2()
    rows = report.quoted_rows()
    assert len(rows) == len(methods) * len(order)
    for r in rows:
        assert r["source"].startswith("quoted") and "not measured here" in r["source"]
        assert r["dataset"] == "EuRoC" and r["n_imu_samples"] == 10
        assert (r["trans_m"], r["rot_rad"]) == table[r["sequence"]][r["method"]]
    assert {(r["sequence"], r["method"]) for r in rows} == {(s, m) for s in order for m in methods}


def test_a_run_on_another_dataset_quotes_no_euroc_table():
    """The paper's Table II is EuRoC's: a TUM-VI run's report says so instead of quoting it (it quoted it)."""
    tumvi = {"roots": [{"path": "tum-vi/dataset-room1_512_16", "format": "tum-vi"}]}
    euroc = {"roots": [{"path": "euroc/MH_01_easy", "format": "euroc"}]}
    assert report.quoted_rows(tumvi) == [] and len(report.quoted_rows(euroc)) == len(report.quoted_rows())
    text = report.quoted_section(tumvi)
    assert "(quoted)" not in text and "quotes EuRoC flights; this run's recordings are tum-vi" in text
    assert report.quoted_section(euroc) == report.quoted_section()


def test_quoted_section_prints_the_paper_numbers():
    methods, table, order = paper_table2()
    text = report.quoted_section()
    assert "NOT measured here" in text and "Quoted" in text
    assert "table:delta_pose_error" in text
    lines = {ln.split("|")[1].strip(): ln for ln in text.splitlines() if ln.startswith("| ") and "(quoted)" in ln}
    assert len(lines) == len(order)
    for seq in order:
        ln = lines[f"{seq.replace('_', chr(92) + '_')} (quoted)"]
        cells = [c.strip() for c in ln.strip().strip("|").split("|")][1:]
        assert len(cells) == len(methods)
        for m, c in zip(methods, cells):
            t, r = table[seq][m]
            assert c == f"{'-' if t is None else f'{t:.4f}'} / {r:.4f}", (seq, m)
    # no quoted AirIMU number is invented
    assert "AirIMU" in text and "could NOT be retrieved" in text


# ---------------------------------------------------------------------------------------------
# tables and summary from a hand-made result

METHODS = ["raw", "gyro-denoise", "end-to-end", "ground truth (noise floor)", "proposed (fit run)"]
SEQS = ["SEQ_A", "SEQ_B"]
HORIZONS = [10, 50]
BY_S = {0.5: 100, 1.0: 200, 2.0: 400, 0.05: 10, 5.0: 1000}


def _value(m, v, s, n, key):
    """A distinct, recognisable number per cell."""
    base = {"trans_m": 1.0, "rot_rad": 2.0, "vel_mps": 3.0}[key]
    return base * (1 + METHODS.index(m)) * (1 + SEQS.index(s)) * n * (0.5 if v == "bias_removed" else 1.0) * 1e-3


def make_result(tmp: Path = Path("/nonexistent")):
    rows = []
    for m in METHODS:
        for v in report.VARIANTS:
            for s in SEQS:
                for n in sorted(set(HORIZONS) | set(BY_S.values())):
                    rot = _value(m, v, s, n, "rot_rad")
                    rows.append({"method": m, "variant": v, "sequence": s, "n": n, "horizon_s": n / 200.0,
                                 "rot_rad": rot, "rot_deg": math.degrees(rot),
                                 "trans_m": float("nan") if m == "gyro-denoise" else _value(m, v, s, n, "trans_m"),
                                 "vel_mps": float("nan") if m in ("gyro-denoise", "end-to-end") else _value(m, v, s, n, "vel_mps"),
                                 "windows": 7})
    seg = {"name": "x", "samples": 100, "t0_ns": 0, "t1_ns": 1, "duration_s": 12.5, "used": True}
    return {
        "config_name": "unit", "config_path": None, "base_path": None,
        "eval": {"horizons": HORIZONS, "airimu_s": [0.5, 1.0, 2.0], "curve_min_s": 0.05, "curve_max_s": 5.0,
                 "curve_count": 2, "stride": 10, "startup_bias_s": 10.0, "noise_floor": "auto"},
        "stride": 10, "startup_bias_s": 10.0,
        "fit_settings": {"window": 200, "steps": 1}, "seed": 0,
        "methods": METHODS, "requested": METHODS[:3], "skipped": ["airimu-style"],
        "records": {"raw": {"status": "fitted", "fit_s": 0.0, "eval_s": 0.1, "file": None},
                    "end-to-end": {"status": "reused", "file": str(tmp / "e.pt")}},
        "split": {"train": [{"entry": "TR_1", "recording": "TR_1", "segments": [seg]}], "val": [],
                  "test": [{"entry": s, "recording": s, "segments": [seg]} for s in SEQS]},
        "test_sequences": SEQS, "test_segments": [],
        "ground_truth": {s: "pose-only (velocity derived)" for s in SEQS},
        "rates_hz": {s: 200.0 for s in SEQS},
        "horizons_by_s": {s: dict(BY_S) for s in SEQS},
        "curve_s": [0.05, 5.0],
        "rows": rows,
        "biases": [{"method": m, "segment": s, "recording": s, "fitted_on": "raw input",
                    "gyro_bias_x": 0.001, "gyro_bias_y": 0.0, "gyro_bias_z": -0.002,
                    "acc_bias_x": 0.01, "acc_bias_y": 0.0, "acc_bias_z": 0.0} for m in METHODS for s in SEQS],
        "versions": {"imu_learn": "0", "python": "3"},
        "roots": [{"path": "datasets/x", "format": "euroc", "groundtruth": ""}],
        "gravity": 9.81, "wall_s": 1.5,
    }


def test_relative_pose_table_average_is_the_mean_of_recordings():
    rel = report.relative_pose_table(make_result())
    idx = {(r["method"], r["variant"], r["sequence"], r["n"]): r for r in rel}
    assert len(rel) == len(METHODS) * 2 * len(HORIZONS) * (len(SEQS) + 1)
    for m in METHODS:
        for v in report.VARIANTS:
            for n in HORIZONS:
                a = idx[(m, v, "average", n)]
                for k in ("rot_rad", "trans_m", "vel_mps"):
                    per = [_value(m, v, s, n, k) for s in SEQS]
                    if (k == "trans_m" and m == "gyro-denoise") or (k == "vel_mps" and m in ("gyro-denoise", "end-to-end")):
                        assert math.isnan(a[k])
                    else:
                        assert a[k] == pytest.approx(sum(per) / len(per), rel=1e-12)
                assert a["windows"] == 14
                assert idx[(m, v, "SEQ_B", n)]["rot_rad"] == pytest.approx(_value(m, v, "SEQ_B", n, "rot_rad"))


def test_airimu_table_uses_the_one_second_horizon():
    air = report.airimu_table(make_result())
    a = next(x for x in air if x["method"] == "raw" and x["variant"] == "open_loop" and x["sequence"] == "SEQ_A")
    assert a["rot_1s_rad"] == pytest.approx(_value("raw", "open_loop", "SEQ_A", 200, "rot_rad"))
    assert a["rot_1s_deg"] == pytest.approx(math.degrees(a["rot_1s_rad"]))
    assert a["pos_0.5s_m"] == pytest.approx(_value("raw", "open_loop", "SEQ_A", 100, "trans_m"))
    assert a["pos_2s_m"] == pytest.approx(_value("raw", "open_loop", "SEQ_A", 400, "trans_m"))
    # keys as they come back from result.json (strings) work too
    r = make_result()
    r["horizons_by_s"] = json.loads(json.dumps(r["horizons_by_s"]))
    assert json.dumps(report.airimu_table(r)) == json.dumps(air)  # (nan != nan, so compare the text)


def test_summary_text_names_every_method_and_variant():
    result = make_result()
    text = report.summary_text(result)
    lines = text.splitlines()
    for m in METHODS:
        mine = [ln for ln in lines if ln.startswith(m + " ")]
        assert len(mine) == 2, (m, lines)
        assert "open loop" in mine[0] and "bias removed" in mine[1]
    raw = next(ln for ln in lines if ln.startswith("raw ") and "open loop" in ln)
    assert f"{_value('raw', 'open_loop', 'SEQ_A', 10, 'trans_m') * 1.5:.4f}" in raw  # mean over SEQ_A, SEQ_B
    gd = next(ln for ln in lines if ln.startswith("gyro-denoise ") and "open loop" in ln)
    assert " - " in gd  # no position for a rotation-only method
    assert "skipped (module not available): airimu-style" in text
    assert "quoted" in text and "0.005 m / 0.0072 rad" in text


def test_write_report_files(tmp_path):
    result = make_result(tmp_path)
    report.write_report(tmp_path, result)
    for name in ("report.md", "relative_pose.csv", "airimu_figures.csv", "integration_error.csv",
                 "errors_all_horizons.csv", "startup_bias.csv", "quoted_paper_table2.csv", "result.json",
                 "integration_error_open_loop.png", "integration_error_bias_removed.png"):
        assert (tmp_path / name).is_file() and (tmp_path / name).stat().st_size > 0, name
    md = (tmp_path / "report.md").read_text()
    for m in METHODS:
        assert report._esc(m) in md, m
    assert "SEQ\\_A" in md and "Quoted figures" in md and "Skipped (module not available): airimu-style" in md
    assert "| raw | fitted |" in md and "| end-to-end | reused |" in md
    with open(tmp_path / "quoted_paper_table2.csv", newline="") as f:
        quoted = list(csv.DictReader(f))
    assert len(quoted) == 30 and all(q["source"].startswith("quoted") for q in quoted)
    with open(tmp_path / "relative_pose.csv", newline="") as f:
        rel = list(csv.DictReader(f))
    assert {r["variant"] for r in rel} == set(report.VARIANTS) and {r["method"] for r in rel} == set(METHODS)
    saved = json.loads((tmp_path / "result.json").read_text())
    assert "rows" not in saved and saved["methods"] == METHODS


def test_floor_table_divides_each_learned_cell_by_the_best_floor_method():
    """raw is the only floor method in make_result: every learned row is its value over raw's, the
    noise floor (a reference) is not judged, and the summary and report.md carry the ratios."""
    result = make_result()
    floor = report.floor_table(result)
    judged = {x["method"] for x in floor}
    assert judged == {"gyro-denoise", "end-to-end", "proposed (fit run)"}
    rel = {(x["method"], x["variant"], x["n"]): x for x in report.relative_pose_table(result) if x["sequence"] == "average"}
    for x in floor:
        assert x["floor"] == "raw"
        assert x["ratio"] == pytest.approx(rel[(x["method"], x["variant"], x["n"])][x["term"]]
                                           / rel[("raw", x["variant"], x["n"])][x["term"]])
    # _value scales with the method's index in METHODS: proposed (index 4) is 5x raw (index 0)
    assert all(x["ratio"] == pytest.approx(5.0) for x in floor if x["method"] == "proposed (fit run)")
    assert not any(x["method"] == "gyro-denoise" and x["term"] == "trans_m" for x in floor)  # no translation
    text = report.summary_text(result)
    assert "learned (and profile:) / best floor (raw)" in text and "5.00 (raw)" in text
    # a better floor method in the run takes over where it is lower
    result["methods"] = ["raw", "timing"] + [m for m in result["methods"] if m != "raw"]
    result["rows"] += [{**x, "method": "timing", "rot_rad": x["rot_rad"] / 2} for x in result["rows"] if x["method"] == "raw"]
    floor = report.floor_table(result)
    assert {x["floor"] for x in floor if x["term"] == "rot_rad"} == {"timing"}
    assert {x["floor"] for x in floor if x["term"] == "trans_m"} == {"raw"}
    assert all(x["ratio"] == pytest.approx(10.0) for x in floor if x["method"] == "proposed (fit run)" and x["term"] == "rot_rad")
    assert "## Learned methods (and shipped profiles) against the floor" in report.markdown(result, report.relative_pose_table(result), [], [], [])


def test_a_learned_model_is_judged_against_the_profiles_in_the_run_too():
    """A model trained on top of a profile: with profile:PATH in the run, the model's floor is the best of
    raw and that profile (it was judged against raw alone, "0.99 (raw)" for a model 1.18x its profile); the
    profile itself is judged against the floor methods only."""
    result = make_result()
    prof = "profile:cal/profile.json"
    result["methods"] = result["methods"] + [prof]
    result["rows"] += [{**x, "method": prof, "rot_rad": x["rot_rad"] / 4, "trans_m": x["trans_m"] / 4}
                       for x in result["rows"] if x["method"] == "raw"]
    floor = report.floor_table(result)
    model = [x for x in floor if x["method"] == "proposed (fit run)"]
    assert model and {x["floor"] for x in model} == {prof}
    assert all(x["ratio"] == pytest.approx(20.0) for x in model)  # 5x raw, raw / 4 the profile
    assert {x["floor"] for x in floor if x["method"] == prof} == {"raw"}
