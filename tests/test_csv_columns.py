"""A user's own IMU CSV (imu_learn.data.formats.csv_columns, read and written in Rust): a Fetch
recording rewritten with other column names, order, units (deg/s, g) and float seconds reads back
to the Fetch reader's values; the writer keeps the user's columns and units; each error names the
file, line, column and field."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imu_learn.data.formats import csv_columns, fetch
from imu_learn.data.formats.csv_columns import STANDARD_GRAVITY, CsvColumns, read_csv_columns, write_csv_columns
from imu_learn.errors import (
    ColumnCountError,
    InvalidInputError,
    NonFiniteError,
    NotNumericError,
    TimestampError,
    TooFewRowsError,
)

T0 = 1691116804753040896  # a Fetch stamp (float64-representable)
N = 300


def fetch_like(tmp_path: Path) -> Path:
    """A Fetch IMU file: ``# timestamp, wx, ..., az``, stamps as float64 in full, 100 Hz."""
    rng = np.random.default_rng(0)
    gyro = rng.normal(0, 0.3, (N, 3))
    acc = rng.normal(0, 0.5, (N, 3)) + [0, 0, 9.81]
    f = tmp_path / "rec" / "mav0" / "imu0" / "data.csv"
    f.parent.mkdir(parents=True)
    # Stamps 10 ms apart, rounded to the 256 ns the float64 stamps resolve.
    t = [int(float(T0 + k * 10_000_000)) for k in range(N)]
    rows = [fetch.format_row(t[k], [*gyro[k], *acc[k]]) for k in range(N)]
    f.write_text("# timestamp, wx, wy, wz, ax, ay, az\n" + "\n".join(rows) + "\n")
    return f


def rewrite_as_user(imu, path: Path, exact_seconds: bool = True) -> None:
    """The same samples as a user exports them: other names and order, a text column, deg/s, g,
    float seconds, a comment, and a trailing column the map leaves out."""
    lines = ["# exported from the robot", "time_s,temp_C,wz_dps,wy_dps,wx_dps,az_g,ay_g,ax_g,status"]
    for k in range(len(imu)):
        t = int(imu.t_ns[k])
        ts = f"{t // 10**9}.{t % 10**9:09d}" if exact_seconds else repr(t * 1e-9)
        g = np.degrees(imu.gyro[k][::-1])
        a = imu.acc[k][::-1] / STANDARD_GRAVITY
        lines.append(",".join([ts, "31.5", *(repr(float(x)) for x in (*g, *a)), "ok"]))
    path.write_text("\n".join(lines) + "\n")


USER = dict(columns="t,_,gz,gy,gx,az,ay,ax", time_unit="s", gyro_unit="deg/s", acc_unit="g")


def test_the_fetch_file_itself_reads_as_the_fetch_reader_does(tmp_path):
    f = fetch_like(tmp_path)
    want = fetch.read_imu(f)
    got = read_csv_columns(f, "t,gx,gy,gz,ax,ay,az", "ns", "rad/s", "m/s2")
    np.testing.assert_array_equal(got.t_ns, want.t_ns)
    np.testing.assert_array_equal(got.gyro, want.gyro)
    np.testing.assert_array_equal(got.acc, want.acc)


