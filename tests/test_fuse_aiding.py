"""imu_learn.fuse aiding edge cases: the strict Leica reader, aiding outside the IMU's time span,
aiding exactly at / halfway between IMU stamps, outages past the end or removing everything, and a
gap far longer than the configured outages (the estimator coasts through it and recovers)."""
import os
from pathlib import Path

import numpy as np
import pytest

import imu_learn as il
from imu_learn.data.formats.asl import LEICA_FILE, read_leica
from imu_learn.errors import AidingError, AidingOverlapError, AlignmentError, ImuError, ParseError
from imu_learn.fuse.aiding import (
    PositionFixes,
    aiding_gaps,
    apply_outages,
    check_aiding,
    clip_outages,
    epochs,
    leica_fixes,
    simulate_position,
    simulate_relative_pose,
)

LEICA_HEADER = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m]\n"
MS = 1_000_000
DT = 5 * MS  # 200 Hz


def data_root() -> Path:
    return Path(os.environ.get("IMU_LEARN_DATA") or Path(__file__).resolve().parent.parent.parent / "shared" / "data")


def imu_stamps(n=2001, t0=10**18):
    return t0 + np.arange(n, dtype=np.int64) * DT


def leica_csv(tmp_path, body, header=LEICA_HEADER, name="data.csv"):
    f = tmp_path / name
    f.write_text(header + body)
    return f


# --------------------------------------------------------------------------------------------
# the Leica reader (strict parsing in the Rust core)


def test_leica_reader_reads_a_sequence_folder_and_its_lever_arm(tmp_path):
    d = tmp_path / "seq" / LEICA_FILE.parent
    d.mkdir(parents=True)
    (d / "data.csv").write_text(LEICA_HEADER + "1000,1.0,2.0,3.0\n2000,1.5,2.5,3.5\n")
    t, p, lever = read_leica(tmp_path / "seq")
    assert t.dtype == np.int64 and list(t) == [1000, 2000] and p.tolist() == [[1.0, 2.0, 3.0], [1.5, 2.5, 3.5]]
    assert lever.tolist() == [0.0, 0.0, 0.0]  # no sensor.yaml: zeros
    (d / "sensor.yaml").write_text("sensor_type: position\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, 0.1,\n"
                                   "  0.0, 1.0, 0.0, -0.2,\n  0.0, 0.0, 1.0, 0.3,\n  0.0, 0.0, 0.0, 1.0]\n")
    assert read_leica(d / "data.csv")[2].tolist() == [0.1, -0.2, 0.3]


def test_a_missing_leica_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError) as e:
        read_leica(tmp_path)
    assert e.value.filename == str(tmp_path / LEICA_FILE)


@pytest.mark.parametrize("body, cls, line, column, field, words", [
    ("1000,1.0,2.0,3.0\n2000,1.5,x,3.5\n", il.NotNumericError, 3, 3, "p_RS_R_y", "not a number"),
    ("1000,1.0,2.0,3.0\n2000,1.5,,3.5\n", il.NotNumericError, 3, 3, "p_RS_R_y", "not a number"),
    ("1000,1.0,2.0,3.0\n2000,1.5,2.5\n", il.ColumnCountError, 3, None, None, "expected 4 columns, found 3"),
    ("1000,1.0,2.0,3.0,4.0\n", il.ColumnCountError, 2, None, None, "expected 4 columns, found 5"),
    ("1000,1.0,2.0,3.0\n2000,nan,2.5,3.5\n", il.NonFiniteError, 3, 2, "p_RS_R_x", "not finite"),
    ("1000,1.0,2.0,3.0\n2000,1.0,2.0,-inf\n", il.NonFiniteError, 3, 4, "p_RS_R_z", "not finite"),
    ("1000,1.0,2.0,3.0\n1000,1.0,2.0,3.0\n", il.TimestampError, 3, 1, "timestamp", "duplicates"),
    ("1000,1.0,2.0,3.0\n3000,1.0,2.0,3.0\n2000,1.0,2.0,3.0\n", il.TimestampError, 4, 1, "timestamp", "earlier"),
    ("1000,1.0,2.0,3.0\n2.0e3,1.0,2.0,3.0\n", il.FloatTimestampError, 3, 1, "timestamp", "float notation"),
])
def test_a_malformed_leica_row_names_file_line_column_and_field(tmp_path, body, cls, line, column, field, words):
    f = leica_csv(tmp_path, body)
    with pytest.raises(cls) as e:
        read_leica(f)
    err = e.value
    assert isinstance(err, ParseError) and isinstance(err, ImuError)
    assert err.path == str(f) and err.line == line and err.column == column
    assert (err.field is None) if field is None else (field in err.field)
    prefix = f"{f}:{line}" + ("" if column is None else f":{column}")
    assert str(err).startswith(prefix + ":") and words in str(err)


