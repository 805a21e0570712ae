//! The native module `deformcal._deformcal`: a thin layer between Python and the
//! library's own pipeline (the functions the command line's `calibrate`,
//! `detect` and `export` use). It converts arrays and options, releases the GIL
//! while the library works, and turns every library error, and any panic, into an
//! exception of the package's hierarchy (`deformcal/_errors.py`). Array shapes and
//! dtypes are checked in the Python layer before anything reaches this module.
use pyo3::prelude::*;
use pyo3::types::PyType;

mod calibrate;
mod camera;
mod detect;

/// The Python exception class `name` of `deformcal._errors`.
fn error_class<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyType>> {
    Ok(py
        .import("deformcal._errors")?
        .getattr(name)?
        .cast_into::<PyType>()?)
}

/// A Python exception of class `name` with `message`.
pub(crate) fn py_error(name: &str, message: String) -> PyErr {
    Python::attach(|py| match error_class(py, name) {
        Ok(class) => PyErr::from_type(class, message),
        Err(e) => e,
    })
}

/// The exception class of a library error: what the user has to change.
pub(crate) fn class_of(e: &deformcal::Error) -> &'static str {
    use deformcal::Error as E;
    match e {
        E::Config { .. } => "OptionError",
        E::Data { .. } | E::Invalid(_) | E::TooLarge(_) => "InputError",
        E::Degenerate(_) | E::Init(_) => "DataError",
        E::Solver(_) | E::Problem(_) => "SolverError",
        E::Io { .. } | E::Write { .. } | E::Locked(_) | E::Photos { .. } | E::Video { .. } => {
            "FileError"
        }
    }
}

/// A library error as the Python exception of its class.
pub(crate) fn lib_error(e: deformcal::Error) -> PyErr {
    py_error(class_of(&e), e.to_string())
}

/// Runs `work` without the GIL; a panic becomes `deformcal.Error` (a bug, said so)
/// instead of crossing into Python.
pub(crate) fn run_detached<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> PyResult<T> + Send,
) -> PyResult<T> {
    let outcome = py.detach(|| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(work)).map_err(|payload| {
            payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "unknown panic".into())
        })
    });
    match outcome {
        Ok(result) => result,
        Err(message) => Err(py_error(
            "Error",
            format!("internal error in deformcal (a bug; please report it): {message}"),
        )),
    }
}

#[pymodule]
fn _deformcal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(calibrate::calibrate, m)?)?;
    m.add_class::<calibrate::NativeCalibration>()?;
    m.add_function(wrap_pyfunction!(detect::detect_file, m)?)?;
    m.add_function(wrap_pyfunction!(detect::detect_array, m)?)?;
    m.add_function(wrap_pyfunction!(camera::project, m)?)?;
    m.add_function(wrap_pyfunction!(camera::unproject, m)?)?;
    m.add_function(wrap_pyfunction!(camera::export, m)?)?;
    m.add_function(wrap_pyfunction!(camera::check_calibration_json, m)?)?;
    m.add_function(wrap_pyfunction!(camera::lens_models, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
