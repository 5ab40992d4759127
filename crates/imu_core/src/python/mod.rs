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
    allan::register(m)?;
    io::register(m)?;
    numerics::register(m)?;
    Ok(())
}
