//! Warnings kept for Python: the library's log warnings, taken by the package after each call.

use pyo3::prelude::*;
use std::sync::Mutex;

/// Every warning of the Rust code (`log::warn!`), kept until the call returns to Python,
/// whose package turns each into a `warnings.warn` (`TwinbenchWarning`): none is dropped
/// (M13), and no Python is called from the simulation's threads.
pub(crate) struct KeptWarnings;

pub(crate) static KEPT: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// At most this many kept between two returns to Python (a flood is said, not kept).
pub(crate) const KEPT_MAX: usize = 1000;

impl log::Log for KeptWarnings {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Warn
    }
    fn log(&self, r: &log::Record) {
        if !self.enabled(r.metadata()) {
            return;
        }
        let mut kept = KEPT.lock().unwrap_or_else(|p| p.into_inner());
        match kept.len() {
            n if n < KEPT_MAX => kept.push(r.args().to_string()),
            KEPT_MAX => kept.push(format!(
                "more than {KEPT_MAX} warnings; the rest is not shown"
            )),
            _ => {}
        }
    }
    fn flush(&self) {}
}

pub(crate) static KEPT_WARNINGS: KeptWarnings = KeptWarnings;

/// The warnings kept since the last call (and forgets them).
#[pyfunction]
pub(crate) fn take_warnings() -> Vec<String> {
    std::mem::take(&mut *KEPT.lock().unwrap_or_else(|p| p.into_inner()))
}
