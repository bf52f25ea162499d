//! The confinement of an isolated worker: what an FMU run with `--isolate` can do.
//!
//! Before the worker loads anything, for good, for itself and everything it starts:
//!
//! - **a process tree that ends with the run**: the worker runs in a PID namespace of its
//!   own (root: `unshare(CLONE_NEWPID)`; another user: with a user namespace), under an init
//!   that ends with the worker; the kernel then kills every process left in the namespace,
//!   and a process in it cannot name, signal or trace one outside; an IPC and a network
//!   namespace of its own too (no System V IPC object, abstract Unix socket or network
//!   interface of the host's), and a mount namespace whose only change is the scratch
//!   folder's tmpfs;
//! - **nothing inherited**: an environment from an allowlist ([`inherit`]), no descriptor
//!   but its channel and stdio;
//! - **bounded resources** ([`limits`]): address space, a scratch folder of a fixed size,
//!   open files, threads; no child processes;
//! - **no privileges**: every capability dropped (bounding, ambient, effective, permitted,
//!   inheritable) with the securebits locked, so that a root worker is root without any
//!   capability; `no_new_privs`, so no exec gains any;
//! - **a filtered system-call set** ([`filter`]): no socket of any family beyond the channel
//!   it has, no new process, no chmod/chown, mount, ptrace, module loading, namespaces, raw
//!   devices, extended attributes or file times, BPF, `io_uring`, keyrings, clock or host
//!   names, no x32 call;
//! - **Landlock** (the `landlock` crate): write access to the worker's scratch folder only
//!   (its working directory, `TMPDIR` and `HOME`); read and execute access to the system's
//!   libraries, a few named system files, its own `/proc` entry, the FMU's unpacked folder
//!   and the files the host names (preloaded libraries, the files of `*_file` parameters),
//!   and nothing else (the user's home, the project, other FMUs' folders); no TCP (Landlock
//!   4 and later); no signals to and no abstract Unix sockets of processes outside
//!   (Landlock 6 and later).
//!
//! What is required: PID, IPC, network and mount namespaces, the seccomp filter and Landlock
//! 3 (Linux 6.2) for the file system. Where one of them cannot be set up the worker says why
//! and exits with [`CANNOT_CONFINE`] before loading anything; the host refuses the FMU unless
//! the user asked for crash isolation only (`--isolate=crash-only`, [`MODE_ENV`]).

mod error;
pub mod filter;
pub mod inherit;
pub mod limits;
pub(crate) mod scratch;

pub use error::{ConfineError, LimitsError};
pub use limits::{Limits, LIMITS_ENV};
pub(crate) use scratch::Scratch;

use landlock::{
    path_beneath_rules, Access, AccessFs, AccessNet, LandlockStatus, Ruleset, RulesetAttr,
    RulesetCreatedAttr, RulesetStatus, Scope, ABI,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The worker's exit code when it cannot confine itself (before anything was loaded).
pub const CANNOT_CONFINE: i32 = 5;

pub use tb_fmi::import::sandbox::MODE_ENV;

/// The environment variable through which the host hands the worker its [`Spec`] (JSON).
pub(crate) const SPEC_ENV: &str = "TWINBENCH_WORKER_CONFINE";

/// What the host grants a worker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Spec {
    /// The only folder the worker can write (created by the host, removed after the run).
    pub scratch: PathBuf,
    /// Folders and files it can read (and execute) besides the system's.
    pub read: Vec<PathBuf>,
    /// Its resource limits.
    pub limits: Limits,
    /// Variables of the environment it keeps besides the allowlist's ([`inherit::PASS_ENV`]).
    pub env: Vec<String>,
}

/// What isolation a run asked for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// Confined (the default): refused where the confinement cannot be set up.
    #[default]
    Confined,
    /// Crash and hang isolation only: the worker runs as the user, unconfined.
    CrashOnly,
}

impl Mode {
    /// This mode, unless the environment says crash-only
    /// ([`tb_fmi::import::sandbox::crash_only_by_environment`]).
    pub fn effective(self) -> Mode {
        match tb_fmi::import::sandbox::crash_only_by_environment() {
            Some(_) => Mode::CrashOnly,
            None => self,
        }
    }
}

/// The system paths every worker reads: libraries, the loader's configuration, time zones,
/// the user and group names, random numbers, the processor count.
const SYSTEM_READ: &[&str] = &[
    "/usr",
    "/lib",
    "/lib32",
    "/lib64",
    "/libx32",
    "/bin",
    "/sbin",
    "/etc/ld.so.cache",
    "/etc/ld.so.conf",
    "/etc/ld.so.conf.d",
    "/etc/ld.so.preload",
    "/etc/localtime",
    "/etc/timezone",
    "/etc/passwd",
    "/etc/group",
    "/etc/nsswitch.conf",
    "/dev/null",
    "/dev/zero",
    "/dev/full",
    "/dev/random",
    "/dev/urandom",
    "/proc/cpuinfo",
    "/proc/meminfo",
    "/proc/stat",
    "/sys/devices/system/cpu",
];

