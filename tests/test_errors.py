"""Every bad input gets its own exception class, naming file, line, column and field."""
import numpy as np
import pytest

import imu_learn as il
from imu_learn import _imu_core as core

HEADER = "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]\n"
ROW = "{t},0.1,0.2,0.3,9.0,0.1,0.2\n"


def write(tmp_path, body, header=HEADER):
    p = tmp_path / "data.csv"
    p.write_text(header + body)
    return p


def rows(ts):
    return "".join(ROW.format(t=t) for t in ts)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        il.read_imu(tmp_path / "nope.csv")


def test_wrong_header(tmp_path):
    p = write(tmp_path, rows([1, 2]), header="#timestamp,gx,gy,gz,ax,ay,az\n")
    with pytest.raises(il.HeaderError) as e:
        il.read_imu(p)
    assert e.value.line == 1 and str(p) in str(e.value)


def test_column_count(tmp_path):
    p = write(tmp_path, rows([1]) + "2,0.1,0.2,0.3,9.0,0.1\n")
    with pytest.raises(il.ColumnCountError) as e:
        il.read_imu(p)
    assert e.value.line == 3
    assert "3" in str(e.value) and str(p) in str(e.value)


def test_not_numeric_names_line_column_field(tmp_path):
    p = write(tmp_path, rows([1]) + "2,0.1,abc,0.3,9.0,0.1,0.2\n")
    with pytest.raises(il.NotNumericError) as e:
        il.read_imu(p)
    err = e.value
    assert (err.line, err.column) == (3, 3)
    assert "w_RS_S_y" in err.field and "w_RS_S_y" in str(err) and str(p) in str(err)
    assert isinstance(err, ValueError) and isinstance(err, il.ImuError)


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "NaN"])
def test_non_finite(tmp_path, bad):
    p = write(tmp_path, rows([1]) + f"2,0.1,0.2,0.3,{bad},0.1,0.2\n")
    with pytest.raises(il.NonFiniteError) as e:
        il.read_imu(p)
    assert (e.value.line, e.value.column) == (3, 5) and "a_RS_S_x" in e.value.field


def test_duplicate_timestamp(tmp_path):
    p = write(tmp_path, rows([1, 2, 2, 3]))
    with pytest.raises(il.TimestampError) as e:
        il.read_imu(p)
    assert e.value.line == 4 and "duplicate" in str(e.value).lower()


def test_decreasing_timestamp(tmp_path):
    p = write(tmp_path, rows([1, 5, 3]))
    with pytest.raises(il.TimestampError) as e:
        il.read_imu(p)
    assert e.value.line == 4 and "earlier" in str(e.value).lower()


def test_float_timestamps_rejected_then_accepted_with_option(shared):
    quirk = shared / "quirks" / "MH_01_easy_imu0_spreadsheet_export.csv"
    with pytest.raises(il.FloatTimestampError) as e:
        il.read_imu(quirk)
    assert e.value.line == 2 and "allow_float_timestamps" in str(e.value)
    imu = il.read_imu(quirk, allow_float_timestamps=True)
    clean = il.read_imu(shared / "euroc" / "MH_01_easy" / "mav0" / "imu0" / "data.csv")
    assert len(imu) == len(clean) == 36820
    np.testing.assert_array_equal(imu.t_ns, clean.t_ns)
    np.testing.assert_array_equal(imu.gyro, clean.gyro)


def test_alignment_without_overlap_is_alignment_error():
    t = np.arange(100, dtype=np.int64) * 5_000_000
    z = np.zeros((100, 3))
    q = np.tile([1.0, 0, 0, 0], (100, 1))
    imu = il.ImuData(t, z, z)
    gt = il.GroundTruth(t + 10**12, z, q)
    with pytest.raises(il.AlignmentError):
        il.align(imu, gt)


def test_shape_errors_are_invalid_input():
    with pytest.raises(il.InvalidInputError):
        core.preintegrate(np.zeros(3, dtype=np.int64), np.zeros((3, 4)), np.zeros((3, 3)))
    with pytest.raises(il.InvalidInputError):
        core.preintegrate(np.arange(3, dtype=np.int64), np.zeros((3, 3)), np.zeros((2, 3)))


@pytest.mark.parametrize("body,cls,where", [
    ("", "TooFewRowsError", (1, None, None)),
    (rows([1]) + "2,0.1,0.2,0.3,9.0,0.1\n", "ColumnCountError", (3, None, None)),
    (rows([1]) + "2,0.1,abc,0.3,9.0,0.1,0.2\n", "NotNumericError", (3, 3, "w_RS_S_y [rad s^-1]")),
    (rows([1]) + "2,0.1,0.2,0.3,nan,0.1,0.2\n", "NonFiniteError", (3, 5, "a_RS_S_x [m s^-2]")),
    (rows([5, 5]), "TimestampError", (3, 1, "timestamp [ns]")),
])
def test_core_raises_the_classes_of_errors_py_directly(tmp_path, body, cls, where):
    """The Rust core raises the classes defined in imu_learn.errors (pyo3 import_exception!), with
    path/line/column/field set, through the public reader and through _imu_core alike."""
    import imu_learn.errors as errors

    p = write(tmp_path, body)
    for read in (lambda: il.read_imu(p), lambda: core.read_asl_imu(str(p))):
        with pytest.raises(errors.ParseError) as e:
            read()
        assert type(e.value) is getattr(errors, cls)
        assert (e.value.path, (e.value.line, e.value.column, e.value.field)) == (str(p), where)
