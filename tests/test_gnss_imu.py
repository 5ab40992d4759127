"""GNSS/IMU: the IMU CSV + RTKLIB time-tag reader (data/formats/gnss_imu.py), the RTKLIB ``.pos``
reader and WGS-84 geodesy (fuse/rtklib.py), the non-holonomic constraint factor (fuse/nhc.py), the
per-fix sigmas in the graph, and the experiment runner (fuse/gnss_run.py) on a synthetic drive."""
from __future__ import annotations

import json
import math
import os
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_learn.data.formats import gnss_imu
from imu_learn.errors import (
    ColumnCountError,
    HeaderError,
    InvalidInputError,
    NonFiniteError,
    NotNumericError,
    SolutionQualityError,
    TimestampError,
    TooFewRowsError,
)
from imu_learn.fuse.aiding import PositionFixes, rtklib
from imu_learn.fuse.factors import nhc

START_S, FRAC = 1752003261, 0.854


def write_tag(path: Path, end_ms: int, start_s: int = START_S, frac: float = FRAC, n: int = 3,
              magic: bytes = b"TIMETAG RTKLIB demo5") -> Path:
    head = magic.ljust(60, b"\0") + struct.pack("<IId", 12345, start_s, frac)
    recs = b"".join(struct.pack("<II", int(end_ms * (i + 1) / n), 100 * i) for i in range(n))
    path.write_bytes(head + recs)
    return path


def write_csv(path: Path, rows, cut_first: str = "", tail: str = "") -> Path:
    text = cut_first + "".join(",".join(f"{v:.3f}" for v in r[:6]) + f",{int(r[6])}\n" for r in rows) + tail
    path.write_text(text)
    return path


def rows_at(counters, acc_g=(0.0, 0.0, 1.0), gyro_dps=(0.0, 0.0, 0.0)):
    return [list(acc_g) + list(gyro_dps) + [c] for c in counters]


# --- IMU CSV and time tag --------------------------------------------------------------------------

def test_reader_units_stamps_first_line_and_delay(tmp_path):
    counters = [1000, 1010, 1020, 1030, 1040]
    rows = rows_at(counters, (0.5, -0.25, 1.0), (90.0, 0.0, -180.0))
    f = write_csv(tmp_path / "imu.csv", rows, cut_first="0.119,0.0\n")  # a cut first line
    write_tag(tmp_path / "imu.csv.tag", end_ms=40)
    log = gnss_imu.read_imu_log(f, delay_s=-0.125)
    # The first line is never trusted: the cut one goes, every complete row stays.
    assert log.skipped_lines == (1,)
    assert len(log.imu.t_ns) == 5
    start_ns = START_S * 10**9 + round(FRAC * 1e9)
    np.testing.assert_array_equal(log.imu.t_ns, start_ns - 125_000_000 + np.arange(5) * 10_000_000)
    np.testing.assert_allclose(log.imu.acc[0], [0.5 * 9.80665, -0.25 * 9.80665, 9.80665])
    np.testing.assert_allclose(log.imu.gyro[0], [math.pi / 2, 0.0, -math.pi])
    assert log.clock_scale == pytest.approx(1.0)
    assert log.rate_hz == pytest.approx(100.0)


def test_reader_maps_counter_linearly_onto_the_tag_span(tmp_path):
    f = write_csv(tmp_path / "imu.csv", rows_at([0, 0, 1000, 2000]))
    write_tag(tmp_path / "imu.csv.tag", end_ms=2002)  # the tag's clock 0.1 % faster
    log = gnss_imu.read_imu_log(f)
    assert log.clock_scale == pytest.approx(2002 / 2000)
    t = log.imu.t_ns - log.tag.start_ns
    np.testing.assert_array_equal(t, [0, 1_001_000_000, 2_002_000_000])


def test_reader_mounting_rotates_both(tmp_path):
    f = write_csv(tmp_path / "imu.csv", rows_at([0, 0, 10, 20], (0.1, 0.2, 1.0), (1.0, 2.0, 3.0)))
    write_tag(tmp_path / "imu.csv.tag", end_ms=20)
    M = gnss_imu.mounting_rotation([180.0, 0.0, 180.0])
    np.testing.assert_allclose(M, np.diag([-1.0, 1.0, -1.0]), atol=1e-12)
    log = gnss_imu.read_imu_log(f, mounting=M)
    np.testing.assert_allclose(log.imu.acc[0], np.array([-0.1, 0.2, -1.0]) * 9.80665)
    np.testing.assert_allclose(log.imu.gyro[0], np.deg2rad([-1.0, 2.0, -3.0]))
    with pytest.raises(InvalidInputError):
        gnss_imu.read_imu_log(f, mounting=np.diag([1.0, 1.0, -1.0]))