def test_a_leica_file_with_another_header_is_a_header_error(tmp_path):
    f = leica_csv(tmp_path, "1000,1,2,3,1,0,0,0\n", header="#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],"
                  "q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n")
    with pytest.raises(il.HeaderError) as e:
        read_leica(f)
    assert e.value.line == 1 and str(f) in str(e.value) and "p_RS_R_z" in str(e.value)


def test_a_header_only_leica_file_reads_empty_and_has_no_fixes(tmp_path):
    f = leica_csv(tmp_path, "")
    t, p, _ = read_leica(f)
    assert len(t) == 0 and p.shape == (0, 3)
    with pytest.raises(AidingError, match="no Leica fixes") as e:
        leica_fixes(t, p, np.zeros(3), imu_stamps(), None, 0.01, source=str(f))
    assert e.value.path == str(f) and not isinstance(e.value, AidingOverlapError)


# --------------------------------------------------------------------------------------------
# aiding and the IMU's time span


@pytest.mark.parametrize("shift_s", [-100.0, 100.0])
def test_leica_fixes_entirely_outside_the_imu_span_are_an_overlap_error(shift_s):
    imu_t = imu_stamps()  # 10 s
    leica_t = imu_t[::10] + int(shift_s * 1e9)
    with pytest.raises(AidingOverlapError) as e:
        leica_fixes(leica_t, np.zeros((len(leica_t), 3)), np.zeros(3), imu_t, None, 0.01, source="/x/leica0/data.csv")
    err, msg = e.value, str(e.value)
    assert isinstance(err, AidingError) and isinstance(err, AlignmentError) and isinstance(err, ValueError)
    assert err.path == "/x/leica0/data.csv" and "Leica MS50" in err.label
    assert msg.startswith(f"/x/leica0/data.csv: lines 2-{len(leica_t) + 1}: ")
    assert f"[{leica_t[0]}, {leica_t[-1]}] ns" in msg and f"[{imu_t[0]}, {imu_t[-1]}] ns" in msg
    assert "time_offset_s" in msg


def test_fixes_outside_the_imu_span_are_dropped_and_counted_not_moved_onto_the_ends():
    imu_t = imu_stamps()
    # 2 and 1 ms before the first sample (within half a period: the old rule moved them onto
    # sample 0), 100 ms before, then the span's own ends, then 1 ms and 1 s after the last sample
    leica_t = np.r_[imu_t[0] - 100 * MS, imu_t[0] - 2 * MS, imu_t[0] - 1 * MS, imu_t[0], imu_t[1000] + 1 * MS,
                    imu_t[-1], imu_t[-1] + 1 * MS, imu_t[-1] + 1000 * MS]
    p = np.arange(len(leica_t) * 3, dtype=float).reshape(-1, 3)
    fixes = leica_fixes(leica_t, p, np.zeros(3), imu_t, None, 0.01, source="f.csv")
    assert fixes.idx.tolist() == [0, 1000, len(imu_t) - 1]
    assert fixes.p.tolist() == p[[3, 4, 5]].tolist()
    assert fixes.dropped_outside == 5 and fixes.dropped_unmatched == 0 and fixes.source == "f.csv"


