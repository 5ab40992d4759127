//! Allan deviation and its slope fits.

use numpy::{PyArray1, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::allan::{self, LineFit, NoiseFit};
use crate::error::ImuError;
use crate::python::arrays::{out1, out2_flat, slice1};
use crate::python::errors::to_py;

/// A contiguous (N, k) float64 array as its flat buffer and k.
fn table<'a>(a: &'a PyReadonlyArray2<'_, f64>, name: &str) -> PyResult<(&'a [f64], usize)> {
    let k = a.shape()[1];
    let flat = a.as_slice().map_err(|_| {
        to_py(ImuError::invalid(format!(
            "{name} must be C-contiguous (use numpy.ascontiguousarray)"
        )))
    })?;
    Ok((flat, k))
}

#[pyfunction]
#[pyo3(signature = (samples, period_s, per_decade=allan::DEFAULT_PER_DECADE, m=None))]
fn allan_deviation<'py>(
    py: Python<'py>,
    samples: PyReadonlyArray2<'py, f64>,
    period_s: f64,
    per_decade: usize,
    m: Option<PyReadonlyArray1<'py, u64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let (flat, k) = table(&samples, "samples")?;
    let n = samples.shape()[0];
    let m: Vec<usize> = match &m {
        Some(m) => slice1(m, "m")?.iter().map(|&x| x as usize).collect(),
        None => allan::cluster_sizes(n, per_decade),
    };
    let d = py
        .allow_threads(|| allan::overlapping_adev(flat, k, period_s, &m))
        .map_err(to_py)?;
    let rows = d.m.len();
    let out = PyDict::new(py);
    out.set_item("m", out1(py, d.m.iter().map(|&x| x as u64).collect()))?;
    out.set_item("tau_s", out1(py, d.tau_s))?;
    out.set_item("n_clusters", out1(py, d.n_clusters.iter().map(|&x| x as u64).collect()))?;
    out.set_item("rel_err", out1(py, d.rel_err))?;
    out.set_item("adev", out2_flat(py, d.adev, rows, k)?)?;
    Ok(out)
}

fn column<'py, T: numpy::Element>(
    py: Python<'py>,
    fits: &[NoiseFit],
    f: impl Fn(&NoiseFit) -> T,
) -> Bound<'py, PyArray1<T>> {
    out1(py, fits.iter().map(f).collect())
}

fn line_dict<'py>(
    py: Python<'py>,
    fits: &[NoiseFit],
    line: impl Fn(&NoiseFit) -> LineFit,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("value", column(py, fits, |f| line(f).value))?;
    d.set_item("rel_err", column(py, fits, |f| line(f).rel_err))?;
    d.set_item("tau_lo", column(py, fits, |f| line(f).tau_lo))?;
    d.set_item("tau_hi", column(py, fits, |f| line(f).tau_hi))?;
    d.set_item("points", column(py, fits, |f| line(f).points as u64))?;
    Ok(d)
}

#[pyfunction]
fn allan_fit<'py>(
    py: Python<'py>,
    tau_s: PyReadonlyArray1<'py, f64>,
    adev: PyReadonlyArray2<'py, f64>,
    rel_err: PyReadonlyArray1<'py, f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let (flat, k) = table(&adev, "adev")?;
    let (tau, err) = (slice1(&tau_s, "tau_s")?, slice1(&rel_err, "rel_err")?);
    if adev.shape()[0] != tau.len() {
        return Err(to_py(ImuError::invalid(format!(
            "adev has {} rows, tau_s {}",
            adev.shape()[0],
            tau.len()
        ))));
    }
    let fits = (0..k)
        .map(|axis| {
            let col: Vec<f64> = flat.iter().skip(axis).step_by(k.max(1)).copied().collect();
            allan::fit_noise(tau, &col, err)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("white", line_dict(py, &fits, |f| f.white)?)?;
    d.set_item("random_walk", line_dict(py, &fits, |f| f.random_walk)?)?;
    d.set_item("bias_instability", column(py, &fits, |f| f.bias_instability))?;
    d.set_item("tau_bias", column(py, &fits, |f| f.tau_bias))?;
    d.set_item("bias_rel_err", column(py, &fits, |f| f.bias_rel_err))?;
    d.set_item("bias_observed", column(py, &fits, |f| f.bias_observed))?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(allan_deviation, m)?)?;
    m.add_function(wrap_pyfunction!(allan_fit, m)?)?;
    Ok(())
}
