//! `bamudi._native`: the Python extension of bamudi (pyo3). It binds the same library
//! functions the `bamudi` command line calls ([`bamudi_gate::session`]), so the numbers for
//! the same inputs and seed are the command line's, and every error is a
//! `bamudi.BamudiError` carrying the command line's message (causes joined by `: `).
//!
//! Long computations (building the gate, simulating, calibrating, predicting, the close
//! loop) release the GIL; the engine's `log` records go to Python's `logging` (logger names
//! start with the Rust module path, e.g. `bamudi.calibration`), progress to an optional
//! callback `progress(stage: str, done: int, total: int)`.
//!
//! The Python-facing layer (`py/bamudi/__init__.py`) adds pandas conversion and file
//! handling; the type stubs are `py/bamudi/_native.pyi`.

mod calibration;
mod closeloop;
mod gate;
mod model;
mod progress;
mod simulate;
mod usercal;

use pyo3::prelude::*;

pyo3::create_exception!(
    _native,
    BamudiError,
    pyo3::exceptions::PyException,
    "An input bamudi refuses or a computation that failed; the message names the culprit."
);

/// Turns any error into a `BamudiError` with its chain of causes (`outer: inner: ...`), the
/// text the command line prints after `error: `.
pub(crate) fn to_py(e: impl Into<Box<dyn std::error::Error + Send + Sync>>) -> PyErr {
    let e: Box<dyn std::error::Error + Send + Sync> = e.into();
    BamudiError::new_err(bamudi_gate::error::one_line_of(e.as_ref()))
}

/// A `BamudiError` with `message`.
pub(crate) fn invalid(message: impl Into<String>) -> PyErr {
    BamudiError::new_err(message.into())
}

/// The text of the input file `path` as the command line reads its files: `label` (the
/// argument's name) and the path start every message; a missing file, a directory, a
/// symbolic-link loop and a byte that is not UTF-8 (with its line) are named.
#[pyfunction]
fn read_input_text(label: &str, path: std::path::PathBuf) -> PyResult<String> {
    bamudi_gate::session::read_input_text(label, &path).map_err(to_py)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    pyo3_log::init();
    m.add("BamudiError", m.py().get_type::<BamudiError>())?;
    m.add_class::<gate::Gate>()?;
    m.add_class::<calibration::Calibration>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate_experiments, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::simulate_field, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::experiments_csv, m)?)?;
    m.add_function(wrap_pyfunction!(calibration::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(closeloop::close_loop, m)?)?;
    m.add_class::<model::Model>()?;
    m.add_class::<usercal::ModelCalibration>()?;
    m.add_function(wrap_pyfunction!(usercal::calibrate_model, m)?)?;
    m.add_function(wrap_pyfunction!(usercal::coverage, m)?)?;
    m.add_function(wrap_pyfunction!(read_input_text, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