def test_fixes_in_an_imu_gap_or_sharing_a_sample_are_dropped_and_counted():
    imu_t = np.r_[imu_stamps(1000), imu_stamps(1000)[-1] + 40 * MS + np.arange(1000, dtype=np.int64) * DT]
    gap_start = imu_t[999]
    leica_t = np.r_[imu_t[10], imu_t[10] + 1 * MS, gap_start + 20 * MS, imu_t[1500]]  # 2nd shares sample 10
    fixes = leica_fixes(leica_t, np.zeros((4, 3)), np.zeros(3), imu_t, None, 0.01)
    assert fixes.idx.tolist() == [10, 1500]
    assert fixes.dropped_unmatched == 2 and fixes.dropped_outside == 0
    # thinning to a rate is not counted as dropped
    thinned = leica_fixes(imu_t[::10], np.zeros((200, 3)), np.zeros(3), imu_t, 1.0, 0.01)
    assert len(thinned) < 200 and thinned.dropped_unmatched == 0 and thinned.dropped_outside == 0


def test_leica_fixes_reject_a_bad_rate_and_mismatched_arrays():
    imu_t = imu_stamps()
    with pytest.raises(il.InvalidInputError, match="rate"):
        leica_fixes(imu_t[:5], np.zeros((5, 3)), np.zeros(3), imu_t, 0.0, 0.01)
    with pytest.raises(il.InvalidInputError, match=r"\(N, 3\)"):
        leica_fixes(imu_t[:5], np.zeros((4, 3)), np.zeros(3), imu_t, None, 0.01)


def test_real_leica_fixes_drop_exactly_those_outside_the_imu_segment():
    root = data_root() / "euroc" / "MH_01_easy"
    if not (root / LEICA_FILE).exists():
        pytest.skip(f"{root / LEICA_FILE} not present")
    from imu_learn import AlignOptions, load_recording
    seq = max(load_recording(root, "euroc", options=AlignOptions(max_gap_s=0.05)).segments, key=len)
    t, p, lever = read_leica(root)
    fixes = leica_fixes(t, p, lever, seq.t_ns, None, 0.01, source=str(root / LEICA_FILE))
    outside = int(np.sum((t < seq.t_ns[0]) | (t > seq.t_ns[-1])))
    assert fixes.dropped_outside == outside > 0  # the tracker runs before and after the IMU segment
    assert len(fixes) + fixes.dropped_outside + fixes.dropped_unmatched == len(t)
    # every fix inside the segment is kept (MH_01's segment has no IMU gap), tied to a sample
    # within half a sample period of it
    inside = t[(t >= seq.t_ns[0]) & (t <= seq.t_ns[-1])]
    assert fixes.dropped_unmatched == 0 and len(fixes) == len(inside)
    half = int(np.median(np.diff(seq.t_ns))) // 2
    assert np.abs(seq.t_ns[fixes.idx] - inside).max() <= half


# --------------------------------------------------------------------------------------------
# aiding exactly at an IMU stamp, and the tie rule


def test_leica_fixes_exactly_at_imu_stamps_map_to_those_samples():
    imu_t = imu_stamps() + np.random.default_rng(0).integers(-50_000, 50_000, 2001)  # jittered stamps
    imu_t = np.sort(imu_t)
    at = np.array([0, 7, 500, 1999, 2000])
    fixes = leica_fixes(imu_t[at], np.arange(15.0).reshape(5, 3), np.zeros(3), imu_t, None, 0.01)
    assert fixes.idx.tolist() == at.tolist() and fixes.p.tolist() == np.arange(15.0).reshape(5, 3).tolist()


