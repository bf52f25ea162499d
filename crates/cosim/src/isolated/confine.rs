//! The confinement of an isolated worker: what an FMU run with `--isolate` can do.
//!
//! Before the worker loads anything, for good, for itself and everything it starts:
//!
//! - **a process tree that ends with the run**: the worker runs in a PID namespace of its
//!   own (root: `unshare(CLONE_NEWPID)`; another user: with a user namespace), under an init
//!   that ends with the worker; the kernel then kills every process left in the namespace
//!   (a daemon the FMU forked included), and a process in it cannot name, signal or trace
//!   one outside; an IPC and a network namespace of its own too (no System V IPC object,
//!   abstract Unix socket or network interface of the host's);
//! - **no privileges**: every capability dropped (bounding, ambient, effective, permitted,
//!   inheritable) with the securebits locked, so that a root worker is root without any
//!   capability; `no_new_privs`, so no exec gains any;
//! - **a filtered system-call set** (`seccompiler`): no chmod/chown, mount, ptrace, module
//!   loading, namespaces, raw devices (mknod), extended attributes or file times, BPF,
//!   `io_uring`, keyrings, clock or host names; sockets of the Unix family only (no network
//!   of any kind, whatever the kernel's Landlock has);
//! - **Landlock** (the `landlock` crate): write access to the worker's scratch folder only
//!   (its working directory, `TMPDIR` and `HOME`); read and execute access to the system's
//!   libraries, a few named system files, its own `/proc` entry, the FMU's unpacked folder
//!   and the files the host names (preloaded libraries, the files of `*_file` parameters),
//!   and nothing else (the user's home, the project, other FMUs' folders); no TCP (Landlock
//!   4 and later); no signals to and no abstract Unix sockets of processes outside
//!   (Landlock 6 and later).
//!
//! What is required: a PID namespace, the seccomp filter and Landlock 3 (Linux 6.2) for the
//! file system. Where one of them cannot be set up the worker says why and exits with
//! [`CANNOT_CONFINE`] before loading anything; the host refuses the FMU unless the user
//! asked for crash isolation only (`--isolate=crash-only`, [`MODE_ENV`]).