def test_mounting_rotation_convention():
    # Yaw 90 deg: the body frame is the IMU frame turned +90 deg about z, so the IMU's x axis is
    # the body's -y axis (a coordinate transformation, Groves' C_imu^body).
    M = gnss_imu.mounting_rotation([0.0, 0.0, 90.0])
    np.testing.assert_allclose(M @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], atol=1e-12)
    # roll then pitch then yaw, each a passive rotation: M = R1(roll) R2(pitch) R3(yaw)
    r, p, y = np.deg2rad([10.0, -6.79, 5.35])
    R1 = np.array([[1, 0, 0], [0, math.cos(r), math.sin(r)], [0, -math.sin(r), math.cos(r)]])
    R2 = np.array([[math.cos(p), 0, -math.sin(p)], [0, 1, 0], [math.sin(p), 0, math.cos(p)]])
    R3 = np.array([[math.cos(y), math.sin(y), 0], [-math.sin(y), math.cos(y), 0], [0, 0, 1]])
    np.testing.assert_allclose(gnss_imu.mounting_rotation([10.0, -6.79, 5.35]), R1 @ R2 @ R3, atol=1e-12)


@pytest.mark.parametrize("tail", ["0.1,0.2,1.0,0.1", "0.1,0.2,1.0,0.1,0.2,0.3,1040"])
def test_reader_drops_a_cut_last_line(tmp_path, tail):
    # no newline at the end: cut while logging, even when it parses
    f = write_csv(tmp_path / "imu.csv", rows_at([1000, 1010, 1020, 1030]), tail=tail)
    write_tag(tmp_path / "imu.csv.tag", end_ms=20)
    log = gnss_imu.read_imu_log(f)
    assert log.skipped_lines == (1, 5)
    assert len(log.imu.t_ns) == 3


def test_a_folder_with_one_log_is_detected_and_one_with_two_names_the_file(tmp_path):
    from imu_learn.data.formats import detect_format, read_imu_source

    d = tmp_path / "drive"
    d.mkdir()
    f = write_csv(d / "imu.csv", rows_at([1000, 1010, 1020, 1030]))
    write_tag(d / "imu.csv.tag", end_ms=20)
    (d / "notes.csv").write_text("a,b\n")  # a CSV without a tag is not a log
    assert detect_format(d) == "gnss-imu" and detect_format(f) == "gnss-imu"
    assert len(read_imu_source(d).t_ns) == 3
    write_csv(d / "imu2.csv", rows_at([1000, 1010, 1020, 1030]))
    write_tag(d / "imu2.csv.tag", end_ms=20)
    with pytest.raises(InvalidInputError, match=r"give it with --format .*gnss-imu.*or a CSV of your own"):
        detect_format(d)


def test_a_log_without_ground_truth_names_the_fixes_beside_it(tmp_path):
    """calibrate --input on a log's folder without --groundtruth: the RTKLIB .pos beside it is named as the
    positions reference to pass (before: "pass one explicitly (TUM or ASL)", which a .pos is neither)."""
    d = tmp_path / "walk"
    d.mkdir()
    write_csv(d / "imu.csv", rows_at([1000, 1010, 1020, 1030]))
    write_tag(d / "imu.csv.tag", end_ms=20)
    with pytest.raises(InvalidInputError, match=r"an RTKLIB \.pos of positions"):
        gnss_imu.read_recording(d)
    (d / "rover.pos").write_text("% header\n")
    with pytest.raises(InvalidInputError, match=r"positions reference: --groundtruth .*rover\.pos"):
        gnss_imu.read_recording(d)


def test_reader_last_line_with_newline_is_kept_when_whole(tmp_path):
    f = write_csv(tmp_path / "imu.csv", rows_at([1000, 1010, 1020, 1030]))
    write_tag(tmp_path / "imu.csv.tag", end_ms=20)
    assert gnss_imu.read_imu_log(f).skipped_lines == (1,)


@pytest.mark.parametrize("bad, err, line, field", [
    ("0.1,0.2,1.0,0.1,abc,0.3,1020", NotNumericError, 3, "gy"),
    ("0.1,0.2,1.0,0.1,0.2,1020", ColumnCountError, 3, None),
    ("0.1,nan,1.0,0.1,0.2,0.3,1020", NonFiniteError, 3, "ay"),
    ("0.1,0.2,1.0,0.1,0.2,0.3,1005", TimestampError, 3, "t_ms"),
    ("", ColumnCountError, 3, None),  # a blank line inside the data
])
def test_reader_malformed_line_names_line_and_field(tmp_path, bad, err, line, field):
    lines = ["0.1,0.2,1.0,0.1,0.2,0.3,1000", "0.1,0.2,1.0,0.1,0.2,0.3,1010", bad,
             "0.1,0.2,1.0,0.1,0.2,0.3,1030", "0.1,0.2,1.0,0.1,0.2,0.3,1040"]
    f = tmp_path / "imu.csv"
    f.write_text("\n".join(lines) + "\n")
    write_tag(tmp_path / "imu.csv.tag", end_ms=30)
    with pytest.raises(err) as e:
        gnss_imu.read_imu_log(f)
    assert e.value.line == line and e.value.field == field and e.value.path == str(f)
    assert f"{f}:{line}:" in str(e.value)