def test_a_leica_fix_exactly_halfway_goes_to_the_earlier_sample():
    imu_t = imu_stamps()
    halfway = imu_t[100] + DT // 2
    assert leica_fixes([halfway], np.zeros((1, 3)), np.zeros(3), imu_t, None, 0.01).idx.tolist() == [100]
    assert leica_fixes([halfway + 1], np.zeros((1, 3)), np.zeros(3), imu_t, None, 0.01).idx.tolist() == [101]
    assert leica_fixes([halfway - 1], np.zeros((1, 3)), np.zeros(3), imu_t, None, 0.01).idx.tolist() == [100]


def test_simulated_epochs_at_imu_stamps_are_those_samples_and_halfway_takes_the_later():
    s = 1_000_000_000
    t = np.array([0, 900, 1100, 2000, 2600], dtype=np.int64) * (s // 1000)
    # grid 0, 1, 2 s: 0 and 2 s are stamps; 1 s lies exactly halfway between 0.9 and 1.1 s
    assert epochs(t, 1.0).tolist() == [0, 2, 3]
    p = np.arange(15.0).reshape(5, 3)
    fixes = simulate_position(t, p, 1.0, 0.0, np.random.default_rng(0))
    assert fixes.idx.tolist() == [0, 2, 3] and fixes.p.tolist() == p[[0, 2, 3]].tolist()
    # on an exact 200 Hz clock, a 1 Hz grid lands on every 200th sample, first and last included
    imu_t = imu_stamps()
    assert epochs(imu_t, 1.0).tolist() == list(range(0, 2001, 200))


def test_an_aiding_rate_above_the_imu_rate_ties_each_sample_once():
    imu_t = imu_stamps(201)
    assert epochs(imu_t, 1000.0).tolist() == list(range(201))
    with pytest.raises(il.InvalidInputError, match="rate"):
        epochs(imu_t, 0.0)


def test_keyframes_include_every_aiding_sample_and_both_ends():
    pytest.importorskip("gtsam")
    from imu_learn.fuse.graph import keyframes

    imu_t = imu_stamps()
    fixes = PositionFixes(np.array([0, 3, 1001, 2000]), np.zeros((4, 3)), 0.1, np.zeros(3), "x")
    kf = keyframes(imu_t, 10.0, [fixes])
    assert set(fixes.idx) <= set(kf.tolist()) and kf[0] == 0 and kf[-1] == 2000
    assert set(kf.tolist()) == set(range(0, 2001, 20)) | {3, 1001}
    fast = leica_fixes(imu_t[::10], np.zeros((201, 3)), np.zeros(3), imu_t, None, 0.01)  # 20 Hz over 10 Hz
    assert set(keyframes(imu_t, 10.0, [fast]).tolist()) == set(range(0, 2001, 10))


# --------------------------------------------------------------------------------------------
# outages


def test_an_outage_past_the_end_is_clipped_to_the_recording():
    imu_t = imu_stamps()  # 10 s
    fixes = simulate_position(imu_t, np.zeros((len(imu_t), 3)), 1.0, 0.0, np.random.default_rng(0))
    assert fixes.idx.tolist() == list(range(0, 2001, 200))  # 0 .. 10 s, the last sample included
    kept = apply_outages(fixes, imu_t, [(7.0, 100.0)])
    assert kept.idx.tolist() == list(range(0, 1201, 200)) and kept.dropped_outage == 4  # 7, 8, 9 and 10 s
    assert clip_outages(imu_t, [(7.0, 100.0)]) == [(7.0, pytest.approx(3.0))]
    # a window before the start is clipped at 0; one after the end acts on nothing and is left out
    assert clip_outages(imu_t, [(-5.0, 6.0), (20.0, 5.0)]) == [(0.0, pytest.approx(1.0))]
    after = apply_outages(fixes, imu_t, [(20.0, 5.0)])
    assert after.idx.tolist() == fixes.idx.tolist() and after.dropped_outage == 0


def test_outages_that_remove_every_measurement_name_the_scenario():
    imu_t = imu_stamps()
    p = np.zeros((len(imu_t), 3))
    fixes = simulate_position(imu_t, p, 1.0, 0.1, np.random.default_rng(0))
    assert check_aiding(apply_outages(fixes, imu_t, [(3.0, 2.0)]), "MH_01|gnss") is not None
    with pytest.raises(AidingError) as e:
        check_aiding(apply_outages(fixes, imu_t, [(0.0, 5.0), (5.0, 100.0)]), "MH_01_easy|gnss_outages")
    msg = str(e.value)
    assert msg.startswith("MH_01_easy|gnss_outages: no aiding measurement left")
    assert f"dropped {len(fixes)} inside the outages" in msg and "simulated position 1 Hz" in msg
    assert e.value.label == "MH_01_easy|gnss_outages" and e.value.path is None
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(imu_t), 1))
    rel = simulate_relative_pose(imu_t, p, q, 2.0, 0.1, 0.01, np.random.default_rng(0))
    with pytest.raises(AidingError, match=f"vo: no aiding .*dropped {len(rel)} inside the outages"):
        check_aiding(apply_outages(rel, imu_t, [(-1.0, 20.0)]), "vo")


