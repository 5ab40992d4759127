//! numpy ↔ Rust without copies: inputs are borrowed as `&[[f64; 3]]` views of C-contiguous
//! arrays; outputs move their `Vec` into numpy (`into_pyarray`), so nothing is copied either way.

use std::sync::{Arc, Mutex};

use numpy::ndarray::{Array1, Array2, Array3, ArrayView, Dimension, IntoDimension, IxDyn};
use numpy::{
    IntoPyArray, PyArray, PyArray1, PyArray2, PyArray3, PyArrayDyn, PyReadonlyArray1, PyReadonlyArray2,
    PyReadwriteArray, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyMemoryError;
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
    // as_slice also takes a Fortran-ordered array, whose memory is not rows of K
    let not_c = || shape_err(format!("{name} must be C-contiguous (use numpy.ascontiguousarray)"));
    if !a.is_c_contiguous() {
        return Err(not_c());
    }
    let flat = a.as_slice().map_err(|_| not_c())?;
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

/// A zero-filled C-order float64 array allocated by numpy, for a result the core writes in place.
/// numpy asks the kernel for huge pages on large arrays, so filling one takes far fewer page faults
/// than filling a fresh `Vec` and moving it (which is what dominated labels and batches). Made by
/// `numpy.zeros`, so a size that cannot be allocated is numpy's `MemoryError` (or `ValueError`: too
/// big for an array), never a panic.
pub fn zeros<'py, D: Dimension>(
    py: Python<'py>,
    dims: impl IntoDimension<Dim = D>,
) -> PyResult<Bound<'py, PyArray<f64, D>>> {
    let shape: Vec<usize> = dims.into_dimension().slice().to_vec();
    let a = py.import("numpy")?.call_method1("zeros", (shape,))?;
    Ok(a.downcast_into::<PyArray<f64, D>>()?)
}

/// Float64 storage that batch outputs are carved from, shared by a `SequenceSet` and the arrays
/// it hands out. When Python drops the last array of a batch, its storage goes back here and the
/// next batch of the same size reuses it: memory the process has already touched, so building a
/// batch costs no page faults. (Fresh multi-MiB arrays cost one fault per 4 KiB page, which was
/// most of the time of a batch on a 2-core VM; see README, Benchmarks.)
pub type BufferPool = Arc<Mutex<Vec<Vec<f64>>>>;

/// At most this many idle buffers are kept (a trainer holds one or two batches at a time; more
/// would only pin memory).
const POOL_KEEP: usize = 16;

/// The owner of one pooled buffer: the numpy arrays of a batch are views with this as their base.
#[pyclass(module = "imu_learn._imu_core", frozen)]
pub struct PooledBuffer {
    data: Vec<f64>,
    pool: BufferPool,
}

impl Drop for PooledBuffer {
    fn drop(&mut self) {
        let data = std::mem::take(&mut self.data);
        // A poisoned lock only means another thread panicked while holding it: drop the buffer.
        if let Ok(mut idle) = self.pool.lock() {
            if idle.len() < POOL_KEEP {
                idle.push(data);
            }
        }
    }
}

/// A buffer of `len` floats from the pool, or a fresh zeroed one; running out of memory is a
/// `MemoryError`, never an abort.
fn take_buffer(pool: &BufferPool, len: usize) -> PyResult<Vec<f64>> {
    if let Ok(mut idle) = pool.lock() {
        while let Some(v) = idle.pop() {
            if v.len() == len {
                return Ok(v);
            }
        }
    }
    try_zeroed(len)
}

/// `vec![T::default(); n]`, but a `MemoryError` instead of an abort when it cannot be allocated.
pub fn try_zeroed<T: Clone + Default>(n: usize) -> PyResult<Vec<T>> {
    crate::batch::try_zeroed_vec(n).map_err(|e| {
        PyMemoryError::new_err(format!(
            "{n} entries of {} bytes cannot be allocated ({e})",
            std::mem::size_of::<T>()
        ))
    })
}

/// Float64 arrays of the given C-order shapes, carved out of one pooled buffer. `fill` gets one
/// mutable slice per shape, runs with the GIL released, and must write every element (a reused
/// buffer still holds the previous batch). Python sees the arrays only after `fill` succeeded.
pub fn pooled_arrays<'py, F>(
    py: Python<'py>,
    pool: &BufferPool,
    shapes: &[&[usize]],
    fill: F,
) -> PyResult<Vec<Bound<'py, PyArrayDyn<f64>>>>
where
    F: FnOnce(Vec<&mut [f64]>) -> crate::error::Result<()> + Send,
{
    let sizes: Vec<usize> = shapes
        .iter()
        .map(|s| s.iter().try_fold(1usize, |a, &d| a.checked_mul(d)))
        .collect::<Option<_>>()
        .ok_or_else(|| shape_err(format!("output shapes {shapes:?} overflow")))?;
    let total = sizes
        .iter()
        .try_fold(0usize, |a, &n| a.checked_add(n))
        .ok_or_else(|| shape_err(format!("output shapes {shapes:?} overflow")))?;
    let mut data = take_buffer(pool, total)?;
    {
        let mut parts = Vec::with_capacity(sizes.len());
        let mut rest: &mut [f64] = &mut data;
        for &n in &sizes {
            let (part, tail) = std::mem::take(&mut rest).split_at_mut(n);
            parts.push(part);
            rest = tail;
        }
        py.allow_threads(|| fill(parts)).map_err(to_py)?;
    }
    // Moving the Vec into its owner moves only its header: the heap block the views point into
    // stays where it is until the owner is dropped.
    let ptr = data.as_ptr();
    let owner = Bound::new(
        py,
        PooledBuffer {
            data,
            pool: Arc::clone(pool),
        },
    )?
    .into_any();
    let mut out = Vec::with_capacity(shapes.len());
    let mut off = 0usize;
    for (shape, n) in shapes.iter().zip(sizes) {
        // SAFETY: [off, off + n) lies inside the owner's buffer (the sizes sum to its length); the
        // buffer is neither reallocated nor freed while the owner lives, and every array made here
        // holds a reference to the owner as its base.
        let view = unsafe { ArrayView::from_shape_ptr(IxDyn(shape), ptr.add(off)) };
        out.push(unsafe { PyArrayDyn::borrow_from_array(&view, owner.clone()) });
        off += n;
    }
    Ok(out)
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
