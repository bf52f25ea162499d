//! The real-time check's system-call trap, in a test binary of its own: the trap's SIGSYS
//! handler is the process's, and the confinement's unit tests set theirs.

/// On a thread of its own (the filter stays with the thread): calls counted and made as
/// asked; a new thread refused; SIGSYS kept unblocked.
#[cfg(target_arch = "x86_64")]
#[test]
fn calls_are_counted_and_made() {
    let t = std::thread::spawn(|| {
        tb_cosim::realtime::trap::install().unwrap();
        tb_rtcount::reset();
        tb_rtcount::arm();
        // SAFETY: plain system calls.
        let pid = unsafe { libc::getpid() };
        let ppid = unsafe { libc::getppid() };
        let fd = unsafe { libc::open(c"/dev/null".as_ptr(), libc::O_RDONLY) };
        let closed = unsafe { libc::close(fd) };
        let mut set: libc::sigset_t = unsafe { std::mem::zeroed() };
        unsafe {
            libc::sigemptyset(&mut set);
            libc::sigaddset(&mut set, libc::SIGSYS);
            libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        }
        let after_block = unsafe { libc::getpid() };
        tb_rtcount::disarm();
        let spawn_failed = std::thread::Builder::new().spawn(|| ()).is_err();
        (
            pid,
            ppid,
            fd,
            closed,
            after_block,
            spawn_failed,
            tb_rtcount::snapshot(),
        )
    });
    let (pid, ppid, fd, closed, after_block, spawn_failed, counts) = t.join().unwrap();
    assert_eq!(pid, std::process::id() as i32);
    assert_eq!(after_block, pid, "SIGSYS stays unblocked");
    assert!(ppid > 0 && fd >= 0 && closed == 0);
    assert!(spawn_failed, "a thread cannot start once the trap is set");
    let calls = |nr: i64| {
        counts
            .syscalls
            .iter()
            .find(|(n, _)| *n == nr)
            .map_or(0, |(_, c)| *c)
    };
    assert_eq!(calls(libc::SYS_getpid), 2);
    assert_eq!(calls(libc::SYS_getppid), 1);
    assert_eq!(calls(libc::SYS_openat), 1);
    assert_eq!(calls(libc::SYS_close), 1);
    assert_eq!(calls(libc::SYS_rt_sigprocmask), 1);
    // Nothing else was counted: the counters are armed around these calls only.
    let total: u64 = counts.syscalls.iter().map(|(_, c)| c).sum();
    assert_eq!(total, 6, "{:?}", counts.syscalls);
}