def test_reader_too_few_rows_and_foreign_tag(tmp_path):
    f = write_csv(tmp_path / "imu.csv", rows_at([1000, 1010]))
    write_tag(tmp_path / "imu.csv.tag", end_ms=10)
    with pytest.raises(TooFewRowsError):
        gnss_imu.read_imu_log(f)
    f = write_csv(tmp_path / "imu.csv", rows_at([0, 0, 1000, 2000]))
    write_tag(tmp_path / "imu.csv.tag", end_ms=5000)  # another log's tag: 2.5x the span
    with pytest.raises(InvalidInputError, match="tag"):
        gnss_imu.read_imu_log(f)


def test_tag_parse_and_errors(tmp_path):
    tt = gnss_imu.read_tag(write_tag(tmp_path / "a.tag", end_ms=548731, n=7))
    assert tt.version == "TIMETAG RTKLIB demo5" and tt.tick_f == 12345 and tt.n_records == 7
    assert tt.start_ns == START_S * 10**9 + 854_000_000
    assert tt.end_ms == 548731 and tt.end_ns == tt.start_ns + 548_731_000_000
    with pytest.raises(HeaderError, match="TIMETAG"):
        gnss_imu.read_tag(write_tag(tmp_path / "b.tag", end_ms=10, magic=b"NOTATAG"))
    short = tmp_path / "c.tag"
    short.write_bytes(b"TIMETAG" + b"\0" * 20)
    with pytest.raises(HeaderError):
        gnss_imu.read_tag(short)
    with pytest.raises(TooFewRowsError):
        gnss_imu.read_tag(write_tag(tmp_path / "d.tag", end_ms=10, n=0))
    with pytest.raises(HeaderError, match="fraction"):
        gnss_imu.read_tag(write_tag(tmp_path / "e.tag", end_ms=10, frac=1.5))


# --- RTKLIB .pos and geodesy -----------------------------------------------------------------------

LLH_HEADER = ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
              "sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)      sdvn     sdve     "
              "sdvu    sdvne    sdveu    sdvun")


def pos_line(when: str, lat, lon, h, q=1, sd=(0.01, 0.02, 0.03), v=(0.0, 0.0, 0.0)) -> str:
    return (f"{when} {lat:.9f} {lon:.9f} {h:.4f} {q} 20 {sd[0]:.4f} {sd[1]:.4f} {sd[2]:.4f} 0.0 0.0 0.0 0.0 0.0 "
            f"{v[0]:.4f} {v[1]:.4f} {v[2]:.4f} 0.05 0.05 0.05 0 0 0")


def write_pos(path: Path, lines, header=LLH_HEADER) -> Path:
    path.write_text("% program   : RTKPOST\n" + header + "\n" + "\n".join(lines) + "\n")
    return path


