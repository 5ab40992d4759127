//! PyO3 bindings: imu_learn._imu_core. Thin wrappers only: numpy in and out, GIL released
//! around the Rust work, every core error mapped to its Python exception class.
use pyo3::prelude::*;

#[pymodule]
fn _imu_core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
