//! What can stop a study.

use std::path::PathBuf;

/// Why a study, a step or its files failed: each variant names the file, the step or the
/// cause; the errors of a run or a comparison are passed on as they are.
#[derive(Debug, thiserror::Error)]
pub enum OptimizeError {
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    #[error("{0}")]
    Invalid(String),
    // Transparent: the inner errors name their file, instance or row already, and a
    // prefixed message with a source would print the cause twice in the CLI's chain.
    #[error(transparent)]
    System(#[from] tb_cosim::SystemError),
    #[error(transparent)]
    Compare(#[from] tb_compare::Error),
    #[error("checkpoint: {0}")]
    Checkpoint(String),
    #[error("{0}")]
    Implausible(String),
    #[error("thread pool: {0}")]
    Threads(String),
    #[error("step '{step}': the start point cannot be evaluated: {reason}")]
    Start {
        step: String,
        reason: Box<crate::failure::RunError>,
    },
    /// The best point a step found fails when it is run again for the result.
    #[error("step '{step}': the start point cannot be evaluated: the best point cannot be re-evaluated: {reason}")]
    BestPoint {
        step: String,
        reason: Box<crate::failure::RunError>,
    },
    /// A step that ran and found nothing (every candidate failed).
    #[error("step '{step}': {reason}")]
    StepFailed { step: String, reason: String },
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The evaluator of a distributed study failed (not a candidate: the study stops, its
    /// checkpoint holds the last whole generation).
    #[error("evaluating candidates: {0}")]
    Evaluator(crate::failure::EvaluatorError),
    /// An observer of the study failed at its end (the report could not be written).
    #[error("{0}")]
    Observer(crate::failure::ObserverError),
}
