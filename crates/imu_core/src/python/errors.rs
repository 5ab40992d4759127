//! Core errors → Python exceptions. The classes live in `imu_learn.errors` (plain Python, so
//! they can inherit from both `ImuError` and `ValueError`) and are imported here with pyo3's
//! `import_exception!`: each core variant is raised as its own class, directly, carrying
//! path/line/column/field as attributes. A missing file is the built-in `FileNotFoundError`.

use pyo3::exceptions::{PyFileNotFoundError, PyOSError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use pyo3::PyTypeInfo;

use std::path::Path;

use crate::align::Sources;
use crate::error::ImuError;

pyo3::import_exception!(imu_learn.errors, HeaderError);
pyo3::import_exception!(imu_learn.errors, ColumnCountError);
pyo3::import_exception!(imu_learn.errors, NotNumericError);
pyo3::import_exception!(imu_learn.errors, NonFiniteError);
pyo3::import_exception!(imu_learn.errors, TimestampError);
pyo3::import_exception!(imu_learn.errors, FloatTimestampError);
pyo3::import_exception!(imu_learn.errors, TooFewRowsError);
pyo3::import_exception!(imu_learn.errors, AlignmentError);
pyo3::import_exception!(imu_learn.errors, NoOverlapError);
pyo3::import_exception!(imu_learn.errors, InvalidInputError);

/// Convert a core error to the exception of its kind.
pub fn to_py(err: ImuError) -> PyErr {
    Python::with_gil(|py| build(py, &err).unwrap_or_else(|e| e))
}

/// Convert an error of `align_from`: alignment errors get the source files as attributes
/// (`path` the ground truth, `imu_path` the IMU), whichever variant raised them.
pub fn alignment_to_py(err: ImuError, sources: &Sources) -> PyErr {
    let (imu, gt) = (sources.imu.as_deref(), sources.gt.as_deref());
    match err {
        ImuError::Alignment(_) => Python::with_gil(|py| {
            py.import("imu_learn.errors")
                .and_then(|_| alignment_error::<AlignmentError>(py, &err.to_string(), imu, gt))
                .unwrap_or_else(|e| e)
        }),
        _ => to_py(err),
    }
}

/// An `AlignmentError` (or subclass) with its `path` (ground truth) and `imu_path`.
fn alignment_error<T: PyTypeInfo>(py: Python<'_>, msg: &str, imu: Option<&Path>, gt: Option<&Path>) -> PyResult<PyErr> {
    let kw = PyDict::new(py);
    kw.set_item("path", gt.map(|p| p.display().to_string()))?;
    kw.set_item("imu_path", imu.map(|p| p.display().to_string()))?;
    Ok(PyErr::from_value(T::type_object(py).call((msg,), Some(&kw))?))
}

/// A `ParseError` subclass located at path:line[:column] in `field`.
fn parse_error<T: PyTypeInfo>(
    py: Python<'_>,
    msg: String,
    path: &Path,
    line: usize,
    column: Option<usize>,
    field: Option<&str>,
) -> PyResult<PyErr> {
    let kw = PyDict::new(py);
    kw.set_item("path", path.display().to_string())?;
    kw.set_item("line", line)?;
    kw.set_item("column", column)?;
    kw.set_item("field", field)?;
    Ok(PyErr::from_value(T::type_object(py).call((msg,), Some(&kw))?))
}

fn build(py: Python<'_>, err: &ImuError) -> PyResult<PyErr> {
    // The imported classes panic if their module cannot load; fail with the ImportError instead.
    py.import("imu_learn.errors")?;
    let msg = err.to_string();
    match err {
        ImuError::NotFound { path } => Ok(PyFileNotFoundError::new_err((
            2,
            "No such file or directory",
            path.display().to_string(),
        ))),
        ImuError::Io { .. } => Ok(PyOSError::new_err(msg)),
        ImuError::Header { path, line, .. } => parse_error::<HeaderError>(py, msg, path, *line, None, None),
        ImuError::ColumnCount { path, line, .. } => parse_error::<ColumnCountError>(py, msg, path, *line, None, None),
        ImuError::MissingColumn {
            path,
            line,
            column,
            field,
            ..
        } => parse_error::<ColumnCountError>(py, msg, path, *line, Some(*column), Some(field)),
        ImuError::NotNumeric {
            path,
            line,
            column,
            field,
            ..
        } => parse_error::<NotNumericError>(py, msg, path, *line, Some(*column), Some(field)),
        ImuError::NonFinite {
            path,
            line,
            column,
            field,
            ..
        } => parse_error::<NonFiniteError>(py, msg, path, *line, Some(*column), Some(field)),
        ImuError::Timestamp {
            path,
            line,
            column,
            field,
            ..
        } => parse_error::<TimestampError>(py, msg, path, *line, Some(*column), Some(field)),
        ImuError::FloatTimestamp {
            path,
            line,
            column,
            field,
            ..
        } => parse_error::<FloatTimestampError>(py, msg, path, *line, Some(*column), Some(field)),
        ImuError::TooFewRows { path, line, .. } => parse_error::<TooFewRowsError>(py, msg, path, *line, None, None),
        ImuError::NoOverlap { imu, gt, .. } => {
            alignment_error::<NoOverlapError>(py, &msg, imu.as_deref(), gt.as_deref())
        }
        ImuError::Alignment(_) => Ok(AlignmentError::new_err(msg)),
        ImuError::InvalidInput(_) | ImuError::UnknownUnit { .. } => Ok(InvalidInputError::new_err(msg)),
    }
}
