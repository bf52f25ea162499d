//! Why a candidate's run failed. The study penalises the candidate and goes on; the error
//! keeps its kind through the worker pool, the laps, the fits and the evaluators, and is
//! only rendered to text where it is reported (the failure reasons of a study, the CLI,
//! Python). Across a process boundary (a Dask task) it travels as its kind and message,
//! [`RunError::kind`] and [`RunError::from_wire`].
//!
//! The observers' own errors are here too ([`ObserverError`]): like a candidate's, they are
//! the caller's kind, not the study's.

use std::sync::Arc;
use tb_cosim::SystemError;
use tb_fmi::FmuError;

/// Why one candidate's run, or one point's laps, failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The simulation failed: an FMU's call, its isolated worker (crashed, hung), the
    /// system. (Boxed: a candidate's result stays small.)
    #[error("{}", simulation_text(.0))]
    Simulation(Box<SystemError>),
    /// A parameter's value cannot be set.
    #[error("setting {name} = {value}: {}", simulation_text(.error))]
    Setting {
        name: String,
        value: f64,
        error: Box<SystemError>,
    },
    #[error("{given} values for {expected} parameters")]
    Count { given: usize, expected: usize },
    /// The recording is no comparison table, or a signal of it cannot be put on the grid.
    #[error("{0}")]
    Table(Box<tb_compare::Error>),
    #[error("comparison: {0}")]
    Comparison(Box<tb_compare::Error>),
    /// One lap of several failed (the lap named).
    #[error("lap '{lap}': {error}")]
    Lap { lap: String, error: Box<RunError> },
    #[error("cost is not finite ({0})")]
    NotFinite(f64),
    /// A worker asked for a step its study does not have (`step` counts from 1).
    #[error("{} has {steps} steps, the candidate is for step {step}", study.display())]
    NoSuchStep {
        study: std::path::PathBuf,
        steps: usize,
        step: usize,
    },
    /// The worker cannot prepare the measurement for the candidate's signals.
    #[error("{0}")]
    Prepare(Arc<tb_compare::Error>),
    /// The evaluator of a distributed study failed for these points (not their runs).
    #[error("the evaluator failed: {0}")]
    Evaluator(Arc<EvaluatorError>),
    /// A failure in another process, in its words, with its kind there.
    #[error("{message}")]
    Remote { kind: FailureKind, message: String },
    /// A [`crate::Problem`]'s own failure (a problem of the caller's, not the bench).
    #[error(transparent)]
    Problem(Box<dyn std::error::Error + Send + Sync>),
}

/// A failed simulation as the study reports it: an FMU's error says so.
fn simulation_text(e: &SystemError) -> String {
    match e {
        SystemError::Fmu(f) => format!("FMU error: {f}"),
        other => other.to_string(),
    }
}

/// What kind of failure a [`RunError`] is, as a word that crosses process boundaries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FailureKind {
    /// An FMU's call failed.
    Fmu,
    /// An isolated FMU's worker died or hung.
    Worker,
    /// Anything else the simulation said.
    Simulation,
    Setting,
    Count,
    Table,
    Comparison,
    NotFinite,
    NoSuchStep,
    Prepare,
    Evaluator,
    Problem,
    /// A failure that came without a kind (a task of the caller's own).
    Unknown,
}

impl FailureKind {
    const NAMES: [(FailureKind, &'static str); 13] = [
        (FailureKind::Fmu, "fmu"),
        (FailureKind::Worker, "worker"),
        (FailureKind::Simulation, "simulation"),
        (FailureKind::Setting, "setting"),
        (FailureKind::Count, "count"),
        (FailureKind::Table, "table"),
        (FailureKind::Comparison, "comparison"),
        (FailureKind::NotFinite, "not-finite"),
        (FailureKind::NoSuchStep, "no-such-step"),
        (FailureKind::Prepare, "prepare"),
        (FailureKind::Evaluator, "evaluator"),
        (FailureKind::Problem, "problem"),
        (FailureKind::Unknown, "unknown"),
    ];

    /// The kind's word on the wire.
    pub fn name(self) -> &'static str {
        Self::NAMES
            .iter()
            .find(|(k, _)| *k == self)
            .map_or("unknown", |(_, n)| n)
    }

