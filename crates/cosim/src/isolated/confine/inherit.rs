//! What a confined worker inherits from the host: an environment from an allowlist, never
//! the host's (cloud keys, tokens, `SSH_AUTH_SOCK`), and no descriptor but its channel and
//! stdio (a CI runner's or a shell's `3>>file` would otherwise be a way out of the sandbox,
//! as Landlock does not check files already open). Both are done in the host's spawn and
//! again in the worker before it loads anything.

use std::ffi::OsString;

/// The environment variable naming further variables a confined worker is given (comma-
/// separated names): those an FMU's own documentation asks for (a licence server, its
/// installation folder, `LD_LIBRARY_PATH` for a runtime it needs).
pub const PASS_ENV: &str = "TWINBENCH_WORKER_ENV";

/// Variables every confined worker is given when the host has them: the locale, the time
/// zone, the search path for programs, the worker's own logging, and an embedded Python's
/// search path (a pythonfmu FMU). `HOME` and the temporary folders are set to the scratch
/// folder by the worker itself.
const KEPT: &[&str] = &[
    "PATH",
    "LANG",
    "LANGUAGE",
    "TZ",
    "RUST_LOG",
    "RUST_BACKTRACE",
    "PYTHONHOME",
    "PYTHONPATH",
];

/// Whether `name` is given to a confined worker (with the names `extra` passes).
pub fn kept(name: &str, extra: &[String]) -> bool {
    KEPT.contains(&name) || name.starts_with("LC_") || extra.iter().any(|e| e == name)
}

/// The names [`PASS_ENV`] passes on.
pub fn passed_names() -> Vec<String> {
    std::env::var(PASS_ENV)
        .map(|v| {
            v.split(',')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(String::from)
                .collect()
        })
        .unwrap_or_default()
}

/// The host's environment as a confined worker gets it.
pub fn environment(extra: &[String]) -> Vec<(OsString, OsString)> {
    std::env::vars_os()
        .filter(|(k, _)| k.to_str().is_some_and(|k| kept(k, extra)))
        .collect()
}

/// In the worker: removes every variable not on the list (single-threaded, before anything
/// is loaded).
pub fn keep_only(extra: &[String]) {
    let gone: Vec<OsString> = std::env::vars_os()
        .map(|(k, _)| k)
        .filter(|k| !k.to_str().is_some_and(|k| kept(k, extra)))
        .collect();
    for k in gone {
        std::env::remove_var(k);
    }
}

/// Marks every descriptor from `first` up close-on-exec (in a spawned child between fork
/// and exec: async-signal-safe, no allocation). `close_range` (Linux 5.11) where the kernel
/// has it, else one `fcntl` per descriptor below `limit`.
///
/// # Safety
/// Only system calls: safe in a child after `fork`.
pub unsafe fn cloexec_from(first: u32, limit: u32) {
    const CLOSE_RANGE_CLOEXEC: libc::c_uint = 1 << 2;
    if libc::syscall(libc::SYS_close_range, first, u32::MAX, CLOSE_RANGE_CLOEXEC) == 0 {
        return;
    }
    for fd in first..limit {
        let flags = libc::fcntl(fd as i32, libc::F_GETFD);
        if flags >= 0 {
            libc::fcntl(fd as i32, libc::F_SETFD, flags | libc::FD_CLOEXEC);
        }
    }
}

/// In the worker: closes every descriptor but stdio and `keep` (the channel).
pub fn close_all_but(keep: i32) {
    // SAFETY: close_range and close on this process's own descriptors; none but `keep` and
    // stdio is in use (called before anything is loaded or any thread started).
    unsafe {
        let range = |from: u32, to: u32| {
            from > to || libc::syscall(libc::SYS_close_range, from, to, 0 as libc::c_uint) == 0
        };
        let keep = keep.max(3) as u32;
        if range(3, keep - 1) && range(keep + 1, u32::MAX) {
            return;
        }
        // Without close_range (Linux < 5.9): the descriptors /proc lists.
        let open: Vec<i32> = std::fs::read_dir("/proc/self/fd")
            .map(|d| {
                d.flatten()
                    .filter_map(|e| e.file_name().to_str()?.parse().ok())
                    .collect()
            })
            .unwrap_or_default();
        for fd in open {
            if fd > 2 && fd != keep as i32 {
                libc::close(fd);
            }
        }
    }
}

/// The soft limit of open descriptors (the fallback's bound in [`cloexec_from`]).
pub fn descriptor_limit() -> u32 {
    let mut l = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit into a local structure.
    if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut l) } == 0 {
        l.rlim_cur.min(1 << 20) as u32
    } else {
        65_536
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_allowlist_keeps_the_locale_and_what_is_passed_and_nothing_else() {
        assert!(kept("LANG", &[]));
        assert!(kept("LC_NUMERIC", &[]));
        assert!(kept("PATH", &[]));
        for secret in [
            "AWS_SECRET_ACCESS_KEY",
            "SSH_AUTH_SOCK",
            "GITHUB_TOKEN",
            "HOME",
            "LD_PRELOAD",
            "LD_LIBRARY_PATH",
            "TWINBENCH_WORKER_LIMITS",
        ] {
            assert!(!kept(secret, &[]), "{secret}");
        }
        assert!(kept("LD_LIBRARY_PATH", &["LD_LIBRARY_PATH".into()]));
    }
}