def test_fetch_rewritten_with_other_columns_units_and_float_seconds_reads_back(tmp_path):
    want = fetch.read_imu(fetch_like(tmp_path))
    user = tmp_path / "mine.csv"
    rewrite_as_user(want, user)
    got = read_csv_columns(user, **USER)
    np.testing.assert_array_equal(got.t_ns, want.t_ns)  # 9 decimals of seconds: exact
    np.testing.assert_allclose(got.gyro, want.gyro, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(got.acc, want.acc, rtol=1e-14, atol=1e-15)
    # Seconds printed as float64 (~0.24 us resolution at this epoch) come back within a microsecond.
    rewrite_as_user(want, user, exact_seconds=False)
    got = read_csv_columns(user, **USER)
    assert np.max(np.abs(got.t_ns - want.t_ns)) < 1000
    assert np.all(np.diff(got.t_ns) > 0)


@pytest.mark.parametrize(
    "delim, time_unit, scale",
    [(";", "ms", 10**6), ("\t", "us", 10**3), ("  ", "ns", 1)],
)
def test_other_delimiters_and_time_units(tmp_path, delim, time_unit, scale):
    f = tmp_path / "x.txt"
    rows = [delim.join([str(k * 5 * 10**6 // scale), "1", "2", "3", "0", "0", "1"]) for k in range(4)]
    f.write_text("\n".join(rows))
    got = read_csv_columns(f, "t,gx,gy,gz,ax,ay,az", time_unit, "rad/s", "g")
    np.testing.assert_array_equal(got.t_ns, np.arange(4) * 5 * 10**6)
    np.testing.assert_array_equal(got.acc[:, 2], STANDARD_GRAVITY)


def test_the_writer_keeps_the_users_columns_and_units(tmp_path):
    orig = fetch.read_imu(fetch_like(tmp_path))
    user = tmp_path / "mine.csv"
    rewrite_as_user(orig, user)
    imu = read_csv_columns(user, **USER)
    gyro, acc = imu.gyro * 1.01 - 1e-3, imu.acc + [0.1, -0.2, 0.05]
    out = tmp_path / "refined.csv"
    write_csv_columns(user, out, gyro, acc, **USER)
    back = read_csv_columns(out, **USER)
    np.testing.assert_array_equal(back.t_ns, imu.t_ns)
    np.testing.assert_allclose(back.gyro, gyro, rtol=1e-15, atol=1e-17)
    np.testing.assert_allclose(back.acc, acc, rtol=1e-15, atol=1e-17)
    before, after = user.read_text().splitlines(), out.read_text().splitlines()
    assert before[:2] == after[:2] and len(before) == len(after)  # comment and header as they were
    for x, y in zip(before[2:], after[2:]):
        fx, fy = x.split(","), y.split(",")
        assert [fx[0], fx[1], fx[8]] == [fy[0], fy[1], fy[8]]  # time, temperature, status
        assert fx[2:8] != fy[2:8]
    # The samples as read, written back, give the file back (values in its own units).
    write_csv_columns(user, out, imu.gyro, imu.acc, **USER)
    np.testing.assert_allclose(read_csv_columns(out, **USER).gyro, imu.gyro, rtol=0, atol=0)
    with pytest.raises(InvalidInputError, match="holds 300 samples"):
        write_csv_columns(user, out, gyro[1:], acc[1:], **USER)


HEADER = "time_s,temp_C,wz_dps,wy_dps,wx_dps,az_g,ay_g,ax_g\n"
GOOD = "0.00,20,0,0,0,1,0,0\n"


@pytest.mark.parametrize(
    "body, cls, line, column, field",
    [
        ("0.01,20,0,0,0,1,0\n", ColumnCountError, 3, 8, "ax_g (ax)"),  # a column missing
        ("0.01,20,0,x,0,1,0,0\n", NotNumericError, 3, 4, "wy_dps (gy)"),  # a bad number
        ("0.01,20,0,0,nan,1,0,0\n", NonFiniteError, 3, 5, "wx_dps (gx)"),
        ("0.01,20,0,0,0,1,0,0\n0.005,20,0,0,0,1,0,0\n", TimestampError, 4, 1, "time_s (t)"),  # non-monotonic
        ("0.00,20,0,0,0,1,0,0\n", TimestampError, 3, 1, "time_s (t)"),  # a duplicate
        ("0.01,20,0,0,0,1,0,0\n0.02,20,0,0,0,1,0,\n", NotNumericError, 4, 8, "ax_g (ax)"),  # an empty field
    ],
)
def test_errors_name_file_line_column_and_field(tmp_path, body, cls, line, column, field):
    f = tmp_path / "bad.csv"
    f.write_text(HEADER + GOOD + body)
    with pytest.raises(cls) as e:
        read_csv_columns(f, **USER)
    assert (e.value.path, e.value.line, e.value.column, e.value.field) == (str(f), line, column, field)
    assert str(e.value).startswith(f"{f}:{line}:{column}: field {field!r}".replace("'", '"'))


def test_too_few_rows_and_unknown_units_and_maps(tmp_path):
    f = tmp_path / "one.csv"
    f.write_text(HEADER + GOOD)
    with pytest.raises(TooFewRowsError) as e:
        read_csv_columns(f, **USER)
    assert e.value.path == str(f) and e.value.line == 2
    f.write_text(HEADER + GOOD + "0.01,20,0,0,0,1,0,0\n")
    for kw, word in [
        (dict(gyro_unit="rpm"), "gyro unit 'rpm'".replace("'", '"')),
        (dict(acc_unit="m/s"), "acc unit"),
        (dict(time_unit="min"), "time unit"),
        (dict(columns="t,_,gz,gy,gx,az,ay"), "has no ax"),
        (dict(columns="t,_,gz,gy,gx,az,ay,ax,gz"), "gz is given twice"),
        (dict(columns="t,temp,gz,gy,gx,az,ay,ax"), "entry 2 is \"temp\""),
    ]:
        with pytest.raises(InvalidInputError, match=word):
            read_csv_columns(f, **{**USER, **kw})
    with pytest.raises(FileNotFoundError):
        read_csv_columns(tmp_path / "none.csv", **USER)


def test_an_imu_source_for_refine_round_trips(tmp_path):
    orig = fetch.read_imu(fetch_like(tmp_path))
    user = tmp_path / "mine.csv"
    rewrite_as_user(orig, user)
    layout = CsvColumns(**USER)
    src = csv_columns.read_imu_source(user, layout)
    assert (src.fmt, src.imu_file, src.root, src.rel) == ("csv-columns", user, tmp_path, Path("mine.csv"))
    out = tmp_path / "out" / "mine.csv"
    out.parent.mkdir()
    csv_columns.write_imu(src, out, src.gyro + 1e-3, src.acc, layout)
    np.testing.assert_allclose(read_csv_columns(out, **USER).gyro, src.gyro + 1e-3, rtol=1e-15)
