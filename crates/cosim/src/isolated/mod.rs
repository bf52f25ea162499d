//! Isolation mode: an FMU instance runs in a worker process (`twinbench worker`, a hidden
//! subcommand of this very executable), so that a segfault, an abort or a hang inside a
//! third-party FMU ends that run with an error naming the instance, the time and the
//! cause, and the host lives on.
//!
//! Transport: a Unix socket pair whose worker end is the worker's stdin (the worker moves
//! it away from fd 0/1 at once, so an FMU printing to stdout cannot corrupt the protocol).
//! Protocol: length-prefixed little-endian frames. A request is a list of operations run in
//! order, stopping at the first error; the response carries the results of the operations
//! that completed. Sets are queued on the host and sent with the next call, and the gets
//! that followed the previous step are sent with each step, so that a Gauss-Seidel step
//! (set inputs, step, get outputs) is one round trip. Every round trip has a watchdog: no
//! complete answer in time, and the worker is killed.

//! - this module: the options and the factory;
//! - [`wire`]: the protocol described once, used by both ends: the operations
//!   ([`wire::Request`]: FMI calls by their number in [`tb_fmi::FUNCTIONS`]), the answer
//!   ([`wire::Response`]: get results, the error with its kind and fields) and their encoding;
//! - [`host`]: the backend that talks to a worker;
//! - [`worker`]: the server that runs in the worker process.

pub mod confine;
mod error;
mod host;
pub mod wire;
pub mod worker;

pub use error::IsolationError;
pub(crate) use error::WorkerLost;
pub use host::IsolatedBackend;
pub use worker::serve_stdio;

use crate::backend::{Backend, BackendFactory, RunAs};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;
use tb_fmi::{FmuError, LoadedFmu};

/// The longest watchdog accepted (a day): longer is a mistake, and beyond what a
/// `Duration` holds it would panic.
pub const MAX_TIMEOUT_S: f64 = 86_400.0;

/// A watchdog of `seconds`, checked: finite, in [`MIN_TIMEOUT_S`, `MAX_TIMEOUT_S`].
/// The shortest watchdog accepted [s].
pub const MIN_TIMEOUT_S: f64 = 1e-3;

pub fn watchdog(seconds: f64) -> Result<Duration, IsolationError> {
    // Below a millisecond no answer arrives (a round trip to the worker takes tens of
    // microseconds, a step of a real FMU more): every call would look like a hang.
    if !(seconds.is_finite() && (MIN_TIMEOUT_S..=MAX_TIMEOUT_S).contains(&seconds)) {
        return Err(IsolationError::Watchdog { seconds });
    }
    Ok(Duration::from_secs_f64(seconds))
}

/// The default per-call watchdog.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(10);
/// Environment variable naming the executable that serves `worker` (default: this one).
pub const WORKER_EXE_ENV: &str = "TWINBENCH_WORKER_EXE";
/// Lines of the worker's stderr kept for crash reports.
const STDERR_LINES: usize = 20;

/// How isolated instances are run.
#[derive(Clone, Debug)]
pub struct IsolationOptions {
    /// Longest wait for one answer of the worker (one step, one initialisation, ...).
    pub timeout: Duration,
    /// The executable to run as `<exe> worker`; default: [`WORKER_EXE_ENV`], else this
    /// executable (or, from a test binary, `target/<profile>/twinbench`).
    pub worker_exe: Option<PathBuf>,
    /// Libraries the worker loads with RTLD_GLOBAL before the FMU's (the system file's
    /// `preload`, e.g. libpython for a pythonfmu FMU).
    pub preload: Vec<PathBuf>,
    /// Confined (the default) or crash isolation only ([`confine`]).
    pub mode: confine::Mode,
    /// Files and folders a confined worker may read besides the system's and its FMU's
    /// folder: the files of the system's `*_file` parameters (set when the plan is compiled;
    /// shared by the plan's instances).
    pub readable: Arc<std::sync::RwLock<Vec<PathBuf>>>,
    /// A confined worker's limits; `None`: [`confine::LIMITS_ENV`], else the defaults.
    pub limits: Option<confine::Limits>,
}

impl Default for IsolationOptions {
    fn default() -> Self {
        IsolationOptions {
            timeout: DEFAULT_TIMEOUT,
            worker_exe: None,
            preload: Vec::new(),
            mode: confine::Mode::default(),
            readable: Arc::default(),
            limits: None,
        }
    }
}

impl IsolationOptions {
    pub fn resolve_exe(&self) -> Result<PathBuf, IsolationError> {
        if let Some(p) = &self.worker_exe {
            return Ok(p.clone());
        }
        if let Some(p) = std::env::var_os(WORKER_EXE_ENV) {
            return Ok(PathBuf::from(p));
        }
        let me = std::env::current_exe().map_err(IsolationError::CurrentExe)?;
        if me.file_stem().is_some_and(|s| s == "twinbench") {
            return Ok(me);
        }
        // A test or bench binary in target/<profile>/deps.
        if let Some(p) = me
            .parent()
            .and_then(Path::parent)
            .map(|d| d.join("twinbench"))
            .filter(|p| p.is_file())
        {
            return Ok(p);
        }
        Err(IsolationError::NoWorkerExe { this: me })
    }
}

/// What loading an FMU's library found (`twinbench info --isolate`).
#[derive(Clone, Debug, PartialEq)]
pub struct LibraryReport {
    /// What `fmi2GetVersion` returned.
    pub version: String,
    /// The optional FMI functions the library does not export.
    pub missing_optional: Vec<String>,
}

/// Load an FMU's library in a worker process and report on it: none of the FMU's code runs
/// in this process.
pub fn probe(fmu: &LoadedFmu, options: &IsolationOptions) -> Result<LibraryReport, FmuError> {
    IsolatedBackend::probe(fmu, options)
}

/// A real-time check of `fmu` in a worker of its own: instantiated, initialised at
/// `spec.start` with the inputs there, then measured ([`crate::realtime`]). The worker ends
/// with the check (its system-call trap cannot be taken off).
pub fn realtime_check(
    fmu: &LoadedFmu,
    options: &IsolationOptions,
    run: RunAs,
    spec: &crate::realtime::CheckSpec,
) -> Result<crate::realtime::Measurement, FmuError> {
    let mut b = IsolatedBackend::start("realtime-check", fmu, options, false, run)?;
    crate::realtime::measure::initialise(&mut b, spec)?;
    b.realtime(spec)
}

/// Creates instances that run in their own worker process.
pub struct IsolatedFactory {
    pub fmu: Arc<LoadedFmu>,
    pub options: IsolationOptions,
    /// The interface (and Model Exchange solver settings): the worker runs that backend.
    pub run: RunAs,
}

impl BackendFactory for IsolatedFactory {
    fn kind(&self) -> &'static str {
        "isolated"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        let b = IsolatedBackend::start(instance_name, &self.fmu, &self.options, logging, self.run)?;
        Ok(Box::new(b))
    }
}
