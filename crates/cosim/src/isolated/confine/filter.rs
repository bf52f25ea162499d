//! The confined worker's seccomp filters (`seccompiler`, from the Firecracker project, and
//! one small program of our own):
//!
//! - the calls an FMU has no business with, refused with `EPERM` ([`refused`]);
//! - **sockets**: `socket`, `socketpair`, `connect`, `bind`, `listen`, `accept` and
//!   `accept4` of every family, refused with `EPERM`. The worker's one socket is its
//!   channel to the host, made before the filter; with no way to make or connect another,
//!   neither a pathname Unix socket (which Landlock does not mediate) nor an abstract one
//!   is reachable. x86-64 has no `socketcall` multiplexer; the 32-bit ABI that has one is
//!   killed by every filter's architecture check;
//! - **processes**: `fork`, `vfork` and `clone` without `CLONE_THREAD` trapped: the
//!   worker's `SIGSYS` handler makes the call return `EAGAIN`, as a process limit would,
//!   and counts it ([`process_attempts`]), so that the worker can say what the FMU tried;
//!   `clone` with a namespace flag `EPERM`; `clone3`, whose flags a filter cannot read,
//!   `ENOSYS` (the C library then falls back to `clone` for its threads);
//! - **x32**: the x32 ABI's calls (`nr | 0x40000000`) share x86-64's architecture value and
//!   would pass a filter of x86-64 numbers; every such number is refused (`EPERM`, where a
//!   kernel without x32 would say `ENOSYS`: the difference shows the filter at work).

use super::ConfineError;
use seccompiler::{
    sock_filter, BpfProgram, SeccompAction, SeccompCmpArgLen, SeccompCmpOp, SeccompCondition,
    SeccompFilter, SeccompRule,
};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU32, Ordering};

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
        // Sockets: the channel to the host exists; no other can be made or reached.
        libc::SYS_socket,
        libc::SYS_socketpair,
        libc::SYS_connect,
        libc::SYS_bind,
        libc::SYS_listen,
        libc::SYS_accept,
        libc::SYS_accept4,
    ];
    #[cfg(target_arch = "x86_64")]
    calls.extend([libc::SYS_iopl, libc::SYS_ioperm]);
    // fchmodat2 (Linux 6.6), not yet named by every libc.
    #[cfg(target_arch = "x86_64")]
    calls.push(452);
    calls
}

fn arch() -> Result<seccompiler::TargetArch, ConfineError> {
    std::env::consts::ARCH
        .try_into()
        .map_err(|_| ConfineError::NoFilter {
            arch: std::env::consts::ARCH,
        })
}

fn cond(arg: u8, op: SeccompCmpOp, v: u64) -> Result<SeccompCondition, ConfineError> {
    SeccompCondition::new(arg, SeccompCmpArgLen::Dword, op, v).map_err(ConfineError::Filter)
}

fn rule(c: Vec<SeccompCondition>) -> Result<SeccompRule, ConfineError> {
    SeccompRule::new(c).map_err(ConfineError::Filter)
}

fn program(
    rules: BTreeMap<i64, Vec<SeccompRule>>,
    matched: SeccompAction,
) -> Result<BpfProgram, ConfineError> {
    let f = SeccompFilter::new(rules, SeccompAction::Allow, matched, arch()?)
        .map_err(ConfineError::Filter)?;
    BpfProgram::try_from(f).map_err(ConfineError::Filter)
}