def test_geodesy_known_points_and_round_trip():
    np.testing.assert_allclose(rtklib.llh_to_ecef(0.0, 0.0, 0.0), [rtklib.WGS84_A, 0.0, 0.0], atol=1e-9)
    b = rtklib.WGS84_A * (1 - rtklib.WGS84_F)
    np.testing.assert_allclose(rtklib.llh_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, b], atol=1e-6)
    for llh in ((40.0966268, -105.1474483, 1601.474), (-33.9, 151.2, -20.0), (89.9, 10.0, 5000.0)):
        back = rtklib.ecef_to_llh(rtklib.llh_to_ecef(*llh))
        np.testing.assert_allclose(back[:2], llh[:2], atol=1e-11)
        assert back[2] == pytest.approx(llh[2], abs=1e-6)
    assert rtklib.normal_gravity(0.0, 0.0) == pytest.approx(9.7803253359)
    assert rtklib.normal_gravity(90.0, 0.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert rtklib.normal_gravity(45.0, 1000.0) == pytest.approx(9.806199 - 0.003086, abs=2e-5)


def test_pos_llh_to_enu_closed_form(tmp_path):
    lat0, lon0, h0, dlon, up = 40.0966268, -105.1474483, 1601.474, 0.001, 12.5
    f = write_pos(tmp_path / "a.pos", [
        pos_line("2025/07/08 19:34:18.499", lat0, lon0, h0, sd=(0.01, 0.02, 0.03), v=(1.0, 2.0, 3.0)),
        pos_line("2025/07/08 19:34:18.749", lat0, lon0 + dlon, h0, q=2),
        pos_line("2025/07/08 19:34:19.000", lat0, lon0, h0 + up, q=5),
    ])
    sol = rtklib.read_pos(f)
    assert sol.position_kind == "llh" and sol.origin_llh == (lat0, lon0, h0)
    np.testing.assert_array_equal(sol.q, [1, 2, 5])
    np.testing.assert_array_equal(sol.lines, [3, 4, 5])
    t0 = (1752003258 * 10**9) + 499_000_000  # 2025-07-08 19:34:18.499 as seconds since 1970 (no leap seconds)
    np.testing.assert_array_equal(sol.t_ns, [t0, t0 + 250_000_000, t0 + 501_000_000])
    # Closed form: same latitude and height, longitude + dlon, in the ENU frame of the first point.
    phi, d = math.radians(lat0), math.radians(dlon)
    r = (rtklib.WGS84_A / math.sqrt(1 - rtklib.WGS84_E2 * math.sin(phi) ** 2) + h0) * math.cos(phi)
    expected = [r * math.sin(d), -r * math.sin(phi) * (math.cos(d) - 1), r * math.cos(phi) * (math.cos(d) - 1)]
    np.testing.assert_allclose(sol.enu[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(sol.enu[1], expected, atol=1e-6)
    np.testing.assert_allclose(sol.enu[2], [0.0, 0.0, up], atol=1e-6)
    np.testing.assert_allclose(sol.sigma_enu[0], [0.02, 0.01, 0.03])  # sde, sdn, sdu
    np.testing.assert_allclose(sol.vel_enu[0], [2.0, 1.0, 3.0])  # ve, vn, vu


def test_pos_week_seconds_and_ecef_agree_with_llh(tmp_path):
    lat0, lon0, h0 = 40.0966268, -105.1474483, 1601.474
    pts = [(lat0, lon0, h0), (lat0 + 1e-4, lon0 - 2e-4, h0 + 3.0)]
    llh = rtklib.read_pos(write_pos(tmp_path / "a.pos", [
        pos_line("2025/07/08 19:34:18.499", *pts[0]), pos_line("2025/07/08 19:34:18.749", *pts[1])]))
    week_tow = rtklib.read_pos(write_pos(tmp_path / "b.pos", [
        pos_line("2374 243258.499", *pts[0]), pos_line("2374 243258.749", *pts[1])]))
    np.testing.assert_array_equal(week_tow.t_ns, llh.t_ns)
    ecef_header = ("%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)   sdy(m)   "
                   "sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio")
    rows = []
    for when, p in zip(("2374 243258.499", "2374 243258.749"), pts):
        x = rtklib.llh_to_ecef(*p)
        rows.append(f"{when} {x[0]:.4f} {x[1]:.4f} {x[2]:.4f} 1 20 0.01 0.01 0.01 0 0 0 0.0 0.0")
    ecef = rtklib.read_pos(write_pos(tmp_path / "c.pos", rows, ecef_header))
    assert ecef.position_kind == "ecef" and ecef.vel_enu is None
    np.testing.assert_allclose(ecef.enu, llh.enu, atol=1e-3)
    np.testing.assert_allclose(ecef.origin_llh, pts[0], atol=1e-7)
    np.testing.assert_allclose(ecef.sigma_enu, 0.01, atol=1e-9)  # isotropic stays isotropic when rotated


def test_pos_cut_last_line_is_left_out_and_one_inside_named(tmp_path, caplog):
    """A logger stopped mid-line: the last line, cut, is left out (said at info), as the IMU logs' reader
    does; the same cut inside the file stops with file, line and how to mend it."""
    import logging

    lines = [pos_line(f"2025/07/08 19:34:{18.499 + 0.25 * k:06.3f}", 40.0966268, -105.1474483, 1601.4) for k in range(3)]
    cut = lines[:2] + [" ".join(lines[2].split()[:5])]
    with caplog.at_level(logging.INFO):
        sol = rtklib.read_pos(write_pos(tmp_path / "cut.pos", cut))
    assert len(sol.t_ns) == 2 and "left out its last line 5, cut (5 of" in caplog.text
    with pytest.raises(ColumnCountError, match=r"inside\.pos:4: .*found 5 \(a cut last line is left out"):
        rtklib.read_pos(write_pos(tmp_path / "inside.pos", [lines[0], cut[2], lines[2]]))


@pytest.mark.parametrize("mutate, err, field", [
    (lambda ls: ls.__setitem__(1, ls[1].replace("40.096626800", "nan", 1)), NonFiniteError, "latitude(deg)"),
    (lambda ls: ls.__setitem__(1, ls[1].replace(" 20 ", " x ", 1)), NotNumericError, "ns"),
    (lambda ls: ls.__setitem__(1, ls[1].rsplit(" ", 1)[0]), ColumnCountError, None),
    (lambda ls: ls.__setitem__(1, ls[1].replace("19:34:18.749", "19:34:18.249")), TimestampError, "GPST"),
    (lambda ls: ls.__setitem__(1, ls[1].replace(" 1 20 ", " 7 20 ")), SolutionQualityError, "Q"),
    (lambda ls: ls.__setitem__(1, ls[1].replace("2025/07/08", "2025/13/08")), NotNumericError, "GPST"),
])
def test_pos_malformed_rows_name_line_and_field(tmp_path, mutate, err, field):
    lines = [pos_line("2025/07/08 19:34:18.499", 40.0966268, -105.1474483, 1601.4),
             pos_line("2025/07/08 19:34:18.749", 40.0966268, -105.1474483, 1601.4),
             pos_line("2025/07/08 19:34:18.999", 40.0966268, -105.1474483, 1601.4)]
    mutate(lines)
    f = write_pos(tmp_path / "bad.pos", lines)
    with pytest.raises(err) as e:
        rtklib.read_pos(f)
    assert e.value.path == str(f) and e.value.line == 4 and e.value.field == field
    assert f"{f}:4:" in str(e.value)


def test_pos_bad_headers(tmp_path):
    row = pos_line("2025/07/08 19:34:18.499", 40.0, -105.0, 1600.0)
    f = tmp_path / "x.pos"
    f.write_text(row + "\n")
    with pytest.raises(HeaderError, match="no '%' header"):
        rtklib.read_pos(f)
    with pytest.raises(HeaderError, match="GPST"):
        rtklib.read_pos(write_pos(tmp_path / "u.pos", [row], LLH_HEADER.replace("GPST", "UTC ")))
    with pytest.raises(HeaderError, match="neither"):
        rtklib.read_pos(write_pos(tmp_path / "d.pos", [row], LLH_HEADER.replace("latitude(deg)", "latitude(d'\")")))
    with pytest.raises(TooFewRowsError):
        rtklib.read_pos(write_pos(tmp_path / "e.pos", []))


def test_fixes_on_imu_sigmas_gains_and_motion(tmp_path):
    lat0, lon0, h0 = 40.0, -105.0, 1600.0
    f = write_pos(tmp_path / "a.pos", [
        pos_line("2025/07/08 19:34:18.500", lat0, lon0, h0, q=1, sd=(0.01, 0.02, 0.03), v=(0.0, 10.0, 0.0)),
        pos_line("2025/07/08 19:34:18.750", lat0, lon0, h0, q=2, sd=(0.01, 0.02, 0.03), v=(0.0, 10.0, 0.0)),
        pos_line("2025/07/08 19:34:19.000", lat0, lon0, h0, q=5),
        pos_line("2025/07/08 19:34:30.000", lat0, lon0, h0, q=1),  # after the IMU
    ])
    sol = rtklib.read_pos(f)
    imu_t = sol.t_ns[0] - 3_000_000 + np.arange(100) * 10_000_000  # 100 Hz, 3 ms before the first fix
    fx = rtklib.fixes_on_imu(sol, imu_t, lever=(0.0, 0.1, 0.0), qualities=(1, 2), float_gain=3.0)
    np.testing.assert_array_equal(fx.idx, [0, 25])
    np.testing.assert_array_equal(fx.q, [1, 2])
    np.testing.assert_allclose(fx.sigmas, [[0.02, 0.01, 0.03], [0.06, 0.03, 0.09]])
    # moved onto the sample's stamp with the epoch's velocity (10 m/s east, 3 ms earlier)
    np.testing.assert_allclose(fx.p[0], [-0.03, 0.0, 0.0], atol=1e-9)
    assert fx.dropped_outside == 1 and len(fx) == 2
    sub = fx.select(np.array([False, True]), dropped_outage=1)
    assert len(sub) == 1 and sub.sigmas.shape == (1, 3) and sub.dropped_outage == 1


def test_graph_uses_per_fix_sigmas():
    from imu_learn.fuse.graph import _aiding_by_sample

    sig = np.array([[0.01, 0.02, 0.03], [1.0, 2.0, 3.0]])
    fx = rtklib.GnssFixes(np.array([3, 7]), np.zeros((2, 3)), 0.5, np.zeros(3), "t", sigmas=sig, q=np.array([1, 2]))
    fixes_at, _ = _aiding_by_sample([fx])
    for s, row in ((3, sig[0]), (7, sig[1])):
        np.testing.assert_allclose(fixes_at[s][0][2].sigmas(), row)
    plain = PositionFixes(np.array([3]), np.zeros((1, 3)), 0.5, np.zeros(3), "t")
    np.testing.assert_allclose(_aiding_by_sample([plain])[0][3][0][2].sigmas(), [0.5] * 3)
    bad = rtklib.GnssFixes(np.array([3, 7]), np.zeros((2, 3)), 0.5, np.zeros(3), "t", sigmas=sig[:1])
    with pytest.raises(InvalidInputError, match="per-fix sigmas"):
        _aiding_by_sample([bad])


# --- NHC -------------------------------------------------------------------------------------------

def test_nhc_jacobians_match_numerical():
    import gtsam
    from gtsam.symbol_shorthand import V, X

    rng = np.random.default_rng(3)
    settings = nhc.NhcSettings(0.2, 0.5, lever=(0.3, -0.1, 0.65))
    for _ in range(5):
        pose = gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 1, 3)), rng.normal(0, 5, 3))
        v = rng.normal(0, 5, 3)
        f = nhc.nhc_factor(X(0), V(0), settings, omega=rng.normal(0, 0.5, 3))
        vals = gtsam.Values()
        vals.insert(X(0), pose)
        vals.insert(V(0), v)
        lin = f.linearize(vals)
        A, _b = lin.jacobian()  # whitened: [H_pose | H_vel] / sigmas
        e0 = f.unwhitenedError(vals)
        num = np.zeros((2, 9))
        h = 1e-6
        for i in range(9):
            d = np.zeros(9)
            d[i] = h
            vp = gtsam.Values()
            vp.insert(X(0), pose.retract(d[:6]))
            vp.insert(V(0), v + d[6:])
            num[:, i] = (f.unwhitenedError(vp) - e0) / h
        np.testing.assert_allclose(A * np.array([[0.2], [0.5]]), num, atol=1e-4)
    # the residual is the body-frame velocity's y, z
    R = gtsam.Rot3.Yaw(0.3).matrix()
    e = nhc.nhc_error(R, R @ np.array([5.0, 0.2, -0.1]), np.zeros(3))
    np.testing.assert_allclose(e, [0.2, -0.1])