    /// The kind of a word (an unknown word: [`FailureKind::Unknown`]).
    pub fn from_name(name: &str) -> FailureKind {
        Self::NAMES
            .iter()
            .find(|(_, n)| *n == name)
            .map_or(FailureKind::Unknown, |(k, _)| *k)
    }
}

fn kind_of_system(e: &SystemError) -> FailureKind {
    match e {
        SystemError::Fmu(FmuError::Isolated { .. }) => FailureKind::Worker,
        SystemError::Fmu(_) => FailureKind::Fmu,
        _ => FailureKind::Simulation,
    }
}

impl RunError {
    /// What kind of failure this is (a lap's: its run's).
    pub fn kind(&self) -> FailureKind {
        match self {
            RunError::Simulation(e) => kind_of_system(e),
            RunError::Setting { .. } => FailureKind::Setting,
            RunError::Count { .. } => FailureKind::Count,
            RunError::Table(_) => FailureKind::Table,
            RunError::Comparison(_) => FailureKind::Comparison,
            RunError::Lap { error, .. } => error.kind(),
            RunError::NotFinite(_) => FailureKind::NotFinite,
            RunError::NoSuchStep { .. } => FailureKind::NoSuchStep,
            RunError::Prepare(_) => FailureKind::Prepare,
            RunError::Evaluator(_) => FailureKind::Evaluator,
            RunError::Remote { kind, .. } => *kind,
            RunError::Problem(_) => FailureKind::Problem,
        }
    }

    /// A failure another process sent as its kind's word and its message.
    pub fn from_wire(kind: &str, message: impl Into<String>) -> RunError {
        RunError::Remote {
            kind: FailureKind::from_name(kind),
            message: message.into(),
        }
    }
}

impl From<SystemError> for RunError {
    fn from(e: SystemError) -> RunError {
        RunError::Simulation(Box::new(e))
    }
}

/// An observer's own failure (its report that could not be written), of the observer's
/// own type.
pub type ObserverError = Box<dyn std::error::Error + Send + Sync>;

/// Why an evaluator of a distributed study could not evaluate (not a candidate's failure:
/// the study stops, its checkpoint holds the last whole generation).
#[derive(Debug, thiserror::Error)]
pub enum EvaluatorError {
    #[error("this evaluator runs candidates' costs only, not the joint fit's laps")]
    CostsOnly,
    #[error("no signals task was given with the executor")]
    NoSignalsTask,
    #[error("{results} results for {candidates} candidates")]
    Results { results: usize, candidates: usize },
    /// The executor raised (a lost cluster, an interruption): its exception's text; the
    /// caller keeps the exception itself.
    #[error("{0}")]
    Raised(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_crosses_processes_as_its_kind_and_message() {
        let e = RunError::Lap {
            lap: "wet".into(),
            error: Box::new(RunError::Count {
                given: 2,
                expected: 3,
            }),
        };
        assert_eq!(e.to_string(), "lap 'wet': 2 values for 3 parameters");
        assert_eq!(e.kind(), FailureKind::Count);
        let back = RunError::from_wire(e.kind().name(), e.to_string());
        assert!(matches!(
            &back,
            RunError::Remote {
                kind: FailureKind::Count,
                ..
            }
        ));
        assert_eq!(back.to_string(), e.to_string());
        // A task of the caller's own says no kind.
        assert!(matches!(
            RunError::from_wire("", "it broke").kind(),
            FailureKind::Unknown
        ));
        for (kind, name) in FailureKind::NAMES {
            assert_eq!(FailureKind::from_name(name), kind);
        }
    }

    #[test]
    fn an_fmus_failure_says_so_and_a_hung_worker_is_the_workers() {
        let call = SystemError::Fmu(FmuError::Instantiate {
            instance: "v".into(),
            message: "no".into(),
        });
        let e = RunError::from(call);
        assert!(matches!(&e, RunError::Simulation(s) if matches!(**s, SystemError::Fmu(_))));
        assert_eq!(e.to_string(), "FMU error: instance 'v': no");
        let e = RunError::Setting {
            name: "v.m".into(),
            value: -1.0,
            error: Box::new(tb_cosim::invalid("v.m", "out of range")),
        };
        assert_eq!(e.to_string(), "setting v.m = -1: v.m: out of range");
        assert_eq!(RunError::NotFinite(f64::NAN).kind(), FailureKind::NotFinite);
    }
}
