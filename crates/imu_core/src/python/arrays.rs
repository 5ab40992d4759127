//! numpy ↔ Rust without copies: inputs are borrowed as `&[[f64; 3]]` views of C-contiguous
//! arrays; outputs move their `Vec` into numpy (`into_pyarray`), so nothing is copied either way.

use numpy::ndarray::{Array1, Array2, Array3, Dimension, IntoDimension};
use numpy::{
    IntoPyArray, PyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadwriteArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::error::ImuError;
use crate::python::errors::to_py;

fn shape_err(msg: String) -> PyErr {
    to_py(ImuError::InvalidInput(msg))
}

/// A contiguous (N, K) float64 array as N rows of K.
pub fn rows<'a, const K: usize>(a: &'a PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<&'a [[f64; K]]> {
    let shape = a.shape();
    if shape[1] != K {
        return Err(shape_err(format!("{name} must have shape (N, {K}), got {shape:?}")));
    }
    let flat = a
        .as_slice()
        .map_err(|_| shape_err(format!("{name} must be C-contiguous (use numpy.ascontiguousarray)")))?;
    let (chunks, rest) = flat.as_chunks::<K>();
    debug_assert!(rest.is_empty());
    Ok(chunks)
}

pub fn slice1<'a, T: numpy::Element>(a: &'a PyReadonlyArray1<'_, T>, name: &str) -> PyResult<&'a [T]> {
    a.as_slice()
        .map_err(|_| shape_err(format!("{name} must be a contiguous 1-d array")))
}

pub fn out1<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>) -> Bound<'py, PyArray1<T>> {
    Array1::from_vec(v).into_pyarray(py)
}

/// Rows of K → (N, K), moving the buffer.
pub fn out2<'py, const K: usize>(py: Python<'py>, v: Vec<[f64; K]>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = v.len();
    let flat: Vec<f64> = v.into_flattened();
    Array2::from_shape_vec((n, K), flat)
        .map(|a| a.into_pyarray(py))
        .map_err(|e| shape_err(e.to_string()))
}

/// Flat buffer → (a, b), moving it.
pub fn out2_flat<'py, T: numpy::Element>(
    py: Python<'py>,
    v: Vec<T>,
    a: usize,
    b: usize,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    Array2::from_shape_vec((a, b), v)
        .map(|x| x.into_pyarray(py))
        .map_err(|e| shape_err(e.to_string()))
}

/// Rows of K laid out as (a, b) → (a, b, K), moving the buffer.
pub fn out3<'py, const K: usize>(
    py: Python<'py>,
    v: Vec<[f64; K]>,
    a: usize,
    b: usize,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let flat: Vec<f64> = v.into_flattened();
    Array3::from_shape_vec((a, b, K), flat)
        .map(|x| x.into_pyarray(py))
        .map_err(|e| shape_err(e.to_string()))
}

/// Flat buffer → (a, b, c), moving it.
pub fn out3_flat<'py>(
    py: Python<'py>,
    v: Vec<f64>,
    a: usize,
    b: usize,
    c: usize,
) -> PyResult<Bound<'py, PyArray3<f64>>> {
    Array3::from_shape_vec((a, b, c), v)
        .map(|x| x.into_pyarray(py))
        .map_err(|e| shape_err(e.to_string()))
}

/// A zero-filled C-order array allocated by numpy, for a result the core writes in place. numpy
/// asks the kernel for huge pages on large arrays, so filling one takes far fewer page faults
/// than filling a fresh `Vec` and moving it (which is what dominated labels and batches).
pub fn zeros<'py, T: numpy::Element, D: Dimension>(
    py: Python<'py>,
    dims: impl IntoDimension<Dim = D>,
) -> Bound<'py, PyArray<T, D>> {
    PyArray::zeros(py, dims, false)
}

/// A writable C-contiguous array's buffer (as made by `zeros`).
pub fn flat_mut<'a, T: numpy::Element, D: Dimension>(a: &'a mut PyReadwriteArray<'_, T, D>) -> PyResult<&'a mut [T]> {
    a.as_slice_mut()
        .map_err(|_| shape_err("output array is not contiguous".to_string()))
}

/// A writable C-contiguous (..., K) float64 array as rows of K.
pub fn rows_mut<'a, const K: usize, D: Dimension>(
    a: &'a mut PyReadwriteArray<'_, f64, D>,
) -> PyResult<&'a mut [[f64; K]]> {
    let (chunks, rest) = flat_mut(a)?.as_chunks_mut::<K>();
    if !rest.is_empty() {
        return Err(shape_err(format!("output array does not hold whole rows of {K}")));
    }
    Ok(chunks)
}
