"""A user's CSV mistakes never pass silently (imu_learn.data.formats.input_checks, called by the one read of a
user's CSV): each mistake a column map and its units let through stops a command with exit 2 and one
line naming the mistake and the option that fixes it, or a warning where the data cannot decide; a
correct file passes without a word; --skip-bad-lines skips a logger's truncated lines and counts them.

The files are synthetic: 5 s at rest (gravity along z, a gyro bias, white noise), then 10 s of motion,
at 200 Hz, written in the units and column order each test says."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from imu_learn.cli import main
from imu_learn.data.formats import CsvColumns, read_imu_source, write_imu
from imu_learn.data.formats.csv_columns import read_csv_columns
from imu_learn.errors import ColumnCountError, ImplausibleInputError, InvalidInputError
from imu_learn.infer import rewrite
from imu_learn.util.staging import can_create_in, check_writable

G = 9.80665
RATE = 200.0
T0_NS = 1_403_636_579_758_560_000  # a EuRoC stamp: Unix time in ns
REPO = Path(__file__).resolve().parents[1]
MAP = "t,gx,gy,gz,ax,ay,az"


def samples(seconds_still: float = 5.0, seconds_moving: float = 10.0, seed: int = 0):
    """Stamps [ns], gyro [rad/s], acc [m/s^2]: at rest, then turning (up to ~1.5 rad/s) and shaken."""
    rng = np.random.default_rng(seed)
    n_still, n_move = int(seconds_still * RATE), int(seconds_moving * RATE)
    n = n_still + n_move
    t = T0_NS + np.arange(n, dtype=np.int64) * int(1e9 / RATE)
    gyro = np.tile([0.01, -0.005, 0.003], (n, 1)) + rng.normal(0, 0.002, (n, 3))
    acc = np.tile([0.3, -0.2, G], (n, 1)) + rng.normal(0, 0.02, (n, 3))
    s = np.arange(n_move) / RATE
    gyro[n_still:] += np.c_[np.sin(2.1 * s), 0.8 * np.sin(1.3 * s + 1), 1.2 * np.cos(0.7 * s)]
    acc[n_still:] += np.c_[2 * np.sin(3.1 * s), 1.5 * np.cos(2.3 * s), np.sin(1.7 * s)]
    return t, gyro, acc


def write(path: Path, t, gyro, acc, header: str = MAP, extra=None, time_text=str) -> Path:
    """A CSV: header, then t, gyro, acc (and ``extra`` columns) as given, full precision."""
    cols = [gyro, acc] + ([extra] if extra is not None else [])
    body = np.concatenate(cols, axis=1)
    lines = [header] + [",".join([time_text(int(ti))] + [repr(float(x)) for x in row]) for ti, row in zip(t, body)]
    path.write_text("\n".join(lines) + "\n")
    return path


def calibrate(capsys, path: Path, *options: str):
    """``imu-learn calibrate --imu-only --format csv-columns`` on ``path``: (exit code, stderr)."""
    rc = main(["calibrate", "--imu-only", "--input", str(path), "--format", "csv-columns", "--out",
               str(path.parent / "out"), "--no-plot", "--quiet", *options])
    return rc, capsys.readouterr().err


def refused(capsys, path: Path, *options: str) -> str:
    """The one line calibrate stops with (exit 2, nothing written)."""
    rc, err = calibrate(capsys, path, *options)
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("imu-learn calibrate: error: ImplausibleInputError: "), err
    assert not (path.parent / "out").exists()
    return err


def test_a_correct_file_passes_silently(tmp_path, caplog):
    t, g, a = samples()
    f = write(tmp_path / "ok.csv", t, g, a)
    with caplog.at_level(logging.INFO, logger="imu_learn"):
        src = read_imu_source(f, columns=CsvColumns(MAP))
        # in other units, named as such
        f2 = write(tmp_path / "ok2.csv", t // 1000, np.degrees(g), a / G)
        src2 = read_imu_source(f2, columns=CsvColumns(MAP, "us", "deg/s", "g"))
    assert caplog.records == []
    assert len(src.t_ns) == len(t) and src.skipped_lines == ()
    np.testing.assert_allclose(src2.gyro, g, rtol=1e-12)
    # and the format's default map (no --columns) for a file of seven columns
    src3 = read_imu_source(f, columns=CsvColumns(columns_named=False))
    assert len(src3.t_ns) == len(t)
    # a delimiter at each line's end is no eighth column
    f4 = tmp_path / "trailing.csv"
    f4.write_text("".join(line + ",\n" for line in f.read_text().splitlines()))
    assert len(read_imu_source(f4, columns=CsvColumns(columns_named=False)).t_ns) == len(t)


# 1. time unit ------------------------------------------------------------------------------------
def test_microsecond_stamps_read_as_ns(tmp_path, capsys):
    t, g, a = samples()
    err = refused(capsys, write(tmp_path / "us.csv", t // 1000, g, a))
    assert "the stamps step by 5000 ns (200 kHz) with --time-unit ns: they look like microseconds" in err
    assert err.rstrip().endswith("add --time-unit us")


def test_microsecond_stamps_read_as_ms(tmp_path, capsys):
    t, g, a = samples()
    boot = (t - t[0]) // 1000 + 123_456  # us since boot: 0.2 Hz in ms
    err = refused(capsys, write(tmp_path / "boot.csv", boot, g, a), "--time-unit", "ms")
    assert "(0.2 Hz) with --time-unit ms" in err and err.rstrip().endswith("add --time-unit us")
    # Unix time in us read as ms does not even fit int64 ns: named the same way
    err = refused(capsys, write(tmp_path / "epoch.csv", t // 1000, g, a), "--time-unit", "ms")
    assert "epoch.csv:2: the stamp 1403636579758560 with --time-unit ms" in err
    assert err.rstrip().endswith("add --time-unit us")


def test_decimal_seconds_read_as_ns(tmp_path, capsys):
    """Seconds with decimals under the default ns round to the same ns and repeat: the reader's
    duplicate is explained by the unit the stamps as written fit."""
    t, g, a = samples()
    err = refused(capsys, write(tmp_path / "s.csv", t, g, a, time_text=lambda ti: f"{ti * 1e-9:.6f}"))
    assert "s.csv:3: the stamps repeat as read with --time-unit ns" in err and "they look like seconds" in err
    assert err.rstrip().endswith("add --time-unit s")
    # stamps that really repeat stay the reader's own error
    t[5] = t[4]
    rc, err = calibrate(capsys, write(tmp_path / "dup.csv", t, g, a))
    assert rc == 2 and "TimestampError" in err and "duplicates the previous row's timestamp" in err, err


# 2. acc unit -------------------------------------------------------------------------------------
def test_acc_in_g_read_as_mps2(tmp_path, capsys):
    t, g, a = samples()
    err = refused(capsys, write(tmp_path / "g.csv", t, g, a / G))
    assert "|acc| at rest is 1 m/s2" in err and err.rstrip().endswith("add --acc-unit g")


def test_acc_in_mps2_read_as_g(tmp_path, capsys):
    t, g, a = samples()
    err = refused(capsys, write(tmp_path / "mps2.csv", t, g, a), "--acc-unit", "g")
    assert "with --acc-unit g, near 9.81 g" in err and err.rstrip().endswith("add --acc-unit m/s2")


# 3. gyro unit ------------------------------------------------------------------------------------
def test_gyro_in_deg_read_as_rad(tmp_path, capsys):
    t, g, a = samples()
    err = refused(capsys, write(tmp_path / "deg.csv", t, np.degrees(g), a))
    assert "faster than an IMU turns" in err and err.rstrip().endswith("add --gyro-unit deg/s")
    # at rest alone: the gyro's noise, 57 times a gyro's in rad/s, gives it away
    t, g, a = samples(seconds_still=15.0, seconds_moving=0.0)
    g = g + np.random.default_rng(1).normal(0, 0.02, g.shape)  # 0.02 deg/s of noise... in deg/s
    err = refused(capsys, write(tmp_path / "deg_rest.csv", t, np.degrees(g), a))
    assert "noise at rest" in err and err.rstrip().endswith("add --gyro-unit deg/s")


def test_gyro_in_rad_read_as_deg_is_a_warning(tmp_path, caplog):
    t, g, a = samples()
    f = write(tmp_path / "rad.csv", t, g, a)
    with caplog.at_level(logging.WARNING, logger="imu_learn"):
        read_imu_source(f, columns=CsvColumns(MAP, gyro_unit="deg/s"))
    assert [r.levelno for r in caplog.records] == [logging.WARNING]
    assert "drop --gyro-unit deg/s" in caplog.records[0].getMessage()


# 4. gyro and acc swapped -------------------------------------------------------------------------
def test_gyro_and_acc_swapped(tmp_path, capsys):
    t, g, a = samples()
    f = write(tmp_path / "swap.csv", t, a, g, header="t,ax,ay,az,gx,gy,gz")
    err = refused(capsys, f, "--columns", MAP)
    assert "gyro and acc look swapped" in err and "--columns t,ax,ay,az,gx,gy,gz" in err
    # the same in g and deg/s
    f = write(tmp_path / "swap2.csv", t, a / G, np.degrees(g))
    err = refused(capsys, f, "--gyro-unit", "deg/s", "--acc-unit", "g")
    assert "gyro and acc look swapped" in err
    # moving throughout, turning at ~11 deg/s: the swapped acc columns read ~11 g, as m/s2 read as g would; their
    # magnitude spreads as a rate's and the gyro columns' holds as gravity's, so it is the swap that is named
    t, g, a = samples(seconds_still=0.0)
    slow = g * 0.15
    assert 8 < np.median(np.linalg.norm(np.degrees(slow), axis=1)) < 14
    err = refused(capsys, write(tmp_path / "swap3.csv", t, a / G, np.degrees(slow)), "--gyro-unit", "deg/s",
                  "--acc-unit", "g")
    assert "gyro and acc look swapped" in err and "--acc-unit m/s2" not in err
    rc, err = calibrate(capsys, write(tmp_path / "right.csv", t, np.degrees(slow), a / G), "--gyro-unit", "deg/s",
                        "--acc-unit", "g")
    # the same motion in the right columns passes the checks (and, never at rest, measures no noise: refused as that)
    assert rc == 2 and "swapped" not in err and "NothingObservedError" in err and err.count("\n") == 1, err


# 5. a constant or integer column -----------------------------------------------------------------
def test_a_constant_column_on_an_axis(tmp_path, capsys):
    t, g, a = samples()
    extra = np.c_[np.full(len(t), 25.0), np.random.default_rng(2).normal(0, 1, len(t))]
    f = write(tmp_path / "const.csv", t, g, a, header="time,wx,wy,wz,ax,ay,az,temp,other", extra=extra)
    err = refused(capsys, f, "--columns", "t,gx,gy,gz,ax,ay,_,az")
    assert "column 8 (temp as az) holds 25 on every line" in err and "fix --columns" in err


def test_an_integer_column_on_an_axis(tmp_path, capsys):
    t, g, a = samples()
    counts = np.round(a * 1000 / G)  # raw counts in mg
    err = refused(capsys, write(tmp_path / "counts.csv", t, g, counts))
    assert "column 5 (ax) holds integers only" in err and "fix --columns" in err


# 6. more columns than the default map names ------------------------------------------------------
def test_more_columns_than_the_default_map_names(tmp_path, capsys):
    t, g, a = samples()
    rng = np.random.default_rng(3)
    extra = rng.normal(0, 1, (len(t), 10))
    names = "timestamp,mag_x,mag_y,mag_z,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z," + ",".join(
        f"aux{i}" for i in range(7))
    body = np.c_[extra[:, :3], g, a, extra[:, 3:]]
    f = tmp_path / "wide.csv"
    f.write_text(names + "\n" + "\n".join(",".join([str(int(ti))] + [repr(float(x)) for x in row])
                                          for ti, row in zip(t, body)) + "\n")
    err = refused(capsys, f, "--acc-unit", "m/s2")
    assert "wide.csv: has 17 columns; name them with --columns (e.g. --columns t,_,_,_,gx,gy,gz,ax,ay,az:" in err
    # named, it reads
    src = read_imu_source(f, columns=CsvColumns("t,_,_,_,gx,gy,gz,ax,ay,az"))
    np.testing.assert_allclose(src.acc, a, rtol=1e-15)


# 7. --skip-bad-lines -----------------------------------------------------------------------------
def test_skip_bad_lines(tmp_path, capsys, caplog):
    t, g, a = samples()
    f = write(tmp_path / "log.csv", t, g, a)
    lines = f.read_text().splitlines()
    lines.insert(1, "60000,0.01,-0.0")  # the logger's first line, cut at its start
    lines.append(f"{t[-1] + 5_000_000},0.0100,-0.00")  # its last line, cut by the power going off
    f.write_text("\n".join(lines))
    n = len(lines)
    # without the flag: the exact error, naming file, line and field
    rc, err = calibrate(capsys, f)
    assert rc == 2 and err.startswith("imu-learn calibrate: error: ColumnCountError: ")
    assert "log.csv:2:4: field \"gz\" is missing" in err
    with pytest.raises(ColumnCountError):
        read_imu_source(f, columns=CsvColumns())
    # with it: both skipped, counted in a warning and on the source
    layout = CsvColumns(skip_bad_lines=True)
    with caplog.at_level(logging.WARNING, logger="imu_learn"):
        src = read_imu_source(f, columns=layout)
    assert src.skipped_lines == (2, n)
    np.testing.assert_array_equal(src.t_ns, t)
    msg = caplog.records[0].getMessage()
    assert "skipped 2 bad lines (--skip-bad-lines)" in msg and f"log.csv:{n}:4: field \"gz\" is missing" in msg
    # the writer keeps them as they were
    out = tmp_path / "out.csv"
    write_imu(src, out, src.gyro * 2, src.acc)
    back = out.read_text().splitlines()
    assert back[1] == lines[1] and back[-1] == lines[-1] and back[0] == lines[0]
    np.testing.assert_allclose(read_imu_source(out, columns=layout).gyro, 2 * src.gyro, rtol=1e-15)
    # the CLI's flag
    rc, err = calibrate(capsys, f, "--skip-bad-lines")
    assert rc == 0 and err.startswith(f"imu-learn calibrate: warning: {f}: skipped 2 bad lines"), err


def test_the_low_level_reader_stays_as_it_was(tmp_path):
    """read_csv_columns (no checks) still reads what the checks refuse: the checks live in one place."""
    t, g, a = samples()
    f = write(tmp_path / "g.csv", t, g, a / G)
    assert len(read_csv_columns(f)) == len(t)
    with pytest.raises(ImplausibleInputError) as e:
        read_imu_source(f, columns=CsvColumns())
    assert e.value.option == "--acc-unit"


def test_a_cut_last_line_and_a_csv_without_its_map_name_the_option(tmp_path, capsys):
    """A line cut short stops in one line that, where it is the file's first or last, names --skip-bad-lines; a CSV of
    one's own given without --columns (read as EuRoC's layout) names --columns and the unit options."""
    t, g, a = samples()
    f = write(tmp_path / "cut.csv", t, g, a)
    f.write_text(f.read_text() + f"{t[-1] + 5_000_000},0.1,0.2\n")
    rc, err = calibrate(capsys, f, "--columns", MAP, "--time-unit", "ns")
    assert rc == 2 and "ColumnCountError" in err and "--skip-bad-lines" in err and err.count("\n") == 1, err
    inner = write(tmp_path / "inner.csv", t, g, a)
    lines = inner.read_text().splitlines()
    lines[100] = ",".join(lines[100].split(",")[:3])
    inner.write_text("\n".join(lines) + "\n")
    rc, err = calibrate(capsys, inner, "--columns", MAP, "--time-unit", "ns")
    assert rc == 2 and "ColumnCountError" in err and "--skip-bad-lines" not in err, err
    first = write(tmp_path / "first.csv", t, g, a)  # a logger started mid-line (the GNSS/IMU walk's log)
    lines = first.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line[:1].isdigit())
    lines[k] = ",".join(lines[k].split(",")[3:])
    first.write_text("\n".join(lines) + "\n")
    rc, err = calibrate(capsys, first, "--columns", MAP, "--time-unit", "ns")
    assert rc == 2 and "ColumnCountError" in err and "first line" in err and "--skip-bad-lines" in err, err
    rc = main(["calibrate", "--imu-only", "--input", str(write(tmp_path / "own.csv", t, g, a)), "--out",
               str(tmp_path / "o"), "--no-plot", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "HeaderError" in err and "--columns" in err and "--time-unit" in err, err


def test_a_decimal_comma_is_named(tmp_path, capsys):
    """A spreadsheet in a locale with decimal commas (fields split by ';'): the one line names the likely cause."""
    t, g, a = samples()
    f = write(tmp_path / "comma.csv", t, g, a, header="t;gx;gy;gz;ax;ay;az")
    text = f.read_text().splitlines()
    rows = [text[0]] + [";".join(x.replace(".", ",") for x in line.split(",")) for line in text[1:]]
    f.write_text("\n".join(rows) + "\n")
    rc, err = calibrate(capsys, f, "--columns", MAP)
    assert rc == 2 and err.count("\n") == 1 and err.startswith("imu-learn calibrate: error: NotNumericError: "), err
    assert ":2:2: " in err and "is not a number; a decimal comma?" in err and "'.' as the decimal separator" in err


def test_a_hand_held_rest_in_rad_s_is_not_taken_for_deg_s(shared, capsys):
    """TUM-VI's rig held in a hand at its start (a rest the accelerometer finds, the gyro turning 0.058 rad/s):
    its gyro, in rad/s, was refused as deg/s with no way round (its spread, not its white noise, was judged);
    every room read through a column map passes the unit checks, and deg/s read as rad/s is still refused."""
    from imu_learn.data.formats.input_checks import white_noise

    room = shared / "tum-vi" / "dataset-room1_512_16" / "mav0"
    if not room.exists():
        pytest.skip(f"{room} not present")
    rc = main(["groundtruth", "--input", str(room / "imu0" / "data.csv"), "--columns", "t,gx,gy,gz,ax,ay,az",
               "--groundtruth", str(room / "mocap0" / "data.csv")])
    out, err = capsys.readouterr()
    assert rc == 0 and "ImplausibleInputError" not in err, err
    # the estimator: white noise kept, a slow turn left out
    rng, k = np.random.default_rng(0), np.arange(4000)
    white = rng.normal(0, 0.03, (4000, 3))
    slow = 0.08 * np.sin(2 * np.pi * k[:, None] / 200.0 * np.array([0.5, 0.8, 1.1]))
    assert abs(white_noise(white, k) - 0.03) < 0.002 and white_noise(slow + 0.001 * white, k) < 0.005
    assert white_noise(white, k[::2]) == 0.0  # no two consecutive samples: nothing measured


def test_missing_samples_are_a_warning_naming_where(tmp_path, caplog):
    """A logger that dropped a second of rows (TUM-VI's room 1 with 200 rows cut: translation over 200 samples
    0.030 -> 0.262 m) passed without a word; a gap of a few samples (EuRoC drops one now and then) stays silent."""
    t, g, a = samples()
    keep = np.r_[0:1000, 1200:len(t)]
    with caplog.at_level(logging.WARNING, logger="imu_learn"):
        read_imu_source(write(tmp_path / "gap.csv", t[keep], g[keep], a[keep]), columns=CsvColumns(MAP))
    msgs = [r.getMessage() for r in caplog.records]
    assert len(msgs) == 1 and "1 gap(s) in the stamps longer than 10 samples, the longest 1.01 s after sample 1000" in \
        msgs[0], msgs
    caplog.clear()
    few = np.r_[0:1000, 1003:len(t)]
    with caplog.at_level(logging.WARNING, logger="imu_learn"):
        read_imu_source(write(tmp_path / "few.csv", t[few], g[few], a[few]), columns=CsvColumns(MAP))
    assert caplog.records == []


ASL_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],"
              "a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")


@pytest.mark.parametrize("name, edit, says, option", [
    ("degs", lambda t, g, a: (t, np.degrees(g), a), "the gyro columns look like deg/s", "--gyro-unit"),
    ("g", lambda t, g, a: (t, g, a / G), "the acc columns look like units of g", "--acc-unit"),
    ("ms", lambda t, g, a: (t // 1_000_000, g, a), "they look like milliseconds", "--time-unit"),
])
def test_an_asl_file_in_other_units_is_named_before_any_work(tmp_path, capsys, caplog, name, edit, says, option):
    """An IMU CSV under EuRoC's header (ns, rad/s, m/s^2) whose numbers are a logger's deg/s, g or ms: refine
    wrote it with a statistics warning, labels built a cache from it. Now the user-CSV checks that decide
    stop the read in one line naming the unit and how to read the file as a CSV of one's own; the file in
    its own units passes without a word."""
    t, g, a = samples()
    good = write(tmp_path / "good.csv", t, g, a, header=ASL_HEADER)
    with caplog.at_level(logging.WARNING):
        read_imu_source(good)
    assert not caplog.records
    bad = write(tmp_path / f"{name}.csv", *edit(t, g, a), header=ASL_HEADER)
    with pytest.raises(ImplausibleInputError, match=says) as e:
        read_imu_source(bad)
    assert e.value.option == option and "--columns t,gx,gy,gz,ax,ay,az" in str(e.value)
    rc = main(["refine", "--input", str(bad), "--profile", str(REPO / "models/profiles/euroc_adis16448/profile.json"),
               "--out", str(tmp_path / "out.csv")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and says in err[0] and not (tmp_path / "out.csv").exists(), err


def test_refine_replaces_its_own_output_never_a_users_file(tmp_path, capsys):
    """--out naming an existing file that refine did not write (no summary beside it) was overwritten without
    a word; refine's own earlier output (its summary beside it) is replaced as before."""
    t, g, a = samples()
    src = write(tmp_path / "imu.csv", t, g, a, header=ASL_HEADER)
    mine = tmp_path / "mine.csv"
    mine.write_text("precious\n")
    profile = str(REPO / "models/profiles/euroc_adis16448/profile.json")
    assert main(["refine", "--input", str(src), "--profile", profile, "--out", str(mine)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "exists and is not an earlier refine output" in err[0], err
    assert mine.read_text() == "precious\n"
    out = tmp_path / "out.csv"
    assert main(["refine", "--input", str(src), "--profile", profile, "--out", str(out)]) == 0
    assert main(["refine", "--input", str(src), "--profile", profile, "--out", str(out)]) == 0  # its own: replaced


def test_refine_names_an_unwritable_out_before_the_work(tmp_path, capsys, monkeypatch):
    """A read-only OUT failed with PermissionError after the whole inference; it is named first (the check
    is os.access, which a root test process passes: the test makes it say no)."""
    t, g, a = samples()
    src = write(tmp_path / "imu.csv", t, g, a, header=ASL_HEADER)
    monkeypatch.setattr(rewrite.os, "access", lambda *_: False)
    called = []
    monkeypatch.setattr(rewrite, "summary_path", lambda *a: called.append(a) or tmp_path / "x")
    rc = main(["refine", "--input", str(src), "--profile", str(REPO / "models/profiles/euroc_adis16448/profile.json"),
               "--out", str(tmp_path / "ro" / "out.csv")])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert rc == 2 and len(err) == 1 and "cannot be written" in err[0] and not called, err


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc, a folder nothing can be made in")
def test_an_out_where_nothing_can_be_made_is_named_before_the_work(tmp_path, capsys):
    """--out /proc/nope passed os.access as root and failed after the work, naming a staging folder."""
    assert can_create_in(tmp_path) and not can_create_in(Path("/proc"))
    with pytest.raises(PermissionError, match="cannot be written"):
        check_writable(Path("/proc/nope"))


def test_a_folder_with_a_users_csv_option_names_its_imu_file(tmp_path):
    """``--skip-bad-lines`` (or any option of a user's CSV) on a recording's folder: one line naming the
    options and the IMU file inside to give instead (not --columns alone: none was given)."""
    imu = tmp_path / "rec" / "mav0" / "imu0" / "data.csv"
    imu.parent.mkdir(parents=True)
    imu.write_text("t,gx,gy,gz,ax,ay,az\n")
    with pytest.raises(InvalidInputError) as e:
        read_imu_source(tmp_path / "rec", columns=CsvColumns(skip_bad_lines=True, columns_named=False))
    msg = str(e.value)
    assert "--skip-bad-lines" in msg and str(imu) in msg and "give its IMU file as --input" in msg, msg


def test_an_out_naming_a_file_of_another_format_is_refused(tmp_path, capsys):
    """OUT ``um.hdf5`` for a CSV input: refused in one line (it was made a folder named um.hdf5 holding a CSV)."""
    src = tmp_path / "imu.csv"
    rng = np.random.default_rng(0)
    g, a = 0.01 + 1e-3 * rng.standard_normal((400, 3)), np.array([0.1, 0.2, 9.8]) + 0.01 * rng.standard_normal((400, 3))
    src.write_text("t,gx,gy,gz,ax,ay,az\n" + "".join(f"{i * 5_000_000},{','.join(f'{v:.6f}' for v in (*g[i], *a[i]))}\n"
                                                       for i in range(400)))
    out = tmp_path / "um.hdf5"
    profile = Path(__file__).resolve().parents[1] / "models" / "profiles" / "euroc_adis16448" / "profile.json"
    assert main(["refine", "--profile", str(profile), "--input", str(src), "--columns", "t,gx,gy,gz,ax,ay,az",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "names a .hdf5 file" in err and "give OUT ending in .csv or a folder" in err, err
    assert not out.exists()