/// The filters, in the order they are installed (each call is judged by all of them; the
/// strictest answer holds).
pub(super) fn filters() -> Result<Vec<BpfProgram>, ConfineError> {
    let mut rules: BTreeMap<i64, Vec<SeccompRule>> =
        refused().into_iter().map(|c| (c, Vec::new())).collect();
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
    let eperm = program(rules, SeccompAction::Errno(libc::EPERM as u32))?;
    let clone3 = program(
        BTreeMap::from([(libc::SYS_clone3, Vec::new())]),
        SeccompAction::Errno(libc::ENOSYS as u32),
    )?;
    // A new process: clone without CLONE_THREAD, fork, vfork.
    let mut processes: BTreeMap<i64, Vec<SeccompRule>> = BTreeMap::from([(
        libc::SYS_clone,
        vec![rule(vec![cond(
            0,
            SeccompCmpOp::MaskedEq(libc::CLONE_THREAD as u64),
            0,
        )?])?],
    )]);
    #[cfg(target_arch = "x86_64")]
    processes.extend([(libc::SYS_fork, Vec::new()), (libc::SYS_vfork, Vec::new())]);
    let processes = program(processes, process_action())?;
    Ok(vec![eperm, clone3, processes, x32()])
}

/// A program that refuses every x32 system-call number (EPERM) and leaves the rest to the
/// other filters. x32 calls carry x86-64's architecture value and `nr | 0x40000000`.
fn x32() -> BpfProgram {
    const LD_W_ABS: u16 = 0x20; // BPF_LD (0) | BPF_W (0) | BPF_ABS
    const JGE_K: u16 = 0x35; // BPF_JMP | BPF_JGE | BPF_K (0)
    const RET_K: u16 = 0x06; // BPF_RET | BPF_K (0)
    const RET_ERRNO: u32 = 0x0005_0000;
    const RET_ALLOW: u32 = 0x7fff_0000;
    let ins = |code, jt, jf, k| sock_filter { code, jt, jf, k };
    vec![
        // seccomp_data.nr at offset 0.
        ins(LD_W_ABS, 0, 0, 0),
        ins(JGE_K, 0, 1, 0x4000_0000),
        ins(RET_K, 0, 0, RET_ERRNO | libc::EPERM as u32),
        ins(RET_K, 0, 0, RET_ALLOW),
    ]
}

/// How many new processes the filter refused in this process.
pub fn process_attempts() -> u32 {
    PROCESS_ATTEMPTS.load(Ordering::Relaxed)
}

static PROCESS_ATTEMPTS: AtomicU32 = AtomicU32::new(0);

#[cfg(target_arch = "x86_64")]
fn process_action() -> SeccompAction {
    SeccompAction::Trap
}

/// Elsewhere the call fails with EAGAIN without being counted.
#[cfg(not(target_arch = "x86_64"))]
fn process_action() -> SeccompAction {
    SeccompAction::Errno(libc::EAGAIN as u32)
}

/// The SIGSYS handler of the trapped calls: the call returns -EAGAIN, the attempt counted,
/// and the first one said on stderr (async-signal-safe: an atomic and a write).
#[cfg(target_arch = "x86_64")]
extern "C" fn on_sigsys(_sig: libc::c_int, _info: *mut libc::siginfo_t, ctx: *mut libc::c_void) {
    if PROCESS_ATTEMPTS.fetch_add(1, Ordering::Relaxed) == 0 {
        const SAID: &[u8] = b"twinbench worker: the FMU tried to start a process; a confined worker runs no child processes (refused with EAGAIN)\n";
        // SAFETY: write(2) of a static buffer, async-signal-safe.
        unsafe { libc::write(2, SAID.as_ptr().cast(), SAID.len()) };
    }
    // SAFETY: the kernel hands a ucontext_t to an SA_SIGINFO handler; its RAX is the
    // trapped call's return value.
    unsafe {
        let uc = ctx.cast::<libc::ucontext_t>();
        (*uc).uc_mcontext.gregs[libc::REG_RAX as usize] = -(libc::EAGAIN as i64);
    }
}

/// Installs the SIGSYS handler of the process trap (before the filters).
pub(super) fn install_trap() -> Result<(), ConfineError> {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: sigaction with a handler that only touches an atomic, the context and stderr.
    unsafe {
        let mut sa: libc::sigaction = std::mem::zeroed();
        sa.sa_sigaction = on_sigsys as *const () as usize;
        sa.sa_flags = libc::SA_SIGINFO;
        libc::sigemptyset(&mut sa.sa_mask);
        if libc::sigaction(libc::SIGSYS, &sa, std::ptr::null_mut()) != 0 {
            return Err(ConfineError::last_os("cannot handle SIGSYS"));
        }
    }
    Ok(())
}