def test_a_leica_scenario_emptied_by_outages_names_its_file_and_what_was_dropped():
    imu_t = imu_stamps()
    leica_t = np.r_[imu_t[0] - 1 * MS, imu_t[::100]]
    fixes = leica_fixes(leica_t, np.zeros((len(leica_t), 3)), np.zeros(3), imu_t, None, 0.01, source="l.csv")
    with pytest.raises(AidingError) as e:
        check_aiding(apply_outages(fixes, imu_t, [(0.0, 11.0)]), "MH_01_easy|leica")
    assert e.value.path == "l.csv" and "l.csv" in str(e.value)
    assert "dropped 21 inside the outages, 1 outside the IMU's time span" in str(e.value)


# --------------------------------------------------------------------------------------------
# gaps, and coasting through one far longer than the configured outages


def test_aiding_gaps_report_the_longest_stretch_without_aiding():
    imu_t = imu_stamps(5001)  # 25 s
    idx = np.array([0, 200, 400, 4400, 4600])  # 0, 1, 2 s, then 22, 23 s
    g = aiding_gaps(PositionFixes(idx, np.zeros((5, 3)), 0.1, np.zeros(3), "x"), imu_t)
    assert g == pytest.approx({"longest_s": 20.0, "longest_start_s": 2.0, "before_first_s": 0.0, "after_last_s": 2.0})
    # relative poses: an outage that drops the poses touching 4..6 s leaves 3 s to 7 s unaided
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(imu_t), 1))
    rel = apply_outages(simulate_relative_pose(imu_t, np.zeros((len(imu_t), 3)), q, 1.0, 0.0, 0.0,
                                               np.random.default_rng(0)), imu_t, [(4.0, 2.5)])
    assert aiding_gaps(rel, imu_t)["longest_s"] == pytest.approx(4.0)
    assert aiding_gaps(rel, imu_t)["longest_start_s"] == pytest.approx(3.0)
    none = aiding_gaps(PositionFixes(np.zeros(0, np.int64), np.zeros((0, 3)), 0.1, np.zeros(3), "x"), imu_t)
    assert none["longest_s"] is None and none["before_first_s"] == pytest.approx(25.0)
    one = aiding_gaps(PositionFixes(np.array([1000]), np.zeros((1, 3)), 0.1, np.zeros(3), "x"), imu_t)
    assert one == pytest.approx({"longest_s": None, "longest_start_s": None, "before_first_s": 5.0,
                                 "after_last_s": 20.0})


