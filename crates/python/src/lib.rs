//! `twinbench._native`: the Rust side of the Python package (`python/twinbench`). Each
//! function is a thin call into the same library code the command line runs, with the GIL
//! released while it simulates; errors are `twinbench.TwinbenchError` with the command
//! line's message. The Python modules add the types, docstrings and numpy/pandas views.

use pyo3::prelude::*;

mod errors;
mod remote;
mod run;
mod study;
mod tools;
mod warnings;

use errors::TwinbenchError;
use remote::{OptimizerPy, StudyEvaluatorPy};
use study::{load_study, optimize};
use tools::{compare, export_twin, pack, realtime_check, register_mirror};
use warnings::{take_warnings, KEPT_WARNINGS};

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // A host that installed its own logger keeps it.
    if log::set_logger(&KEPT_WARNINGS).is_ok() {
        log::set_max_level(log::LevelFilter::Warn);
    }
    m.add_function(wrap_pyfunction!(take_warnings, m)?)?;
    m.add("TwinbenchError", m.py().get_type::<TwinbenchError>())?;
    // The package's version is the workspace's (the wheel's metadata says the same).
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(run::run, m)?)?;
    m.add_function(wrap_pyfunction!(pack, m)?)?;
    m.add_function(wrap_pyfunction!(export_twin, m)?)?;
    m.add_function(wrap_pyfunction!(realtime_check, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add_function(wrap_pyfunction!(load_study, m)?)?;
    m.add_function(wrap_pyfunction!(register_mirror, m)?)?;
    m.add_class::<StudyEvaluatorPy>()?;
    m.add_class::<OptimizerPy>()?;
    Ok(())
}
