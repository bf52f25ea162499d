//! The system-call trap of a real-time check: every system call the stepping thread makes
//! is counted by number (in [`tb_rtcount`], while armed) and then made as asked.
//!
//! A seccomp filter on the worker's stepping thread (and what it starts) returns
//! `SECCOMP_RET_TRAP` for every call but two: `rt_sigreturn` (the end of a signal
//! handler) and the calls made from one instruction of this module's own, [`raw_syscall`].
//! The kernel then sends SIGSYS before the call runs; the handler counts the call and
//! makes it through `raw_syscall` with the trapped registers, and puts the result where
//! the caller finds it. So the FMU runs as it would, every call seen, whatever filter the
//! worker's confinement adds (the confinement's refusals still hold: it sees the call
//! `raw_syscall` makes). Trapping is slow (microseconds a call), which matters only to
//! an FMU that calls the system, and that one fails the check anyway.
//!
//! Not emulated: starting a thread or a process (`clone`, `clone3`, `fork`, `vfork`,
//! `execve`, `execveat`) fails with EAGAIN once the trap is set (a new thread cannot
//! start inside a signal handler); blocking SIGSYS or handling it otherwise is refused
//! with EPERM (it would end the process). x86-64 only; elsewhere the check says that
//! system calls were not counted.

use std::sync::atomic::{AtomicBool, Ordering};

/// Why the system calls of a check cannot be counted.
#[derive(Debug, thiserror::Error)]
pub enum TrapError {
    #[error("system calls are counted on x86-64 Linux only")]
    Unsupported,
    #[error("cannot handle SIGSYS: {0}")]
    Handler(std::io::Error),
    #[error("cannot set the system-call trap (seccomp): {0}")]
    Seccomp(seccompiler::Error),
}

/// Why system calls cannot be counted here.
#[cfg(not(target_arch = "x86_64"))]
pub fn install() -> Result<(), TrapError> {
    Err(TrapError::Unsupported)
}

#[cfg(target_arch = "x86_64")]
pub use x86_64::install;

/// Set once the trap is on this process's stepping thread.
static INSTALLED: AtomicBool = AtomicBool::new(false);

pub fn installed() -> bool {
    INSTALLED.load(Ordering::SeqCst)
}

#[cfg(target_arch = "x86_64")]
mod x86_64 {
    use super::INSTALLED;
    use seccompiler::sock_filter;
    use std::sync::atomic::Ordering;

    // raw_syscall(nr, a1..a6): the only instruction the filter lets through. The System V
    // arguments (rdi, rsi, rdx, rcx, r8, r9, stack) move to the kernel's (rax, rdi, rsi,
    // rdx, r10, r8, r9).
    std::arch::global_asm!(
        ".pushsection .text.tb_rt_raw_syscall,\"ax\",@progbits",
        ".p2align 4",
        ".globl tb_rt_raw_syscall",
        ".hidden tb_rt_raw_syscall",
        ".type tb_rt_raw_syscall,@function",
        "tb_rt_raw_syscall:",
        "mov rax, rdi",
        "mov rdi, rsi",
        "mov rsi, rdx",
        "mov rdx, rcx",
        "mov r10, r8",
        "mov r8, r9",
        "mov r9, qword ptr [rsp + 8]",
        ".globl tb_rt_raw_syscall_insn",
        ".hidden tb_rt_raw_syscall_insn",
        "tb_rt_raw_syscall_insn:",
        "syscall",
        "ret",
        ".size tb_rt_raw_syscall, .-tb_rt_raw_syscall",
        ".popsection",
    );

    extern "C" {
        fn tb_rt_raw_syscall(nr: i64, a: i64, b: i64, c: i64, d: i64, e: i64, f: i64) -> i64;
        static tb_rt_raw_syscall_insn: u8;
    }

    /// A system call made from the one instruction the filter allows.
    ///
    /// # Safety
    /// As the system call itself.
    pub(super) unsafe fn raw_syscall(nr: i64, args: [i64; 6]) -> i64 {
        tb_rt_raw_syscall(nr, args[0], args[1], args[2], args[3], args[4], args[5])
    }

    const AUDIT_ARCH_X86_64: u32 = 0xC000_003E;
    /// `siginfo_t`'s SIGSYS fields: the call's number and architecture.
    const SI_SYSCALL: usize = 24;
    const SI_ARCH: usize = 28;