/// Drops every capability of this process for good (a root worker keeps uid 0 without any
/// capability; the securebits locked so that no exec, setuid or ambient set gives one back).
fn drop_capabilities() -> Result<(), ConfineError> {
    // SAFETY: prctl and capset with documented arguments; no memory is handed over but the
    // two capset structures, which live across the call.
    unsafe {
        if libc::prctl(libc::PR_CAPBSET_READ, 0, 0, 0, 0) >= 0 {
            let mut cap = 0;
            while libc::prctl(libc::PR_CAPBSET_READ, cap, 0, 0, 0) >= 0 {
                if libc::prctl(libc::PR_CAPBSET_DROP, cap, 0, 0, 0) != 0
                    && libc::prctl(libc::PR_CAPBSET_READ, cap, 0, 0, 0) == 1
                {
                    let error = std::io::Error::last_os_error();
                    return Err(ConfineError::Call {
                        what: format!("cannot drop capability {cap} from the bounding set"),
                        error,
                    });
                }
                cap += 1;
            }
        }
        libc::prctl(
            libc::PR_CAP_AMBIENT,
            libc::PR_CAP_AMBIENT_CLEAR_ALL,
            0,
            0,
            0,
        );
        // SECBIT_NOROOT, _NO_SETUID_FIXUP, _KEEP_CAPS_LOCKED, _NO_CAP_AMBIENT_RAISE, each
        // with its lock.
        const SECURE: libc::c_ulong = 0x01 | 0x02 | 0x04 | 0x08 | 0x20 | 0x40 | 0x80;
        if libc::prctl(libc::PR_SET_SECUREBITS, SECURE, 0, 0, 0) != 0 && libc::geteuid() == 0 {
            return Err(ConfineError::last_os("cannot lock the securebits"));
        }
        #[repr(C)]
        struct Header {
            version: u32,
            pid: i32,
        }
        #[repr(C)]
        #[derive(Clone, Copy)]
        struct Data {
            effective: u32,
            permitted: u32,
            inheritable: u32,
        }
        let mut header = Header {
            version: 0x2008_0522,
            pid: 0,
        };
        let none = [Data {
            effective: 0,
            permitted: 0,
            inheritable: 0,
        }; 2];
        if libc::syscall(libc::SYS_capset, &mut header, none.as_ptr()) != 0 {
            return Err(ConfineError::last_os("cannot drop the capabilities"));
        }
    }
    Ok(())
}

/// Confines this process (single-threaded: Landlock and seccomp hold for the calling thread
/// and whatever it starts afterwards). Called in the worker, inside its namespaces.
pub fn confine(spec: &Spec) -> Result<(), ConfineError> {
    spec.limits.apply()?;
    drop_capabilities()?;
    std::env::set_current_dir(&spec.scratch).map_err(|error| ConfineError::EnterScratch {
        path: spec.scratch.clone(),
        error,
    })?;
    inherit::keep_only(&spec.env);
    for var in ["TMPDIR", "TMP", "TEMP", "HOME"] {
        std::env::set_var(var, &spec.scratch);
    }
    // SAFETY: prctl with documented arguments.
    if unsafe { libc::prctl(libc::PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) } != 0 {
        return Err(ConfineError::last_os("cannot set no_new_privs"));
    }
    // Landlock first (its rules open the paths), then seccomp.
    let latest = ABI::V6;
    let read = AccessFs::from_read(latest);
    let mut paths: Vec<PathBuf> = SYSTEM_READ.iter().map(PathBuf::from).collect();
    paths.push(own_proc_entry()?);
    paths.extend(spec.read.iter().cloned());
    let status = Ruleset::default()
        .handle_access(AccessFs::from_all(latest))
        .and_then(|r| r.handle_access(AccessNet::from_all(latest)))
        .and_then(|r| r.scope(Scope::from_all(latest)))
        .and_then(|r| r.create())
        .and_then(|r| r.add_rules(path_beneath_rules(&paths, read)))
        .and_then(|r| r.add_rules(path_beneath_rules(["/dev/null"], AccessFs::WriteFile)))
        .and_then(|r| {
            r.add_rules(path_beneath_rules(
                [&spec.scratch],
                AccessFs::from_all(latest),
            ))
        })
        .and_then(|r| r.restrict_self())
        .map_err(ConfineError::Landlock)?;
    let abi = match status.landlock {
        LandlockStatus::Available { effective_abi, .. } => effective_abi as i32,
        LandlockStatus::NotEnabled => return Err(ConfineError::LandlockDisabled),
        _ => return Err(ConfineError::NoLandlock),
    };
    if status.ruleset == RulesetStatus::NotEnforced || abi < 3 {
        return Err(ConfineError::LandlockTooOld { abi });
    }
    filter::apply()
}

