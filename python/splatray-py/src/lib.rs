//! `splatray._splatray`: the Python package's native module. numpy arrays
//! in and out; the GIL released (`Python::detach`) while the library works;
//! the library's one-line errors raised as `splatray.SplatrayError`, bad
//! arrays as `TypeError` / `ValueError` before any work starts.
//!
//! The Python-facing documentation is in `python/splatray/_splatray.pyi`.

mod arrays;
mod cast;
mod progress;
mod scene;
mod splats;
mod workflows;

use pyo3::prelude::*;

pyo3::create_exception!(
    _splatray,
    SplatrayError,
    pyo3::exceptions::PyRuntimeError,
    "An error of the splatray library: its one-line message."
);

/// A library error as a Python exception carrying its one-line message.
pub(crate) fn err(e: impl std::fmt::Display) -> PyErr {
    SplatrayError::new_err(e.to_string())
}

/// The native module.
#[pymodule]
fn _splatray(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SplatrayError", m.py().get_type::<SplatrayError>())?;
    m.add("INVALID_ID", u32::MAX)?;
    m.add("BACKENDS", splatray::accel::registry::names())?;
    m.add_class::<splats::PointCloud>()?;
    m.add_class::<splats::Splats>()?;
    m.add_class::<cast::SplatScene>()?;
    m.add_class::<scene::Scene>()?;
    m.add_class::<scene::Image>()?;
    m.add_function(wrap_pyfunction!(splats::read_points, m)?)?;
    m.add_function(wrap_pyfunction!(splats::splat, m)?)?;
    m.add_function(wrap_pyfunction!(scene::read_image, m)?)?;
    m.add_function(wrap_pyfunction!(workflows::scan_check, m)?)?;
    m.add_function(wrap_pyfunction!(workflows::sweep, m)?)?;
    Ok(())
}
