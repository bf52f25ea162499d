//! Errors as Python sees them, and Python values as the command line's.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyBool;

// Declared in the module `twinbench`, where the package exports it: Python shows it as
// `twinbench.TwinbenchError`.
create_exception!(
    twinbench,
    TwinbenchError,
    PyException,
    "An error of twinbench: a bad file, a wrong name, a failed run (the message is the command line's)."
);

/// An error as the command line prints it (the whole chain, `error: ` left off).
pub(crate) fn error(e: impl Into<anyhow::Error>) -> PyErr {
    TwinbenchError::new_err(tb_bench::bench::message(&e.into()))
}

/// A Python value as the TOML value `--set` would give the same text.
pub(crate) fn toml_value(v: &Bound<'_, PyAny>, name: &str) -> PyResult<toml::Value> {
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(x) = v.extract::<f64>() {
        return Ok(toml::Value::Float(x));
    }
    if let Ok(s) = v.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    Err(TwinbenchError::new_err(format!(
        "parameter \"{name}\": expected a number, a boolean or a string, got {}",
        v.get_type().name()?
    )))
}
