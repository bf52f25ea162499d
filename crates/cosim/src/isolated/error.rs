//! Why an isolated worker cannot be used: its settings, its executable, and a worker lost
//! during a request.

use super::wire::{WireError, MAX_FRAME};
use std::path::PathBuf;
use std::time::Duration;

/// A setting of isolated runs that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum IsolationError {
    #[error(
        "watchdog must be a number of seconds in [{}, {}], got {seconds:e}",
        super::MIN_TIMEOUT_S,
        super::MAX_TIMEOUT_S
    )]
    Watchdog { seconds: f64 },
    #[error("cannot find this executable: {0}")]
    CurrentExe(std::io::Error),
    #[error(
        "cannot find the twinbench executable to run the worker (this is {}); set {}",
        this.display(),
        super::WORKER_EXE_ENV
    )]
    NoWorkerExe { this: PathBuf },
}

/// Why a worker answered no request: it was killed, or died. `end` says how it ended (its
/// exit status or signal).
#[derive(Debug, thiserror::Error)]
pub(crate) enum WorkerLost {
    #[error("protocol error (answer of {size} bytes is too large, the limit is {MAX_FRAME}); killed ({end})")]
    TooLarge { size: usize, end: String },
    #[error("no answer within {timeout:?} (watchdog): the FMU hangs; killed ({end})")]
    Hung { timeout: Duration, end: String },
    /// `note`: the confined worker's limits, when it died of a signal (empty otherwise).
    #[error("{end} (crashed){note}")]
    Crashed { end: String, note: String },
    #[error("protocol error ({error}); killed ({end})")]
    Protocol { error: WireError, end: String },
}
