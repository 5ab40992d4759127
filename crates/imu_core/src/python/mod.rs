//! PyO3 bindings: `imu_learn._imu_core`. Thin wrappers only: numpy in and out without copies,
//! the GIL released around the Rust work, and every core error mapped to its Python class.
//! The Python-facing documentation is `python/imu_learn/_imu_core.pyi`.

mod allan;
mod arrays;
mod errors;
mod io;
mod numerics;

use pyo3::prelude::*;

#[pymodule]
fn _imu_core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    // numpy's C API is looked up on its first use, which imports numpy's capsule from Python; done
    // lazily, a Ctrl-C pending at that moment made the lookup fail and the numpy crate panic
    // (PanicException, exit 1, seen once in 20 interrupted `imu-learn labels` runs): done here, at import.
    let _ = numpy::PyArray1::<f64>::zeros(m.py(), 0, false);
    allan::register(m)?;
    io::register(m)?;
    numerics::register(m)?;
    Ok(())
}
