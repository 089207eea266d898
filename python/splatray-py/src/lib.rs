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

/// `splatray ARGS...`: runs the command line with `argv` (the program's
/// name first) as the `splatray` binary does (the library's `run_cli`, the
/// binary's own code), and returns its exit status.
/// Its output goes to the process's stdout and stderr (progress on stderr);
/// the GIL is released while it runs. A panic returns 101, the status of a
/// binary that panicked, after the panic's message on stderr.
#[pyfunction]
#[pyo3(name = "main")]
fn cli_main(py: Python<'_>, argv: Vec<std::ffi::OsString>) -> i32 {
    py.detach(|| std::panic::catch_unwind(|| splatray::run_cli(argv)).map_or(101, i32::from))
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
    m.add_function(wrap_pyfunction!(cli_main, m)?)?;
    Ok(())
}
