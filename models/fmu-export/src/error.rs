//! The error a model returns, and how bad it is (the FMI status it becomes).

use std::fmt;

/// How bad a [`ModelError`] is, i.e. the FMI status the runtime returns for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Severity {
    /// fmi2Error: the instance is in the error state (reset or restore to go on).
    #[default]
    Error,
    /// fmi2Discard: the step was not completed (e.g. a solver gave up); the instance stays
    /// usable for reading, terminating or restoring a state, and the host decides.
    Discard,
    /// fmi2Fatal: the model's computations are irreparably corrupted.
    Fatal,
}

/// An error from a model: the message names the variable, file or row at fault.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelError(pub String, pub Severity);

impl ModelError {
    /// An error (fmi2Error).
    pub fn new(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Error)
    }
    /// The step could not be completed (fmi2Discard from fmi2DoStep).
    pub fn discard(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Discard)
    }
    /// The model is irreparably corrupted (fmi2Fatal).
    pub fn fatal(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Fatal)
    }
    pub fn severity(&self) -> Severity {
        self.1
    }
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ModelError {}