def test_nhc_callback_rate_and_turns():
    gyro = np.zeros((50, 3))
    gyro[20, 2] = 1.0  # a fast turn at sample 20

    class Inc:
        t_ns = np.arange(50) * 10_000_000

    cb = nhc.nhc_callback(nhc.NhcSettings(every_s=0.1, max_yaw_rate_dps=math.degrees(0.5)), gyro)
    got = [s for s in range(50) if cb(Inc, s, s)]
    assert got == [0, 10, 21, 31, 41]
    with pytest.raises(InvalidInputError):
        nhc.NhcSettings(sigma_lat=0.0)


# --- the experiment on a synthetic drive -----------------------------------------------------------

def synthetic_drive(tmp_path: Path, heading_deg: float = 30.0, seconds: float = 40.0) -> Path:
    """Still for 5 s, then accelerating at 0.5 m/s^2 in a straight line along ``heading_deg``
    (from east towards north), level; the IMU (100 Hz) mounted with yaw 90 deg; fixes at 4 Hz."""
    g = rtklib.normal_gravity(40.0, 1600.0)
    fs, t_still = 100, 5.0
    n = int(seconds * fs)
    tt = np.arange(n) / fs
    a_fwd = np.where(tt >= t_still, 0.5, 0.0)
    M = gnss_imu.mounting_rotation([0.0, 0.0, 90.0])  # body = M @ imu
    f_body = np.stack([a_fwd, np.zeros(n), np.full(n, g)], axis=1)  # body x forward, z up
    f_imu = f_body @ M  # imu = M^T @ body
    d = tmp_path / "rec"
    d.mkdir()
    rows = [list(f_imu[i] / 9.80665) + [0.0, 0.0, 0.0] + [5000 + 10 * i] for i in range(n)]
    text = "".join(f"{r[0]:.6f},{r[1]:.6f},{r[2]:.6f},{r[3]:.3f},{r[4]:.3f},{r[5]:.3f},{r[6]}\n" for r in rows)
    (d / "imu.csv").write_text("0.5,1\n" + text)  # a cut first line
    start_s = 1752003261
    write_tag(d / "imu.csv.tag", end_ms=10 * (n - 1), start_s=start_s, frac=0.0)
    psi = math.radians(heading_deg)
    u = np.array([math.cos(psi), math.sin(psi), 0.0])
    lat0, lon0, h0 = 40.0, -105.0, 1600.0
    x0 = rtklib.llh_to_ecef(lat0, lon0, h0)
    Rn = rtklib.ecef_to_enu_rotation(lat0, lon0)
    lines = []
    for k in range(int((seconds - 0.3) * 4)):
        tk = 0.25 * k + 0.002  # 2 ms after the IMU samples
        s = 0.5 * 0.25 * max(tk - t_still, 0.0) ** 2
        v = 0.5 * max(tk - t_still, 0.0)
        llh = rtklib.ecef_to_llh(x0 + Rn.T @ (u * s))
        whole = start_s + int(tk)
        stamp = f"{np.datetime_as_string(np.datetime64(whole, 's')).replace('-', '/').replace('T', ' ')}" \
                f".{int(round((tk % 1) * 1000)):03d}"
        lines.append(pos_line(stamp, *llh, q=1, sd=(0.01, 0.01, 0.01), v=(v * u[1], v * u[0], 0.0)))
    write_pos(d / "gnss.pos", lines)
    return d