def coast_through_a_gap(gap_s, iterations=1, seed=3, sigma=0.02, resolve_after_s=2.0):
    """The closed-form spin-and-climb of imu_learn.data.synthetic with a biased, noisy IMU and position
    fixes at 1 Hz for the first 2 s and the last 3 s only: ``gap_s`` seconds without aiding."""
    from imu_learn.data.synthetic import spin_and_climb
    from imu_learn.fuse.graph import fuse
    from imu_learn.fuse.settings import FusionSettings

    rng = np.random.default_rng(seed)
    dur = gap_s + 5
    t, gyro, acc, p, R = spin_and_climb(n=int(dur * 200) + 1)
    gyro = gyro + 0.005 + rng.normal(0, 0.002, gyro.shape)
    acc = acc + 0.05 + rng.normal(0, 0.02, acc.shape)
    idx = np.round(np.r_[0.0, 1.0, 2.0, np.arange(gap_s + 2, dur + 1e-9, 1.0)] * 200).astype(np.int64)
    fixes = PositionFixes(idx, p[idx] + rng.normal(0, sigma, (len(idx), 3)), sigma, np.zeros(3), "start and end")
    res = fuse(t, gyro, acc, (R[0], p[0], np.zeros(3)), [fixes],
               FusionSettings(iterations=iterations, resolve_after_s=resolve_after_s))
    kf = res.kf_idx
    at = {int(s): int(np.searchsorted(kf, s)) for s in idx}
    err_c = np.linalg.norm(res.causal_p - p[kf], axis=1)
    err_s = np.linalg.norm(res.smoothed_p - p[kf], axis=1)
    return t, fixes, res, idx, at, err_c, err_s


# 40 s is longer than every outage configs/fuse_euroc.toml configures (the longest: 30 s)
@pytest.mark.parametrize("gap_s", [20.0, 40.0])
def test_the_estimator_coasts_through_a_long_gap_and_recovers_at_the_fixes_after_it(gap_s):
    pytest.importorskip("gtsam")
    t, fixes, res, idx, at, err_c, err_s = coast_through_a_gap(gap_s)
    assert aiding_gaps(fixes, t)["longest_s"] == pytest.approx(gap_s)
    for a in (res.causal_p, res.causal_R, res.smoothed_p, res.smoothed_R, res.smoothed_v, res.smoothed_bias):
        assert np.all(np.isfinite(a))
    after = [at[int(s)] for s in idx[3:]]  # keyframes of the fixes after the gap
    coasted = err_c[after[0] - 1]  # the last IMU-only estimate before the first fix after the gap
    assert coasted > 50 * fixes.sigma_m  # the IMU really did drift inside the gap
    assert err_c[after[0]] < coasted  # the first fix pulls the estimate towards it ...
    # ... and from the second fix on, the causal estimate is back at the fixes' noise level
    assert err_c[after[1]:].max() < 7.5 * fixes.sigma_m, err_c[after[1]:]
    # the smoothed trajectory is at that level at every fix, and bounded inside the gap
    assert err_s[[at[int(s)] for s in idx]].max() < 7.5 * fixes.sigma_m
    assert err_s.max() < 0.02 * coasted


@pytest.mark.parametrize("seed", [0, 4])
def test_the_first_fix_after_a_long_gap_settles_the_causal_estimate(seed):
    """After a 40 s coast the graph so far is re-solved in batch at the first fix; with Gauss-Newton
    steps alone (no re-solve) that fix's live estimate stays far from it (measured: 240-270 m)."""
    pytest.importorskip("gtsam")
    _t, fixes, res, idx, at, err_c, _err_s = coast_through_a_gap(40.0, seed=seed)
    assert res.counts["resolves_after_coast"] == 1
    assert err_c[at[int(idx[3])]] < 7.5 * fixes.sigma_m
    _t, fixes, res, idx, at, err_c, _err_s = coast_through_a_gap(40.0, seed=seed, iterations=3, resolve_after_s=np.inf)
    assert res.counts["resolves_after_coast"] == 0
    assert err_c[at[int(idx[3])]] > 100 * fixes.sigma_m


