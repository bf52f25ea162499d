//! Co-simulation of FMI 2.0 units, in one direction: a system file ([`config`]) is compiled
//! once into a [`Plan`] (FMUs loaded, names resolved, everything checked), a [`Simulation`]
//! runs a plan with a master algorithm ([`master`]) over units behind one small trait
//! ([`backend`]: an FMU in-process, a model linked natively, an FMU isolated in a worker
//! process), and records a [`tb_table::Table`]; what watches a run, the recording and the
//! stop condition included, is an observer ([`observe`]). Replayed measurement channels
//! ([`replay`]) are units too. [`ssp`] writes a system as an SSP package, [`ssp_import`]
//! reads one as a system file.

pub mod backend;
pub mod config;
pub mod exchange;
pub mod isolated;
pub mod master;
pub mod native;
pub mod observe;
pub mod pacing;
pub mod plan;
pub mod realtime;
pub mod replay;
pub mod ssp;
pub mod ssp_import;
pub mod trace;

pub use config::{Algorithm, StepConvention, StopConfig, SystemFile};
pub use master::{RunSummary, Simulation};
pub use observe::{Ended, Moment, RunObserver, RunView};
pub use plan::{
    ConnectionDef, Endpoint, InstanceDef, LoadOptions, ParamSlot, ParamValue, Plan, Stop,
};
pub use tb_table::Table;

use std::path::PathBuf;
use tb_fmi::FmuError;

#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    // Transparent: with "{0}" and #[from], `{:#}` printed the FMU error twice.
    #[error(transparent)]
    Fmu(#[from] FmuError),
    /// An SSP package that cannot be run (named with the file and line inside it).
    #[error(transparent)]
    Ssp(Box<ssp_import::SspImportError>),
    #[error("{context}: {message}")]
    Invalid { context: String, message: String },
    /// A connection that cannot convert what it carries (`context`: the system file and
    /// the connection; `hint`: how to fix a replayed column's unit, else empty).
    #[error("{context}: {error}{hint}")]
    Conversion {
        context: String,
        error: plan::ConversionError,
        hint: String,
    },
    /// The units cannot be stepped in an order (`context`: the system file).
    #[error("{context}: {error}")]
    Order {
        context: String,
        error: plan::OrderError,
    },
    #[error("replay '{name}' ({path}): {error}")]
    Replay {
        name: String,
        path: PathBuf,
        error: Box<replay::ReplayError>,
    },
    #[error(
        "{signal} is not finite ({value}) at t = {time} s after the step of instance '{instance}'"
    )]
    NotFinite {
        instance: String,
        signal: String,
        value: f64,
        time: f64,
    },
    #[error("{0}")]
    Stop(String),
    /// An observer's own input or output failed (the file it writes, the pipe it reads):
    /// the run fails with it, named by the observer.
    #[error("observer '{observer}': {error}")]
    Observer {
        observer: String,
        error: std::io::Error,
    },
    /// An FMU asked to end the simulation (a step returned `fmi2Discard` with
    /// `fmi2Terminated` true): the run ends normally at its last successful time. Only seen
    /// between the master's step and its run loop.
    #[error("instance '{instance}' asked to end the simulation at t = {time} s")]
    EndedByFmu { instance: String, time: f64 },
    /// The run completed, then ending an instance failed: the recording is complete and
    /// kept; the error is still an error.
    #[error("the run completed ({}), then {error}; its recording is complete and kept", summary.stopped_by)]
    AfterRun {
        summary: Box<RunSummary>,
        error: Box<SystemError>,
    },
}

impl From<ssp_import::SspImportError> for SystemError {
    fn from(e: ssp_import::SspImportError) -> Self {
        SystemError::Ssp(Box::new(e))
    }
}

/// An error about the system, with where it is (file, connection, parameter).
pub fn invalid(context: impl Into<String>, message: impl Into<String>) -> SystemError {
    SystemError::Invalid {
        context: context.into(),
        message: message.into(),
    }
}

/// Split `instance.variable`.
pub fn split_name(s: &str) -> Option<(&str, &str)> {
    let (a, b) = s.trim().split_once('.')?;
    (!a.is_empty() && !b.is_empty()).then_some((a, b))
}