/// Applies the filters to this thread and what it starts.
pub(super) fn apply() -> Result<(), ConfineError> {
    install_trap()?;
    for f in filters()? {
        seccompiler::apply_filter(&f).map_err(ConfineError::Seccomp)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs `f` on a thread of its own with `programs` applied to that thread only (and
    /// no_new_privs, which a filter needs), so the test process stays unfiltered.
    fn filtered<T: Send + 'static>(
        programs: Vec<BpfProgram>,
        f: impl FnOnce() -> T + Send + 'static,
    ) -> T {
        std::thread::spawn(move || {
            // SAFETY: prctl with documented arguments, for this thread.
            assert_eq!(
                unsafe { libc::prctl(libc::PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) },
                0
            );
            for p in &programs {
                seccompiler::apply_filter(p).unwrap();
            }
            f()
        })
        .join()
        .unwrap()
    }

    fn errno() -> i32 {
        std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
    }

    #[test]
    fn no_socket_of_any_family_can_be_made_or_connected() {
        let all = filters().unwrap();
        let got = filtered(all, || {
            // SAFETY: plain system calls with valid arguments.
            unsafe {
                let unix = libc::socket(libc::AF_UNIX, libc::SOCK_STREAM, 0);
                let e1 = errno();
                let mut sv = [0i32; 2];
                let pair = libc::socketpair(libc::AF_UNIX, libc::SOCK_STREAM, 0, sv.as_mut_ptr());
                let e2 = errno();
                let inet = libc::socket(libc::AF_INET, libc::SOCK_STREAM, 0);
                let e3 = errno();
                // connect on a descriptor that is no socket: refused before the kernel looks.
                let c = libc::connect(0, std::ptr::null(), 0);
                let e4 = errno();
                (unix, e1, pair, e2, inet, e3, c, e4)
            }
        });
        assert_eq!((got.0, got.1), (-1, libc::EPERM), "socket(AF_UNIX)");
        assert_eq!((got.2, got.3), (-1, libc::EPERM), "socketpair");
        assert_eq!((got.4, got.5), (-1, libc::EPERM), "socket(AF_INET)");
        assert_eq!((got.6, got.7), (-1, libc::EPERM), "connect");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn x32_numbers_are_refused_by_the_filter_not_only_by_the_kernel() {
        // getpid as an x32 call: a kernel without x32 says ENOSYS, the filter EPERM.
        let x32_getpid = 0x4000_0000 | libc::SYS_getpid;
        let filtered = filtered(vec![x32()], move || {
            // SAFETY: as above.
            let r = unsafe { libc::syscall(x32_getpid) };
            let e = errno();
            // SAFETY: the x86-64 getpid still passes.
            let pid = unsafe { libc::syscall(libc::SYS_getpid) };
            (r, e, pid)
        });
        assert_eq!((filtered.0, filtered.1), (-1, libc::EPERM));
        assert_eq!(filtered.2, std::process::id() as i64);
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn a_new_process_is_refused_with_eagain_and_counted_while_threads_start() {
        install_trap().unwrap();
        let before = process_attempts();
        let all = filters().unwrap();
        let (fork, e, thread_ok) = filtered(all, || {
            // SAFETY: fork refused by the filter (no child is made); were it not, the child
            // ends at once.
            let p = unsafe { libc::fork() };
            if p == 0 {
                unsafe { libc::_exit(0) };
            }
            let e = errno();
            // Threads still start (clone with CLONE_THREAD, after clone3's ENOSYS).
            let t = std::thread::spawn(|| 7).join().unwrap_or(0) == 7;
            (p, e, t)
        });
        assert_eq!((fork, e), (-1, libc::EAGAIN));
        assert!(thread_ok, "a thread could not start under the filter");
        assert!(process_attempts() > before);
    }
}