    /// The filter: allow `rt_sigreturn` and the calls made at `raw_syscall`'s instruction
    /// (the kernel reports the address after it; the instruction's own is allowed too), trap
    /// everything else.
    fn program(insn: u64) -> Vec<sock_filter> {
        const LD_W_ABS: u16 = 0x20;
        const JEQ_K: u16 = 0x15;
        const RET_K: u16 = 0x06;
        const RET_TRAP: u32 = 0x0003_0000;
        const RET_ALLOW: u32 = 0x7fff_0000;
        let after = insn + 2;
        let hi = |x: u64| (x >> 32) as u32;
        let lo = |x: u64| x as u32;
        assert_eq!(hi(insn), hi(after), "the instruction does not cross 4 GiB");
        let ins = |code, jt, jf, k| sock_filter { code, jt, jf, k };
        vec![
            // 0: arch; a call of another ABI is trapped (and refused by the handler).
            ins(LD_W_ABS, 0, 0, 4),
            ins(JEQ_K, 0, 7, AUDIT_ARCH_X86_64),
            // 2: rt_sigreturn runs as it is.
            ins(LD_W_ABS, 0, 0, 0),
            ins(JEQ_K, 6, 0, libc::SYS_rt_sigreturn as u32),
            // 4: the instruction pointer's high half, then its low half.
            ins(LD_W_ABS, 0, 0, 12),
            ins(JEQ_K, 0, 3, hi(insn)),
            ins(LD_W_ABS, 0, 0, 8),
            ins(JEQ_K, 2, 0, lo(after)),
            ins(JEQ_K, 1, 0, lo(insn)),
            // 9: trap; 10: allow.
            ins(RET_K, 0, 0, RET_TRAP),
            ins(RET_K, 0, 0, RET_ALLOW),
        ]
    }

    /// Counts the trapped call and makes it (async-signal-safe: atomics and system calls).
    extern "C" fn on_sigsys(_sig: libc::c_int, info: *mut libc::siginfo_t, ctx: *mut libc::c_void) {
        // SAFETY: the kernel hands an SA_SIGINFO handler a valid siginfo_t and ucontext_t;
        // for SIGSYS the call's number and architecture are at these offsets.
        unsafe {
            let raw = info.cast::<u8>();
            let nr = raw.add(SI_SYSCALL).cast::<i32>().read() as i64;
            let arch = raw.add(SI_ARCH).cast::<u32>().read();
            let uc = ctx.cast::<libc::ucontext_t>();
            let g = &mut (*uc).uc_mcontext.gregs;
            let result = if arch != AUDIT_ARCH_X86_64 {
                tb_rtcount::count_syscall(tb_rtcount::SYSCALL_SLOTS as i64 - 1);
                -(libc::ENOSYS as i64)
            } else {
                tb_rtcount::count_syscall(nr);
                let args = [
                    g[libc::REG_RDI as usize],
                    g[libc::REG_RSI as usize],
                    g[libc::REG_RDX as usize],
                    g[libc::REG_R10 as usize],
                    g[libc::REG_R8 as usize],
                    g[libc::REG_R9 as usize],
                ];
                emulate(nr, args)
            };
            g[libc::REG_RAX as usize] = result;
        }
    }

    /// The trapped call made, or refused where it cannot be made from a handler.
    unsafe fn emulate(nr: i64, mut args: [i64; 6]) -> i64 {
        match nr {
            libc::SYS_clone
            | libc::SYS_clone3
            | libc::SYS_fork
            | libc::SYS_vfork
            | libc::SYS_execve
            | libc::SYS_execveat => -(libc::EAGAIN as i64),
            libc::SYS_rt_sigaction if args[0] == libc::SIGSYS as i64 && args[1] != 0 => {
                -(libc::EPERM as i64)
            }
            libc::SYS_rt_sigprocmask if args[1] != 0 && args[0] != libc::SIG_UNBLOCK as i64 => {
                // The new mask without SIGSYS (a blocked SIGSYS would end the process at
                // the next call); the caller's set is not changed.
                let mut set: u64 = (args[1] as *const u64).read_unaligned();
                set &= !(1u64 << (libc::SIGSYS - 1));
                args[1] = &set as *const u64 as i64;
                raw_syscall(nr, args)
            }
            _ => raw_syscall(nr, args),
        }
    }

    /// Sets the trap on the calling thread (and whatever it starts). For good: a seccomp
    /// filter cannot be taken off; the worker that checks ends with the check.
    pub fn install() -> Result<(), super::TrapError> {
        if INSTALLED.load(Ordering::SeqCst) {
            return Ok(());
        }
        // SAFETY: sigaction with a handler that only touches atomics, its context and the
        // system; the address of a symbol of this module.
        let insn = unsafe {
            let mut sa: libc::sigaction = std::mem::zeroed();
            sa.sa_sigaction = on_sigsys as *const () as usize;
            sa.sa_flags = libc::SA_SIGINFO;
            libc::sigemptyset(&mut sa.sa_mask);
            if libc::sigaction(libc::SIGSYS, &sa, std::ptr::null_mut()) != 0 {
                return Err(super::TrapError::Handler(std::io::Error::last_os_error()));
            }
            std::ptr::addr_of!(tb_rt_raw_syscall_insn) as u64
        };
        seccompiler::apply_filter(&program(insn)).map_err(super::TrapError::Seccomp)?;
        INSTALLED.store(true, Ordering::SeqCst);
        Ok(())
    }
}
