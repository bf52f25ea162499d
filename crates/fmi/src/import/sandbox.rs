//! Whether isolated workers are confined on this machine: the host's question, asked before
//! it believes a manifest in the store without the archive (a store no unconfined FMU can
//! have written). The confinement itself is the worker's (`tb_cosim::isolated::confine`:
//! Landlock, seccomp, a PID namespace); here only the kernel's Landlock is asked for, and
//! the environment's say.

/// Set to `off`, isolated workers are taken as unconfined (as `TWINBENCH_ISOLATE=crash-only`
/// makes them) and libraries are checked against their archives (tests; a system whose
/// Landlock breaks an FMU). Set to `assume`, the host takes workers as confined without
/// asking the kernel (instruction counts under valgrind, which does not know Landlock's
/// system calls).
pub const SANDBOX_ENV: &str = "TWINBENCH_WORKER_SANDBOX";

/// `crash-only`: isolated workers are not confined (crash and hang isolation only), as if
/// every `--isolate` were `--isolate=crash-only`.
pub const MODE_ENV: &str = "TWINBENCH_ISOLATE";

/// Why the environment makes isolated workers unconfined ([`MODE_ENV`]`=crash-only`, or
/// [`SANDBOX_ENV`]`=off`); `None` when it does not.
pub fn crash_only_by_environment() -> Option<String> {
    if std::env::var_os(MODE_ENV).is_some_and(|v| v == "crash-only") {
        return Some(format!("{MODE_ENV}=crash-only"));
    }
    std::env::var_os(SANDBOX_ENV)
        .is_some_and(|v| v == "off")
        .then(|| format!("{SANDBOX_ENV}=off"))
}

const CREATE_RULESET_VERSION: u32 = 1;

/// Landlock's ABI version, or why there is none.
fn abi() -> Result<i64, SandboxError> {
    // SAFETY: the documented version query: no attribute, size 0.
    let v = unsafe {
        libc::syscall(
            libc::SYS_landlock_create_ruleset,
            std::ptr::null::<u8>(),
            0usize,
            CREATE_RULESET_VERSION,
        )
    };
    if v < 1 {
        let e = std::io::Error::last_os_error();
        return Err(match e.raw_os_error() {
            Some(libc::ENOSYS) => SandboxError::NoLandlock,
            Some(libc::EOPNOTSUPP) => SandboxError::Disabled,
            errno => SandboxError::Unavailable {
                errno: errno.unwrap_or(0),
            },
        });
    }
    Ok(v)
}

/// Whether isolated workers are confined here; the reason when not (memorised: the kernel does
/// not change under a process).
pub fn available() -> Result<(), SandboxError> {
    static ANSWER: std::sync::OnceLock<Result<(), SandboxError>> = std::sync::OnceLock::new();
    ANSWER
        .get_or_init(|| {
            if let Some(setting) = crash_only_by_environment() {
                return Err(SandboxError::Environment { setting });
            }
            if std::env::var_os(SANDBOX_ENV).is_some_and(|v| v == "assume") {
                return Ok(());
            }
            // ABI 3 (Linux 6.2): what a confined worker requires.
            abi().and_then(|v| match v {
                v if v >= 3 => Ok(()),
                version => Err(SandboxError::Abi {
                    version,
                    required: 3,
                }),
            })
        })
        .clone()
}

/// Why isolated workers are not confined here.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SandboxError {
    /// The environment turned confinement off (`setting`: the variable and its value).
    #[error("{setting}")]
    Environment { setting: String },
    #[error("this kernel has no Landlock")]
    NoLandlock,
    #[error("Landlock is disabled on this system")]
    Disabled,
    /// The version query failed otherwise (`errno`: the kernel's error number).
    #[error(
        "Landlock is not available: {}",
        std::io::Error::from_raw_os_error(*errno)
    )]
    Unavailable { errno: i32 },
    #[error("this kernel's Landlock is ABI {version}; confinement needs {required}")]
    Abi { version: i64, required: i64 },
}