/// This process's own `/proc` entry on the procfs it sees: `/proc/self` resolved now. The
/// process runs in a PID namespace of its own but sees the host's procfs, where its number
/// is not the one `getpid` gives inside the namespace (that one names another process
/// there). A rule holds for the folder it names when made, so `/proc/self` itself would
/// not do.
fn own_proc_entry() -> Result<PathBuf, ConfineError> {
    let me = std::fs::read_link("/proc/self")
        .map_err(ConfineError::call("cannot find this process's /proc entry"))?;
    Ok(Path::new("/proc").join(me))
}

/// The namespaces the worker runs in: PID, IPC, network and mount. Root makes them;
/// another user makes them with a user namespace of its own (mapping its own user and
/// group to themselves). In the mount namespace, made private, a tmpfs of `limits.scratch`
/// bytes is mounted on the scratch folder. Called in the guard before it starts the
/// worker's init.
pub fn new_namespaces(scratch: &Path, limits: &Limits) -> Result<(), ConfineError> {
    // With the PID namespace an IPC and a network namespace of its own: the user's System
    // V shared memory, semaphores and message queues, its abstract Unix sockets and
    // every network interface (loopback included) are out of reach, whatever the
    // worker's user id and the kernel's Landlock.
    let flags = libc::CLONE_NEWPID | libc::CLONE_NEWIPC | libc::CLONE_NEWNET | libc::CLONE_NEWNS;
    // SAFETY: geteuid, getegid and unshare with documented flags, in a single-threaded
    // process.
    let (uid, gid) = unsafe { (libc::geteuid(), libc::getegid()) };
    let r = unsafe {
        if uid == 0 {
            libc::unshare(flags)
        } else {
            libc::unshare(libc::CLONE_NEWUSER | flags)
        }
    };
    if r != 0 {
        return Err(ConfineError::last_os(
            "cannot make a PID, IPC, network and mount namespace (so that nothing the FMU starts outlives the run, it reaches no other process's shared memory or sockets, and its scratch folder has a size)",
        ));
    }
    if uid != 0 {
        for (file, text) in [
            ("/proc/self/setgroups", "deny".to_string()),
            ("/proc/self/uid_map", format!("{uid} {uid} 1")),
            ("/proc/self/gid_map", format!("{gid} {gid} 1")),
        ] {
            std::fs::write(file, text).map_err(ConfineError::call(format!(
                "cannot map the user in its user namespace ({file})"
            )))?;
        }
    }
    mount_scratch(scratch, limits.scratch)
}

/// Makes every mount of this (new) mount namespace private, then mounts a tmpfs of `size`
/// bytes, mode 700, on `scratch`: what the FMU writes there has that limit, and goes with
/// the namespace.
fn mount_scratch(scratch: &Path, size: u64) -> Result<(), ConfineError> {
    use std::os::unix::ffi::OsStrExt;
    let target = std::ffi::CString::new(scratch.as_os_str().as_bytes())
        .map_err(|_| ConfineError::NulInPath)?;
    let options =
        std::ffi::CString::new(format!("size={size},mode=0700")).expect("no NUL in the options");
    // SAFETY: mount(2) with NUL-terminated strings that live across the calls.
    unsafe {
        if libc::mount(
            std::ptr::null(),
            c"/".as_ptr(),
            std::ptr::null(),
            libc::MS_REC | libc::MS_PRIVATE,
            std::ptr::null(),
        ) != 0
        {
            return Err(ConfineError::last_os(
                "cannot make the worker's mounts private",
            ));
        }
        if libc::mount(
            c"tmpfs".as_ptr(),
            target.as_ptr(),
            c"tmpfs".as_ptr(),
            libc::MS_NOSUID | libc::MS_NODEV,
            options.as_ptr().cast(),
        ) != 0
        {
            let error = std::io::Error::last_os_error();
            return Err(ConfineError::Call {
                what: format!(
                    "cannot mount a tmpfs of {} on the scratch folder {}",
                    limits::size_text(size),
                    scratch.display()
                ),
                error,
            });
        }
    }
    Ok(())
}

/// The folders and files of `paths` that exist, as given (a missing one is no rule).
pub(crate) fn existing(paths: impl IntoIterator<Item = PathBuf>) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::new();
    for p in paths {
        if Path::new(&p).exists() && !out.contains(&p) {
            out.push(p);
        }
    }
    out
}