# --------------------------------------------------------------------------------------------
# aiding trajectories: read by the core's one trajectory reader (the TUM ground-truth reader's
# rules), through imu_learn.fuse.aiding.tum


def test_aiding_tum_skips_comments_and_blank_lines_like_the_core_ground_truth_reader(tmp_path):
    from imu_learn import _imu_core as core
    from imu_learn.fuse.aiding.tum import read_tum

    f = tmp_path / "a.tum"
    f.write_text("# t tx ty tz qx qy qz qw\n\n1.0 0 0 0 0 0 0 1\n\n   \n  # indented\n2.0 1 2 3 0 0 0 1\n"
                 "3.0 2 2 3 0 0 0.6 0.8  # a comment after the row\n\n")
    tr = read_tum(f)
    assert tr.t_ns.dtype == np.int64 and tr.t_ns.tolist() == [10**9, 2 * 10**9, 3 * 10**9]
    assert tr.lines.tolist() == [3, 7, 8] and tr.path == str(f)
    assert tr.p.tolist() == [[0, 0, 0], [1, 2, 3], [2, 2, 3]]
    assert np.allclose(tr.q_xyzw[2], [0, 0, 0.6, 0.8])
    # the ground-truth reader (no comment after a row there) agrees on the same rows
    f.write_text(f.read_text().replace("  # a comment after the row", ""))
    gt = core.read_tum(str(f))
    assert gt["t_ns"].tolist() == read_tum(f).t_ns.tolist()
    assert np.allclose(gt["q_wxyz"][:, [1, 2, 3, 0]], read_tum(f).q_xyzw)


def test_aiding_four_columns_are_positions_only_where_allowed(tmp_path):
    from imu_learn.fuse.aiding.tum import read_trajectory, read_tum

    f = tmp_path / "p.tum"
    f.write_text("# t x y z\n1.0 0 0 0\n\n2.0 1 2 3\n")
    tr = read_tum(f, need_orientation=False)
    assert tr.q_xyzw is None and tr.p.tolist() == [[0, 0, 0], [1, 2, 3]] and tr.lines.tolist() == [2, 4]
    with pytest.raises(il.ColumnCountError) as e:
        read_tum(f)
    assert (e.value.path, e.value.line, e.value.column) == (str(f), 2, None)
    assert str(e.value) == f"{f}:2: 4 columns, expected 8 (t tx ty tz qx qy qz qw)"
    c = tmp_path / "p.csv"
    c.write_text("t,x,y,z\n1.0,0,0,0\n2.0,1,2,3\n")
    assert read_trajectory(c, "csv", need_orientation=False).p.tolist() == tr.p.tolist()


def test_aiding_stamps_are_exact_and_round_half_to_even_past_nine_decimals(tmp_path):
    from imu_learn.fuse.aiding.tum import read_tum, seconds_to_ns

    f = tmp_path / "s.tum"
    stamps = ["1403636579.763556", "1403636579.7635560015", "1403636579.7635560025000001", "1403636579.7635560045"]
    f.write_text("".join(f"{t} 0 0 0 0 0 0 1\n" for t in stamps))
    base = 1403636579763556000
    assert read_tum(f).t_ns.tolist() == [base, base + 2, base + 3, base + 4]
    assert seconds_to_ns("1403636579.763556") == 1403636579763556000
    assert seconds_to_ns("1.0000000005") == 10**9 and seconds_to_ns("1.0000000015") == 10**9 + 2
    assert seconds_to_ns("-1.5") == -1_500_000_000 and seconds_to_ns("1.5e-3") == 1_500_000
    with pytest.raises(ValueError):
        seconds_to_ns("12:00")
    with pytest.raises(OverflowError):
        seconds_to_ns("nan")