def test_experiment_on_a_synthetic_drive(tmp_path):
    from imu_learn.fuse.experiments import gnss as gnss_run

    synthetic_drive(tmp_path)
    cfg = gnss_run.GnssRunConfig(name="synthetic", data_root=str(tmp_path), imu="rec/imu.csv", pos="rec/gnss.pos",
                                 mounting_rpy_deg=[0.0, 0.0, 90.0], level_s=3.0, earth_rate=False,
                                 variants=["raw", "raw+nhc"], keyframe_hz=4.0,
                                 outages=gnss_run.OutageCfg(first_s=15.0, duration_s=10.0, period_s=30.0,
                                                            end_margin_s=2.0))
    cfg.noise.gyro_noise_density, cfg.noise.acc_noise_density = 1e-4, 1e-3
    cfg.nhc = replace(cfg.nhc, lever_from="raw")  # fitted on the raw run: a straight drive leaves it at zero
    res = gnss_run.experiment(cfg)
    fit = res["runs"]["raw+nhc"]["nhc_lever_fit"]
    assert "too little yaw/roll rate" in fit["fallback"] and fit["lever_m"] == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(res["outages_s"], [(15.0, 10.0)], atol=1e-9)
    assert res["imu"]["skipped_lines"] == [1]
    st = res["start"]
    assert st["speed_mps"] > 1.0 and 7.0 < st["start_s_after_first_epoch"] < 8.0
    # the start attitude from levelling + the track: body x along the 30 deg heading, level
    R0 = np.array(st["R0"])
    np.testing.assert_allclose(R0[:, 0], [math.cos(math.radians(30)), math.sin(math.radians(30)), 0.0], atol=0.02)
    for v in ("raw", "raw+nhc"):
        r = res["runs"][v]
        assert r["live"]["outages"][0]["n"] == 40
        assert r["live"]["outages"][0]["end_m"] < 0.3, r["live"]
        assert r["smoothed"]["outages"][0]["max_m"] < 0.1, r["smoothed"]
        assert r["live"]["outside_rms_m"] < 0.05
    text = gnss_run.table(res, cfg)
    assert "ours raw+nhc" in text


