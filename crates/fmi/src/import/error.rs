//! The importer's errors, each naming the file or instance and what was expected.

use crate::fmi2::fmi2Status;
use crate::functions::Function;
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum FmuError {
    #[error("{path}: cannot load shared library: {message}")]
    Load { path: PathBuf, message: String },
    #[error("{path}: required FMI function {symbol} is not exported")]
    MissingSymbol { path: PathBuf, symbol: &'static str },
    #[error("instance '{instance}': {message}")]
    Instantiate { instance: String, message: String },
    #[error(
        "instance '{instance}' at t = {time} s: {function} returned {status}{}",
        format_log(log)
    )]
    Call {
        instance: String,
        function: Function,
        status: fmi2Status,
        time: f64,
        log: Vec<String>,
    },
    /// An FMI 3.0 call that did not return OK or Warning.
    #[error(
        "instance '{instance}' at t = {time} s: {function} returned {status}{}",
        format_log(log)
    )]
    Call3 {
        instance: String,
        function: String,
        status: String,
        time: f64,
        log: Vec<String>,
    },
    /// A Model Exchange instance's error: an FMI call, or the integrator (CVODE) with its
    /// return flag's name, e.g. `CVode returned CV_CONV_FAILURE (-4): ...`.
    #[error(
        "{}: instance '{instance}' (Model Exchange) at t = {time} s: {call} {problem}{}",
        fmu.display(),
        format_log(log)
    )]
    ModelExchange {
        /// The .fmu the user gave (boxed, as `call`: the error stays small).
        fmu: Box<std::path::Path>,
        instance: String,
        time: f64,
        /// The FMI function (`fmi2GetDerivatives`) or the solver's (`CVode`).
        call: Box<str>,
        /// What went wrong: `returned fmi2Error`, `returned CV_CONV_FAILURE (-4): ...`.
        problem: String,
        log: Vec<String>,
    },
    /// A get or set given value references and values of different lengths (a caller's
    /// mistake, refused before the FMU could read or write past the values).
    #[error(
        "instance '{instance}': {function} was given {references} value references and {values} values"
    )]
    Lengths {
        instance: String,
        function: Function,
        references: usize,
        values: usize,
    },
    #[error("instance '{instance}': {what} is not provided by this FMU")]
    Unsupported {
        instance: String,
        what: &'static str,
    },
    /// A unit run in a worker process (isolation mode) that crashed, hung or broke the protocol.
    #[error(
        "instance '{instance}' at t = {time} s: {function} in the isolated worker process: {cause}{}",
        format_log(log)
    )]
    Isolated {
        instance: String,
        function: String,
        time: f64,
        cause: String,
        log: Vec<String>,
    },
    #[error("{path}: {message}")]
    Archive { path: PathBuf, message: String },
    #[error("{path}: modelDescription.xml: {message}")]
    Description { path: PathBuf, message: String },
}

fn format_log(lines: &[String]) -> String {
    if lines.is_empty() {
        String::new()
    } else {
        format!("; the FMU's last messages:\n  {}", lines.join("\n  "))
    }
}

impl FmuError {
    /// A refused call: the one place a status becomes an error, for every backend.
    #[cold]
    pub fn call(
        instance: &str,
        function: Function,
        status: fmi2Status,
        time: f64,
        log: Vec<String>,
    ) -> FmuError {
        FmuError::Call {
            instance: instance.to_string(),
            function,
            status,
            time,
            log,
        }
    }
}