def test_aiding_quaternion_far_from_unit_length_names_its_line(tmp_path):
    from imu_learn.errors import AidingQuaternionError
    from imu_learn.fuse.aiding.tum import read_trajectory

    f = tmp_path / "q.csv"
    f.write_text("#timestamp,px,py,pz,qw,qx,qy,qz\n1000000000,0,0,0,1,0,0,0\n\n2000000000,0,0,0,2,0,0,0\n")
    with pytest.raises(AidingQuaternionError) as e:
        read_trajectory(f, "asl")
    assert (e.value.path, e.value.line, e.value.column, e.value.field) == (str(f), 4, 5, "qw")


@pytest.mark.parametrize("text, layout, cls, line, column, message", [
    ("1.0 0 0 0 0 0 0 1\n\nx 0 0 0 0 0 0 1\n", "tum", il.NotNumericError, 3, 1,
     "column 1 (t): 'x' is not a number of seconds"),
    ("1.0 0 0 0 0 0 0 1\n1.1 0 0 0 q 0 0 1\n", "tum", il.NotNumericError, 2, 5, "column 5 (qx): 'q' is not a number"),
    ("1.0 0 0 0 0 0 0 1\n1.1 0 inf 0 0 0 0 1\n", "tum", il.NonFiniteError, 2, 3, "column 3 (ty): 'inf' is not finite"),
    ("1.0 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n", "tum", il.TimestampError, 2, 1,
     "stamp 0.500000000 s is before the stamp before it (1.000000000 s): stamps must increase"),
    ("1,0,0,0,1,0,0,0\n2.0e3,0,0,0,1,0,0,0\n", "asl", il.FloatTimestampError, 2, 1,
     "column 1 (timestamp): '2.0e3' is not an integer ns stamp"),
    ("t,x,y,z,qx,qy,qz,qw\n1.0,0,0,0,0,0,0,1\n", "csv", il.TooFewRowsError, 2, None,
     "1 trajectory row(s); at least 2 needed"),
])
def test_aiding_errors_from_the_core_reader_keep_their_wording(tmp_path, text, layout, cls, line, column, message):
    from imu_learn.fuse.aiding.tum import read_trajectory

    f = tmp_path / "bad.txt"
    f.write_text(text)
    with pytest.raises(cls) as e:
        read_trajectory(f, layout)
    assert (e.value.path, e.value.line, e.value.column) == (str(f), line, column)
    assert str(e.value).startswith(f"{f}:{line}: " if column else f"{f}: ") and str(e.value).endswith(message)


def test_a_fetch_motion_capture_file_is_aiding_and_ground_truth(tmp_path):
    """Fetch's mocap0/data.csv (``# timestamp, x, y, z, qw, qx, qy, qz``, ns in float notation) is ASL aiding,
    and navigate's --groundtruth reads it by its header with the Fetch reader (was a HeaderError)."""
    from imu_learn.fuse.aiding.detect import detect
    from imu_learn.fuse.navigate import NavigateOptions, Sources, read_aiding
    from imu_learn.fuse.score import read_truth

    f = tmp_path / "data.csv"
    t0 = 1691117483314093312
    rows = [f"{float(t0 + k * 10_000_000):.18e},{0.01 * k:.6f},0.5,0.36,1.0,0.0,0.0,0.0" for k in range(50)]
    f.write_text("# timestamp, x, y, z, qw, qx, qy, qz\n" + "\n".join(rows) + "\n")
    assert detect(f) == "asl"
    gt = read_truth(f)
    assert len(gt.t_ns) == 50 and gt.p[10, 0] == pytest.approx(0.1)
    traj = read_aiding(Sources(input=tmp_path, aiding=f), NavigateOptions(aiding_format="asl", aiding_kind="pose"))
    assert traj.q_xyzw[0].tolist() == [0.0, 0.0, 0.0, 1.0] and traj.t_ns[1] - traj.t_ns[0] == pytest.approx(1e7, abs=512)