def test_experiment_through_the_cli(tmp_path, capsys):
    """``imu-learn fuse --config`` routes a ``kind = "gnss-outages"`` config to the experiment; ``--set``
    and ``--variants`` apply to it only; the library prints nothing (the CLI does)."""
    from imu_learn.cli import main

    synthetic_drive(tmp_path, seconds=25.0)
    cfg = tmp_path / "gnss.toml"
    cfg.write_text('kind = "gnss-outages"\nname = "synthetic"\nimu = "rec/imu.csv"\npos = "rec/gnss.pos"\n'
                   'mounting_rpy_deg = [0.0, 0.0, 90.0]\nlevel_s = 3.0\nearth_rate = false\nkeyframe_hz = 4.0\n'
                   'variants = ["raw", "raw+nhc"]\n[noise]\ngyro_noise_density = 1e-4\nacc_noise_density = 1e-3\n'
                   '[outages]\nfirst_s = 12.0\nduration_s = 5.0\nperiod_s = 30.0\nend_margin_s = 2.0\n')
    out = tmp_path / "report"
    rc = main(["fuse", "--config", str(cfg), "--data-root", str(tmp_path), "--out", str(out), "--variants", "raw",
               "--set", "nhc.sigma_lat=0.05", "--set", "velocity_sigma_mps=0.05"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert cap.out.splitlines()[0].startswith("synthetic raw: live mean RMS/max/end")
    assert f"wrote {out / 'results.json'} and {out / 'table.md'}" in cap.out
    res = json.loads((out / "results.json").read_text())
    assert list(res["runs"]) == ["raw"] and res["config"]["nhc"]["sigma_lat"] == 0.05
    assert res["config"]["velocity_sigma_mps"] == 0.05 and res["config"]["kind"] == "gnss-outages"
    assert (out / "table.md").read_text().startswith("# synthetic")
    for argv, msg in (
        (["--variants", "raw+gps"], "variants: each one of raw, raw+nhc"),
        (["--set", "nope=1"], "nope: unknown key"),
        (["--set", "novalue"], "--set 'novalue': expected KEY=VALUE"),
        (["--online"], "--online: not with a kind = \"gnss-outages\" config"),
    ):
        rc = main(["fuse", "--config", str(cfg), "--data-root", str(tmp_path), "--out", str(out), *argv])
        err = capsys.readouterr().err
        assert rc == 2 and err.startswith("imu-learn fuse: error: ConfigError: ") and msg in err, err
    # the fusion experiment's configs have no kind: --set / --variants are not theirs; an unknown kind is refused
    rc = main(["fuse", "--config", "configs/fuse_euroc.toml", "--variants", "raw"])
    assert rc == 2 and '--variants: only with a kind = "gnss-outages" config' in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('kind = "other"\n')
    rc = main(["fuse", "--config", str(bad)])
    assert rc == 2 and "kind: 'gnss-outages' or none" in capsys.readouterr().err


# --- the real drive --------------------------------------------------------------------------------

DATA = Path(os.environ.get("IMU_LEARN_DATA", "")) if os.environ.get("IMU_LEARN_DATA") else \
    Path(__file__).resolve().parents[1].parent / "shared" / "data"
DRIVE = DATA / "gnss-imu" / "drive_0708"


@pytest.mark.skipif(not (DRIVE / "imu_1934.csv").is_file(), reason="the gnss-imu drive is not on this machine "
                    "(set IMU_LEARN_DATA to the data root)")
def test_real_drive_first_seconds():
    M = gnss_imu.mounting_rotation([180.0, -6.79, 185.35])
    log = gnss_imu.read_imu_log(DRIVE / "imu_1934.csv", mounting=M, delay_s=-0.125)
    assert log.skipped_lines == (1,)
    assert log.rate_hz == pytest.approx(100.0, rel=0.01)
    assert log.imu.t_ns[0] == log.tag.start_ns - 125_000_000
    assert abs(log.clock_scale - 1.0) < 1e-3
    first = log.imu.t_ns < log.imu.t_ns[0] + 5_000_000_000  # the still start
    f = log.imu.acc[first].mean(axis=0)
    # 9.93 m/s^2 against 9.797 of normal gravity there: an accelerometer error the graph must estimate
    assert np.linalg.norm(f) == pytest.approx(9.80, abs=0.2)
    assert f[2] < -9.5  # body frame forward-right-down: the specific force points up (-z)
    sol = rtklib.read_pos(DRIVE / "gnss_1934_sf.pos")
    assert len(sol) == 2197 and set(np.unique(sol.q)) == {1, 2}
    fx = rtklib.fixes_on_imu(sol, log.imu.t_ns)
    assert fx.dropped_outside > 0 and len(fx) > 2000
    speed = np.linalg.norm(sol.vel_enu[:, :2], axis=1)
    assert speed[sol.t_ns < log.imu.t_ns[0] + 30_000_000_000].max() < 0.1


def test_nhc_lever_calibration_recovers_the_point():
    rng = np.random.default_rng(7)
    K = 200
    R = Rotation.from_rotvec(np.c_[rng.normal(0, 0.05, (K, 2)), rng.uniform(-3, 3, K)]).as_matrix()
    omega = rng.normal(0, 0.3, (K, 3))
    r = np.array([-1.2, 0.0, 0.7])
    vb = np.c_[rng.uniform(3, 15, K), np.zeros(K), np.zeros(K)] - np.cross(omega, r)  # the point: no y velocity
    v = np.einsum("kij,kj->ki", R, vb)
    lever, resid, used = nhc.calibrate_lever(R, v, omega)
    np.testing.assert_allclose(lever, r, atol=1e-9)
    assert resid < 1e-9 and used == K
    with pytest.raises(InvalidInputError, match="keyframes"):
        nhc.calibrate_lever(R[:5], v[:5], omega[:5])
    with pytest.raises(InvalidInputError, match="too little"):  # a straight drive: no turning
        nhc.calibrate_lever(R, v, omega * 1e-3)
