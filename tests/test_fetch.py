"""The Fetch (Debias_IMU) layout: float-notation stamps read exactly, typed errors that locate a bad
row, detection ahead of ASL, and a recording whose IMU aligns with its mocap. The crop is written
by each test in the recorder's own format (``%.18e`` everywhere), so no data file is needed."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import imu_learn as il
from imu_learn.data.datasets import find_recordings
from imu_learn.data.formats import detect_format, fetch, read_imu_source, read_recording, write_imu
from imu_learn.data.synthetic import FETCH_T0 as T0
from imu_learn.data.synthetic import IMU_HEADER, fetch_row, write_fetch_recording
from imu_learn.errors import (
    ColumnCountError,
    HeaderError,
    NonFiniteError,
    NotNumericError,
    ParseError,
    TimestampError,
)


def test_float_stamp_is_parsed_exactly():
    assert fetch.parse_stamp("1.691116804753040896e+18") == 1691116804753040896
    assert fetch.parse_stamp("1691116804753040896") == 1691116804753040896
    # The float64 grid at this epoch is 256 ns: neighbouring stamps differ by exactly that.
    assert fetch.parse_stamp(repr(float(np.nextafter(float(T0), np.inf)))) - T0 == fetch.STAMP_RESOLUTION_NS
    for bad in ("1.5", "nan", "inf", "1e30", "abc"):
        with pytest.raises(ValueError):
            fetch.parse_stamp(bad)


def test_crop_reads_detects_and_aligns(tmp_path):
    rec = write_fetch_recording(tmp_path)
    assert detect_format(rec) == "fetch"
    assert detect_format(rec / "mav0" / "imu0" / "data.csv") == "fetch"
    assert [n for n, _ in find_recordings("fetch", tmp_path)] == ["01_crop"]
    imu, gt = read_recording(rec)
    assert imu.t_ns.dtype == np.int64 and imu.t_ns[0] == T0
    # every stamp exactly the float64 written, not a rounded neighbour
    assert np.array_equal(imu.t_ns, (T0 + np.arange(len(imu.t_ns)) * 10_000_000).astype(float).astype(np.int64))
    assert len(gt.t_ns) > 300 and np.allclose(gt.p[:, 2], 0.36)
    segs = il.align(imu, gt, il.AlignOptions(max_gap_s=0.1)).segments
    assert len(segs) == 1 and len(segs[0]) == len(imu.t_ns)
    # the mocap's orientation, interpolated at the IMU stamps, is the gyro integrated
    s = segs[0]
    yaw = 2 * np.arctan2(s.q_wxyz[:, 3], s.q_wxyz[:, 0])
    expect = 0.5 * (s.t_ns - T0) * 1e-9
    assert np.max(np.abs(np.angle(np.exp(1j * (yaw - expect))))) < 1e-6


def test_asl_layout_is_not_taken_for_fetch(tmp_path):
    rec = tmp_path / "MH"
    (rec / "mav0" / "imu0").mkdir(parents=True)
    (rec / "mav0" / "imu0" / "data.csv").write_text("#timestamp [ns],w_RS_S_x [rad s^-1]\n")
    assert not fetch.detect(rec)
    assert detect_format(rec) == "asl"


@pytest.mark.parametrize(
    "row, error, line, column, field",
    [
        ("1.691116804773040896e+18,0,0,0,0,0", ColumnCountError, 4, None, None),
        ("1.691116804773040896e+18,0,0,x,0,0,9.8", NotNumericError, 4, 4, "wz"),
        ("1.691116804773040896e+18,0,0,0,nan,0,9.8", NonFiniteError, 4, 5, "ax"),
        ("1.691116804753040896e+18,0,0,0,0,0,9.8", TimestampError, 4, 1, "timestamp"),
        ("1.6911168047730409e+09,0,0,0,0,0,9.8", NotNumericError, 4, 1, "timestamp"),
        ("", ColumnCountError, 4, None, None),
    ],
)
def test_bad_row_is_a_typed_error_naming_file_line_and_field(tmp_path, row, error, line, column, field):
    f = tmp_path / "data.csv"
    good = [fetch_row(float(T0 + k * 10_000_000), [0, 0, 0, 0, 0, 9.8]) for k in range(2)]
    f.write_text("\n".join([IMU_HEADER, *good, row, good[-1]]) + "\n")
    with pytest.raises(error) as e:
        fetch.read_table(f, fetch.IMU_NAMES)
    assert isinstance(e.value, ParseError)
    assert (e.value.path, e.value.line, e.value.column, e.value.field) == (str(f), line, column, field)
    assert f"{f}:{line}:" in str(e.value)


def test_wrong_header_is_a_header_error(tmp_path):
    f = tmp_path / "data.csv"
    f.write_text("# timestamp, x, y, z, qw, qx, qy, qz\n" + fetch_row(float(T0), [0] * 7) + "\n")
    with pytest.raises(HeaderError):
        fetch.read_table(f, fetch.IMU_NAMES)


def test_refined_copy_keeps_stamps_and_reads_back(tmp_path):
    rec = write_fetch_recording(tmp_path, seconds=1.0)
    src = read_imu_source(rec)
    gyro, acc = src.gyro + 0.125, src.acc * 0.5
    out = tmp_path / "out.csv"
    write_imu(src, out, gyro, acc)
    t, v = fetch.read_table(out, fetch.IMU_NAMES)
    assert np.array_equal(t, src.t_ns) and np.array_equal(v[:, :3], gyro) and np.array_equal(v[:, 3:], acc)
    assert out.read_text().splitlines()[0] == IMU_HEADER


REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fetch" / "01_square"  # beside the repo, as conftest.SHARED


@pytest.mark.skipif(not REAL.is_dir(), reason="the Fetch recordings are not on this machine")
def test_real_recording_stamps_match_float64_parse():
    imu, gt = read_recording(REAL, "fetch")
    first = (REAL / "mav0" / "imu0" / "data.csv").read_text().splitlines()[1].split(",")[0]
    assert imu.t_ns[0] == int(float(first)) and np.all(imu.t_ns % fetch.STAMP_RESOLUTION_NS == 0)
    assert il.align(imu, gt, il.AlignOptions(max_gap_s=0.1)).segments
