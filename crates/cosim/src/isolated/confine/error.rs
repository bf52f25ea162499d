//! Why a worker cannot be confined, or its limits cannot be read.

use std::io;
use std::path::PathBuf;

/// Why the confinement of a worker cannot be set up: the step that failed, with the
/// system's own error. The worker says it on stderr and exits with
/// [`super::CANNOT_CONFINE`]; the host says it when it cannot prepare one.
#[derive(Debug, thiserror::Error)]
pub enum ConfineError {
    /// A system call failed: what it was to do (the call, the file), and the system's error.
    #[error("{what}: {error}")]
    Call { what: String, error: io::Error },
    #[error("{}: cannot enter the scratch folder: {error}", path.display())]
    EnterScratch { path: PathBuf, error: io::Error },
    #[error("the scratch folder's path has a NUL byte")]
    NulInPath,
    #[error("Landlock: {0}")]
    Landlock(landlock::RulesetError),
    #[error("Landlock is disabled on this system (lsm= boot parameter)")]
    LandlockDisabled,
    #[error("this kernel has no Landlock")]
    NoLandlock,
    #[error("this kernel's Landlock (ABI {abi}) cannot keep the FMU from truncating files it may not write (ABI 3, Linux 6.2, is needed)")]
    LandlockTooOld { abi: i32 },
    #[error("no seccomp filter for {arch}")]
    NoFilter { arch: &'static str },
    /// A filter that cannot be compiled (a rule, a condition the backend refuses).
    #[error("{0}")]
    Filter(seccompiler::BackendError),
    #[error("seccomp: {0}")]
    Seccomp(seccompiler::Error),
    /// The host's side: the worker's scratch folder cannot be made.
    #[error("cannot make the worker's scratch folder: {0}")]
    MakeScratch(io::Error),
    /// The host's side: the confinement cannot be written for the worker.
    #[error("cannot describe the confinement: {0}")]
    Describe(serde_json::Error),
    #[error(transparent)]
    Limits(#[from] LimitsError),
}

impl ConfineError {
    /// A failed call, with the system's last error.
    pub(crate) fn last_os(what: &str) -> ConfineError {
        // The system's error first: nothing may run between the call and this.
        let error = io::Error::last_os_error();
        ConfineError::Call {
            what: what.into(),
            error,
        }
    }

    /// A failed call, with its error.
    pub(crate) fn call(what: impl Into<String>) -> impl FnOnce(io::Error) -> ConfineError {
        let what = what.into();
        move |error| ConfineError::Call { what, error }
    }
}

/// Why a worker's limits (`--worker-limits`, [`super::LIMITS_ENV`]) cannot be read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    #[error("'{item}' is not key=value (keys: memory, scratch, files, threads)")]
    NotKeyValue { item: String },
    #[error("unknown limit '{key}' (keys: memory, scratch, files, threads)")]
    UnknownKey { key: String },
    #[error("{key} = '{value}' is not {}", if *size { "a size (bytes, or a number with K, M, G or T)" } else { "a whole number" })]
    NotANumber {
        key: String,
        value: String,
        size: bool,
    },
    /// A value outside its bounds (each as the messages write it: a size with its unit).
    #[error("{key} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        key: String,
        value: String,
        min: String,
        max: String,
    },
    /// The limits of the environment variable.
    #[error("{env}: {0}", env = super::LIMITS_ENV)]
    Environment(Box<LimitsError>),
}
