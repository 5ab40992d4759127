//! File readers and writers.

use std::path::PathBuf;

use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyOverflowError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::ImuError;
use crate::io::columns::{self, CsvFormat};
use crate::io::table::{parse_decimal, Decimal};
use crate::io::tum::{TrajectoryLayout, TrajectoryOptions};
use crate::io::{asl, kaist, tum, ReadOptions};
use crate::python::arrays::{out1, out2, rows, slice1};
use crate::python::errors::to_py;
use crate::types::{GroundTruth, ImuSamples};

type ImuArrays<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray2<f64>>,
);

fn opts(allow_float_timestamps: bool) -> ReadOptions {
    ReadOptions { allow_float_timestamps }
}

fn imu_out(py: Python<'_>, s: ImuSamples) -> PyResult<ImuArrays<'_>> {
    Ok((out1(py, s.t_ns), out2(py, s.gyro)?, out2(py, s.acc)?))
}

fn gt_out(py: Python<'_>, g: GroundTruth) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("t_ns", out1(py, g.t_ns))?;
    d.set_item("p", out2(py, g.p)?)?;
    d.set_item("q_wxyz", out2(py, g.q_wxyz)?)?;
    d.set_item("v", g.v.map(|v| out2(py, v)).transpose()?)?;
    d.set_item("bias_gyro", g.bias_gyro.map(|v| out2(py, v)).transpose()?)?;
    d.set_item("bias_acc", g.bias_acc.map(|v| out2(py, v)).transpose()?)?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_asl_imu(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<ImuArrays<'_>> {
    let s = py
        .allow_threads(|| asl::read_imu(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    imu_out(py, s)
}

#[pyfunction]
fn read_asl_imu_header(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    py.allow_threads(|| asl::read_imu_header(&path)).map_err(to_py)
}

#[pyfunction]
#[pyo3(signature = (path, t_ns, gyro, acc, header=None, crlf=false))]
fn write_asl_imu(
    py: Python<'_>,
    path: PathBuf,
    t_ns: PyReadonlyArray1<'_, i64>,
    gyro: PyReadonlyArray2<'_, f64>,
    acc: PyReadonlyArray2<'_, f64>,
    header: Option<String>,
    crlf: bool,
) -> PyResult<()> {
    let s = ImuSamples {
        t_ns: slice1(&t_ns, "t_ns")?.to_vec(),
        gyro: rows::<3>(&gyro, "gyro")?.to_vec(),
        acc: rows::<3>(&acc, "acc")?.to_vec(),
    };
    py.allow_threads(|| asl::write_imu_lines(&path, &s, header.as_deref(), crlf))
        .map_err(to_py)
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_asl_state(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<Bound<'_, PyDict>> {
    let g = py
        .allow_threads(|| asl::read_state(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    gt_out(py, g)
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_asl_pose(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<Bound<'_, PyDict>> {
    let g = py
        .allow_threads(|| asl::read_pose(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    gt_out(py, g)
}

/// Stamps [ns] and positions (N, 3) as numpy arrays.
type StampedPositions<'py> = (Bound<'py, PyArray1<i64>>, Bound<'py, PyArray2<f64>>);

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_asl_position(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<StampedPositions<'_>> {
    let (t, p) = py
        .allow_threads(|| asl::read_position(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    Ok((out1(py, t), out2(py, p)?))
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_tum(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<Bound<'_, PyDict>> {
    let g = py
        .allow_threads(|| tum::read_tum(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    gt_out(py, g)
}

/// A trajectory (aiding) file -> {t_ns, p, q_wxyz (None for positions only), lines}.
#[pyfunction]
#[pyo3(signature = (path, layout="tum", positions_only=false, allow_float_timestamps=false))]
fn read_trajectory<'py>(
    py: Python<'py>,
    path: PathBuf,
    layout: &str,
    positions_only: bool,
    allow_float_timestamps: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = TrajectoryOptions {
        layout: TrajectoryLayout::parse(layout).map_err(to_py)?,
        positions_only,
        allow_float_timestamps,
    };
    let t = py
        .allow_threads(|| tum::read_trajectory(&path, &opts))
        .map_err(|e| with_details(py, e))?;
    let d = PyDict::new(py);
    d.set_item("t_ns", out1(py, t.t_ns))?;
    d.set_item("p", out2(py, t.p)?)?;
    d.set_item("q_wxyz", t.q_wxyz.map(|q| out2(py, q)).transpose()?)?;
    let lines: Vec<i64> = t.lines.into_iter().map(|l| l as i64).collect();
    d.set_item("lines", out1(py, lines))?;
    Ok(d)
}

/// The Python error for `err`, with what the error holds beyond its place as attributes, for a
/// caller that words its own message: `value` (the field's text; the stamp [ns] for a
/// `TimestampError`), `previous` (the stamp before it [ns]), `expected` and `found` (column
/// counts; `found` rows for a `TooFewRowsError`).
fn with_details(py: Python<'_>, err: ImuError) -> PyErr {
    enum Attr {
        Text(String),
        Int(i64),
        Count(usize),
    }
    let attrs: Vec<(&str, Attr)> = match &err {
        ImuError::NotNumeric { value, .. }
        | ImuError::NonFinite { value, .. }
        | ImuError::FloatTimestamp { value, .. } => vec![("value", Attr::Text(value.clone()))],
        ImuError::Timestamp { value, previous, .. } => {
            vec![("value", Attr::Int(*value)), ("previous", Attr::Int(*previous))]
        }
        ImuError::ColumnCount { expected, found, .. } => {
            vec![("expected", Attr::Count(*expected)), ("found", Attr::Count(*found))]
        }
        ImuError::TooFewRows { found, .. } => vec![("found", Attr::Count(*found))],
        _ => Vec::new(),
    };
    let e = to_py(err);
    let obj = e.value(py);
    for (name, value) in attrs {
        // An exception that refuses an attribute is still the right exception.
        let _ = match value {
            Attr::Text(s) => obj.setattr(name, s),
            Attr::Int(i) => obj.setattr(name, i),
            Attr::Count(n) => obj.setattr(name, n),
        };
    }
    e
}

/// Decimal seconds as integer ns, by the readers' rule (exact, half to even past the ns).
#[pyfunction]
fn seconds_to_ns(text: &str) -> PyResult<i64> {
    let s = text.trim();
    match parse_decimal(s.as_bytes(), 9) {
        Decimal::Int(n) | Decimal::Frac(n) => Ok(n),
        Decimal::OutOfRange => Err(PyOverflowError::new_err(format!("{s:?} s is out of the ns range"))),
        Decimal::Invalid => match fast_float2::parse::<f64, _>(s) {
            Ok(x) if !x.is_finite() => Err(PyOverflowError::new_err(format!("{s:?} is not finite"))),
            _ => Err(PyValueError::new_err(format!("{s:?} is not a number of seconds"))),
        },
    }
}

#[pyfunction]
fn write_tum(
    py: Python<'_>,
    path: PathBuf,
    t_ns: PyReadonlyArray1<'_, i64>,
    p: PyReadonlyArray2<'_, f64>,
    q_wxyz: PyReadonlyArray2<'_, f64>,
) -> PyResult<()> {
    let g = GroundTruth {
        t_ns: slice1(&t_ns, "t_ns")?.to_vec(),
        p: rows::<3>(&p, "p")?.to_vec(),
        q_wxyz: rows::<4>(&q_wxyz, "q_wxyz")?.to_vec(),
        ..Default::default()
    };
    py.allow_threads(|| tum::write_tum(&path, &g)).map_err(to_py)
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_kaist_imu(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<ImuArrays<'_>> {
    let s = py
        .allow_threads(|| kaist::read_xsens_imu(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    imu_out(py, s)
}

#[pyfunction]
#[pyo3(signature = (path, allow_float_timestamps=false))]
fn read_kaist_pose(py: Python<'_>, path: PathBuf, allow_float_timestamps: bool) -> PyResult<Bound<'_, PyDict>> {
    let g = py
        .allow_threads(|| kaist::read_global_pose(&path, &opts(allow_float_timestamps)))
        .map_err(to_py)?;
    gt_out(py, g)
}

#[pyfunction]
fn read_csv_columns<'py>(
    py: Python<'py>,
    path: PathBuf,
    columns: &str,
    time_unit: &str,
    gyro_unit: &str,
    acc_unit: &str,
) -> PyResult<ImuArrays<'py>> {
    let fmt = CsvFormat::parse(columns, time_unit, gyro_unit, acc_unit).map_err(to_py)?;
    let s = py.allow_threads(|| columns::read_imu(&path, &fmt)).map_err(to_py)?;
    imu_out(py, s)
}

/// A user's CSV with what the plausibility checks need: {t_ns, gyro, acc, skipped: [(line, problem)],
/// names: [str], fields: int}.
#[pyfunction]
#[pyo3(signature = (path, columns, time_unit, gyro_unit, acc_unit, skip_bad_lines=false))]
fn read_csv_columns_checked<'py>(
    py: Python<'py>,
    path: PathBuf,
    columns: &str,
    time_unit: &str,
    gyro_unit: &str,
    acc_unit: &str,
    skip_bad_lines: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let fmt = CsvFormat::parse(columns, time_unit, gyro_unit, acc_unit)
        .map_err(to_py)?
        .with_skip_bad_lines(skip_bad_lines);
    let r = py
        .allow_threads(|| columns::read_imu_checked(&path, &fmt))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("t_ns", out1(py, r.samples.t_ns))?;
    d.set_item("gyro", out2(py, r.samples.gyro)?)?;
    d.set_item("acc", out2(py, r.samples.acc)?)?;
    let skipped: Vec<(usize, String)> = r.skipped.into_iter().map(|s| (s.line, s.problem)).collect();
    d.set_item("skipped", skipped)?;
    d.set_item("names", r.names)?;
    d.set_item("fields", r.fields)?;
    Ok(d)
}

#[pyfunction]
#[pyo3(signature = (original, out, gyro, acc, columns, time_unit, gyro_unit, acc_unit, skip_bad_lines=false))]
#[allow(clippy::too_many_arguments)]
fn write_csv_columns(
    py: Python<'_>,
    original: PathBuf,
    out: PathBuf,
    gyro: PyReadonlyArray2<'_, f64>,
    acc: PyReadonlyArray2<'_, f64>,
    columns: &str,
    time_unit: &str,
    gyro_unit: &str,
    acc_unit: &str,
    skip_bad_lines: bool,
) -> PyResult<()> {
    let fmt = CsvFormat::parse(columns, time_unit, gyro_unit, acc_unit)
        .map_err(to_py)?
        .with_skip_bad_lines(skip_bad_lines);
    let (g, a) = (rows::<3>(&gyro, "gyro")?, rows::<3>(&acc, "acc")?);
    py.allow_threads(|| columns::write_imu(&original, &out, &fmt, g, a))
        .map_err(to_py)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_csv_columns, m)?)?;
    m.add_function(wrap_pyfunction!(read_csv_columns_checked, m)?)?;
    m.add_function(wrap_pyfunction!(write_csv_columns, m)?)?;
    m.add_function(wrap_pyfunction!(read_asl_imu, m)?)?;
    m.add_function(wrap_pyfunction!(read_asl_imu_header, m)?)?;
    m.add_function(wrap_pyfunction!(write_asl_imu, m)?)?;
    m.add_function(wrap_pyfunction!(read_asl_state, m)?)?;
    m.add_function(wrap_pyfunction!(read_asl_pose, m)?)?;
    m.add_function(wrap_pyfunction!(read_asl_position, m)?)?;
    m.add_function(wrap_pyfunction!(read_tum, m)?)?;
    m.add_function(wrap_pyfunction!(read_trajectory, m)?)?;
    m.add_function(wrap_pyfunction!(seconds_to_ns, m)?)?;
    m.add_function(wrap_pyfunction!(write_tum, m)?)?;
    m.add_function(wrap_pyfunction!(read_kaist_imu, m)?)?;
    m.add_function(wrap_pyfunction!(read_kaist_pose, m)?)?;
    Ok(())
}
