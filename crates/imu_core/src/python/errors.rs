//! Core errors → Python exceptions. The classes live in `imu_learn.errors` (plain Python, so
//! they can inherit from both `ImuError` and `ValueError`); each variant maps to its own class
//! and carries path/line/column/field as attributes.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError, PyRuntimeError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use std::path::Path;

use crate::align::Sources;
use crate::error::ImuError;

/// Convert a core error, falling back to RuntimeError only if the errors module cannot load.
pub fn to_py(err: ImuError) -> PyErr {
    Python::with_gil(|py| build(py, &err).unwrap_or_else(|e| PyRuntimeError::new_err(format!("{err} ({e})"))))
}

/// Convert an error of `align_from`: alignment errors get the source files as attributes
/// (`path` the ground truth, `imu_path` the IMU), whichever variant raised them.
pub fn alignment_to_py(err: ImuError, sources: &Sources) -> PyErr {
    let (imu, gt) = (sources.imu.as_deref(), sources.gt.as_deref());
    let class = match err {
        ImuError::Alignment(_) => "AlignmentError",
        _ => return to_py(err),
    };
    Python::with_gil(|py| {
        alignment_error(py, class, &err.to_string(), imu, gt)
            .unwrap_or_else(|e| PyRuntimeError::new_err(format!("{err} ({e})")))
    })
}

fn alignment_error(py: Python<'_>, class: &str, msg: &str, imu: Option<&Path>, gt: Option<&Path>) -> PyResult<PyErr> {
    let cls = py.import("imu_learn.errors")?.getattr(class)?;
    let kw = PyDict::new(py);
    kw.set_item("path", gt.map(|p| p.display().to_string()))?;
    kw.set_item("imu_path", imu.map(|p| p.display().to_string()))?;
    Ok(PyErr::from_value(cls.call((msg,), Some(&kw))?))
}

fn build(py: Python<'_>, err: &ImuError) -> PyResult<PyErr> {
    let msg = err.to_string();
    let (class, path, line, column, field) = match err {
        ImuError::NotFound { path } => {
            return Ok(PyFileNotFoundError::new_err((
                2,
                "No such file or directory",
                path.display().to_string(),
            )))
        }
        ImuError::Io { .. } => return Ok(PyOSError::new_err(msg)),
        ImuError::Header { path, line, .. } => ("HeaderError", Some(path), Some(*line), None, None),
        ImuError::ColumnCount { path, line, .. } => ("ColumnCountError", Some(path), Some(*line), None, None),
        ImuError::NotNumeric {
            path,
            line,
            column,
            field,
            ..
        } => (
            "NotNumericError",
            Some(path),
            Some(*line),
            Some(*column),
            Some(field.as_str()),
        ),
        ImuError::NonFinite {
            path,
            line,
            column,
            field,
            ..
        } => (
            "NonFiniteError",
            Some(path),
            Some(*line),
            Some(*column),
            Some(field.as_str()),
        ),
        ImuError::Timestamp {
            path,
            line,
            column,
            field,
            ..
        } => (
            "TimestampError",
            Some(path),
            Some(*line),
            Some(*column),
            Some(field.as_str()),
        ),
        ImuError::FloatTimestamp {
            path,
            line,
            column,
            field,
            ..
        } => (
            "FloatTimestampError",
            Some(path),
            Some(*line),
            Some(*column),
            Some(field.as_str()),
        ),
        ImuError::TooFewRows { path, line, .. } => ("TooFewRowsError", Some(path), Some(*line), None, None),
        ImuError::NoOverlap { imu, gt, .. } => {
            return alignment_error(py, "NoOverlapError", &msg, imu.as_deref(), gt.as_deref())
        }
        ImuError::Alignment(_) => ("AlignmentError", None, None, None, None),
        ImuError::InvalidInput(_) => ("InvalidInputError", None, None, None, None),
    };
    let cls = py.import("imu_learn.errors")?.getattr(class)?;
    let value = if class.ends_with("Error") && path.is_some() {
        let kw = PyDict::new(py);
        kw.set_item("path", path.map(|p| p.display().to_string()))?;
        kw.set_item("line", line)?;
        kw.set_item("column", column)?;
        kw.set_item("field", field)?;
        cls.call((msg,), Some(&kw))?
    } else {
        cls.call1((msg,))?
    };
    Ok(PyErr::from_value(value))
}