use landlock::{
    path_beneath_rules, Access, AccessFs, AccessNet, LandlockStatus, Ruleset, RulesetAttr,
    RulesetCreatedAttr, RulesetStatus, Scope, ABI,
};
use seccompiler::{
    BpfProgram, SeccompAction, SeccompCmpArgLen, SeccompCmpOp, SeccompCondition, SeccompFilter,
    SeccompRule,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The worker's exit code when it cannot confine itself (before anything was loaded).
pub const CANNOT_CONFINE: i32 = 5;

pub use tb_fmi::import::sandbox::MODE_ENV;

/// The environment variable through which the host hands the worker its [`Spec`] (JSON).
pub(crate) const SPEC_ENV: &str = "TWINBENCH_WORKER_CONFINE";

/// What the host grants a worker.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Spec {
    /// The only folder the worker can write (created by the host, removed after the run).
    pub scratch: PathBuf,
    /// Folders and files it can read (and execute) besides the system's.
    pub read: Vec<PathBuf>,
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
fn drop_capabilities() -> Result<(), String> {
    // SAFETY: prctl and capset with documented arguments; no memory is handed over but the
    // two capset structures, which live across the call.
    unsafe {
        if libc::prctl(libc::PR_CAPBSET_READ, 0, 0, 0, 0) >= 0 {
            let mut cap = 0;
            while libc::prctl(libc::PR_CAPBSET_READ, cap, 0, 0, 0) >= 0 {
                if libc::prctl(libc::PR_CAPBSET_DROP, cap, 0, 0, 0) != 0
                    && libc::prctl(libc::PR_CAPBSET_READ, cap, 0, 0, 0) == 1
                {
                    return Err(format!(
                        "cannot drop capability {cap} from the bounding set: {}",
                        std::io::Error::last_os_error()
                    ));
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
            return Err(format!(
                "cannot lock the securebits: {}",
                std::io::Error::last_os_error()
            ));
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
            return Err(format!(
                "cannot drop the capabilities: {}",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// The system calls an FMU has no business with, refused with EPERM.
fn refused() -> Vec<i64> {
    let mut calls = vec![
        libc::SYS_chmod,
        libc::SYS_fchmod,
        libc::SYS_fchmodat,
        libc::SYS_chown,
        libc::SYS_fchown,
        libc::SYS_lchown,
        libc::SYS_fchownat,
        libc::SYS_mount,
        libc::SYS_umount2,
        libc::SYS_pivot_root,
        libc::SYS_chroot,
        libc::SYS_ptrace,
        libc::SYS_process_vm_readv,
        libc::SYS_process_vm_writev,
        libc::SYS_init_module,
        libc::SYS_finit_module,
        libc::SYS_delete_module,
        libc::SYS_kexec_load,
        libc::SYS_kexec_file_load,
        libc::SYS_reboot,
        libc::SYS_swapon,
        libc::SYS_swapoff,
        libc::SYS_setns,
        libc::SYS_unshare,
        libc::SYS_mknod,
        libc::SYS_mknodat,
        libc::SYS_setxattr,
        libc::SYS_lsetxattr,
        libc::SYS_fsetxattr,
        libc::SYS_removexattr,
        libc::SYS_lremovexattr,
        libc::SYS_fremovexattr,
        libc::SYS_utime,
        libc::SYS_utimes,
        libc::SYS_utimensat,
        libc::SYS_futimesat,
        libc::SYS_acct,
        libc::SYS_quotactl,
        libc::SYS_bpf,
        libc::SYS_perf_event_open,
        libc::SYS_keyctl,
        libc::SYS_add_key,
        libc::SYS_request_key,
        libc::SYS_open_by_handle_at,
        libc::SYS_name_to_handle_at,
        libc::SYS_settimeofday,
        libc::SYS_clock_settime,
        libc::SYS_clock_adjtime,
        libc::SYS_adjtimex,
        libc::SYS_sethostname,
        libc::SYS_setdomainname,
        libc::SYS_syslog,
        libc::SYS_userfaultfd,
        libc::SYS_io_uring_setup,
        libc::SYS_io_uring_enter,
        libc::SYS_io_uring_register,
        libc::SYS_pidfd_getfd,
        libc::SYS_move_mount,
        libc::SYS_open_tree,
        libc::SYS_fsopen,
        libc::SYS_fsmount,
        libc::SYS_fsconfig,
        libc::SYS_fspick,
        libc::SYS_mount_setattr,
    ];
    #[cfg(target_arch = "x86_64")]
    calls.extend([libc::SYS_iopl, libc::SYS_ioperm]);
    // fchmodat2 (Linux 6.6), not yet named by every libc.
    #[cfg(target_arch = "x86_64")]
    calls.push(452);
    calls
}

fn arch() -> Result<seccompiler::TargetArch, String> {
    std::env::consts::ARCH
        .try_into()
        .map_err(|_| format!("no seccomp filter for {}", std::env::consts::ARCH))
}

/// The seccomp filters: the refused calls and every socket but a Unix one (EPERM), clone
/// with a namespace flag (EPERM), and clone3, whose flags a filter cannot read (ENOSYS, so
/// that the C library falls back to clone).
fn filters() -> Result<Vec<BpfProgram>, String> {
    let cond = |arg: u8, op: SeccompCmpOp, v: u64| {
        SeccompCondition::new(arg, SeccompCmpArgLen::Dword, op, v).map_err(|e| e.to_string())
    };
    let rule = |c: Vec<SeccompCondition>| SeccompRule::new(c).map_err(|e| e.to_string());
    let mut rules: BTreeMap<i64, Vec<SeccompRule>> =
        refused().into_iter().map(|c| (c, Vec::new())).collect();
    let not_unix = rule(vec![cond(0, SeccompCmpOp::Ne, libc::AF_UNIX as u64)?])?;
    rules.insert(libc::SYS_socket, vec![not_unix.clone()]);
    rules.insert(libc::SYS_socketpair, vec![not_unix]);
    let namespaces = [
        libc::CLONE_NEWNS,
        libc::CLONE_NEWUTS,
        libc::CLONE_NEWIPC,
        libc::CLONE_NEWUSER,
        libc::CLONE_NEWPID,
        libc::CLONE_NEWNET,
        libc::CLONE_NEWCGROUP,
    ];
    rules.insert(
        libc::SYS_clone,
        namespaces
            .iter()
            .map(|&f| rule(vec![cond(0, SeccompCmpOp::MaskedEq(f as u64), f as u64)?]))
            .collect::<Result<_, _>>()?,
    );
    let eperm = SeccompFilter::new(
        rules,
        SeccompAction::Allow,
        SeccompAction::Errno(libc::EPERM as u32),
        arch()?,
    )
    .map_err(|e| e.to_string())?;
    let clone3 = SeccompFilter::new(
        BTreeMap::from([(libc::SYS_clone3, Vec::new())]),
        SeccompAction::Allow,
        SeccompAction::Errno(libc::ENOSYS as u32),
        arch()?,
    )
    .map_err(|e| e.to_string())?;
    [eperm, clone3]
        .into_iter()
        .map(|f| BpfProgram::try_from(f).map_err(|e| e.to_string()))
        .collect()
}

/// Confines this process (single-threaded: Landlock and seccomp hold for the calling thread
/// and whatever it starts afterwards). Called in the worker, inside its PID namespace.
pub fn confine(spec: &Spec) -> Result<(), String> {
    drop_capabilities()?;
    std::env::set_current_dir(&spec.scratch).map_err(|e| {
        format!(
            "{}: cannot enter the scratch folder: {e}",
            spec.scratch.display()
        )
    })?;
    for var in ["TMPDIR", "TMP", "TEMP", "HOME"] {
        std::env::set_var(var, &spec.scratch);
    }
    // SAFETY: prctl with documented arguments.
    if unsafe { libc::prctl(libc::PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) } != 0 {
        return Err(format!(
            "cannot set no_new_privs: {}",
            std::io::Error::last_os_error()
        ));
    }
    // Landlock first (its rules open the paths), then seccomp.
    let latest = ABI::V6;
    let read = AccessFs::from_read(latest);
    let mut paths: Vec<PathBuf> = SYSTEM_READ.iter().map(PathBuf::from).collect();
    // This process's own /proc entry (not /proc/self: a rule holds for the folder it names
    // when made).
    paths.push(PathBuf::from(format!("/proc/{}", std::process::id())));
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
        .map_err(|e| format!("Landlock: {e}"))?;
    let abi = match status.landlock {
        LandlockStatus::Available { effective_abi, .. } => effective_abi as i32,
        LandlockStatus::NotEnabled => {
            return Err("Landlock is disabled on this system (lsm= boot parameter)".into())
        }
        _ => return Err("this kernel has no Landlock".into()),
    };
    if status.ruleset == RulesetStatus::NotEnforced || abi < 3 {
        return Err(format!(
            "this kernel's Landlock (ABI {abi}) cannot keep the FMU from truncating files it may not write (ABI 3, Linux 6.2, is needed)"
        ));
    }
    for f in filters()? {
        seccompiler::apply_filter(&f).map_err(|e| format!("seccomp: {e}"))?;
    }
    Ok(())
}

/// The PID, IPC and network namespaces the worker runs in: root makes them; another user
/// makes them with a user namespace of its own. Called in the guard before it starts the worker's init.
pub fn new_pid_namespace() -> Result<(), String> {
    // SAFETY: unshare with documented flags, in a single-threaded process.
    let r = unsafe {
        // With the PID namespace an IPC and a network namespace of its own: the user's System
        // V shared memory, semaphores and message queues, its abstract Unix sockets and
        // every network interface (loopback included) are out of reach, whatever the
        // worker's user id and the kernel's Landlock.
        let flags = libc::CLONE_NEWPID | libc::CLONE_NEWIPC | libc::CLONE_NEWNET;
        if libc::geteuid() == 0 {
            libc::unshare(flags)
        } else {
            libc::unshare(libc::CLONE_NEWUSER | flags)
        }
    };
    if r != 0 {
        return Err(format!(
            "cannot make a PID, IPC and network namespace (so that nothing the FMU starts outlives the run, and it reaches no other process's shared memory or sockets): {}",
            std::io::Error::last_os_error()
        ));
    }
    Ok(())
}

/// The host's side: the scratch folder of one worker, removed with it.
pub(crate) struct Scratch {
    pub path: PathBuf,
}

impl Scratch {
    pub fn new() -> std::io::Result<Scratch> {
        use std::os::unix::fs::DirBuilderExt;
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let path = std::env::temp_dir().join(format!(
            "twinbench-worker-{}-{n}-{nanos:08x}",
            std::process::id()
        ));
        std::fs::DirBuilder::new().mode(0o700).create(&path)?;
        Ok(Scratch { path })
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // remove_dir_all follows no link the FMU left in it.
        let _ = std::fs::remove_dir_all(&self.path);
    }
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
