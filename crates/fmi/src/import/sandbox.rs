//! The isolated worker's sandbox: before it loads an FMU's library, the worker makes the
//! store of unpacked FMUs read-only for itself and everything it starts, with Landlock (an
//! unprivileged Linux security module, 5.13 and later). Nothing the FMU's code does can
//! lift it: not root, not `CAP_SYS_ADMIN`, not another path to the same files (rules hold
//! on the files themselves, so a bind mount or `/proc/<pid>/root` reaches nothing more), and
//! Landlock forbids the sandboxed process to trace the unsandboxed host.
//!
//! Landlock grants, it never denies: writes are forbidden everywhere except beneath the
//! folders and files granted. The worker grants them on everything beside the path from
//! `/` to the store: every entry of `/`, of each folder on the way and of the store's own
//! folder except the next one on the way. So the worker can write everywhere it could
//! before except into the store, with one limit: it can create or remove no entry directly
//! in a folder on the way to the store (`/`, the home folder, `~/.cache`, `~/.cache/twinbench`
//! for the default store); files there stay writable. (A private mount namespace with the
//! store bind-mounted read-only would not have that limit, but as root the FMU undoes it
//! with one `umount`, and in a user namespace of its own too.)

use std::ffi::CString;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::os::unix::ffi::OsStrExt;
use std::path::{Path, PathBuf};

/// Set to `off`, workers are not sandboxed and the host verifies libraries as when the
/// kernel has no Landlock (tests; a system whose Landlock breaks an FMU). Set to `assume`,
/// the host takes workers as sandboxed without asking the kernel (instruction counts under
/// valgrind, which does not know Landlock's system calls; a worker that then cannot
/// sandbox itself still says so).
pub const SANDBOX_ENV: &str = "TWINBENCH_WORKER_SANDBOX";

const CREATE_RULESET_VERSION: u32 = 1;
const RULE_PATH_BENEATH: u32 = 1;

const WRITE_FILE: u64 = 1 << 1;
const REMOVE_DIR: u64 = 1 << 4;
const REMOVE_FILE: u64 = 1 << 5;
const MAKE_CHAR: u64 = 1 << 6;
const MAKE_DIR: u64 = 1 << 7;
const MAKE_REG: u64 = 1 << 8;
const MAKE_SOCK: u64 = 1 << 9;
const MAKE_FIFO: u64 = 1 << 10;
const MAKE_BLOCK: u64 = 1 << 11;
const MAKE_SYM: u64 = 1 << 12;
const REFER: u64 = 1 << 13;
const TRUNCATE: u64 = 1 << 14;

#[repr(C)]
struct RulesetAttr {
    handled_access_fs: u64,
}

#[repr(C, packed)]
struct PathBeneathAttr {
    allowed_access: u64,
    parent_fd: i32,
}

/// Landlock's ABI version, or why there is none.
fn abi() -> Result<i64, String> {
    // SAFETY: the documented version query: no attribute, size 0.
    let v = unsafe {
        libc::syscall(
            libc::SYS_landlock_create_ruleset,
            std::ptr::null::<RulesetAttr>(),
            0usize,
            CREATE_RULESET_VERSION,
        )
    };
    if v < 1 {
        let e = std::io::Error::last_os_error();
        return Err(match e.raw_os_error() {
            Some(libc::ENOSYS) => "this kernel has no Landlock".to_string(),
            Some(libc::EOPNOTSUPP) => "Landlock is disabled on this system".to_string(),
            _ => format!("Landlock is not available: {e}"),
        });
    }
    Ok(v)
}

/// Whether workers can be sandboxed here; the reason when not (memorised: the kernel does
/// not change under a process).
pub fn available() -> Result<(), String> {
    static ANSWER: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    ANSWER
        .get_or_init(|| {
            if std::env::var_os("TWINBENCH_ISOLATE").is_some_and(|v| v == "crash-only") {
                return Err("TWINBENCH_ISOLATE=crash-only".into());
            }
            match std::env::var_os(SANDBOX_ENV) {
                Some(v) if v == "off" => return Err(format!("{SANDBOX_ENV}=off")),
                Some(v) if v == "assume" => return Ok(()),
                _ => {}
            }
            abi().map(|_| ())
        })
        .clone()
}

/// The rights the sandbox restricts for an ABI version: every write.
fn handled(abi: i64) -> u64 {
    let mut r = WRITE_FILE
        | REMOVE_DIR
        | REMOVE_FILE
        | MAKE_CHAR
        | MAKE_DIR
        | MAKE_REG
        | MAKE_SOCK
        | MAKE_FIFO
        | MAKE_BLOCK
        | MAKE_SYM;
    if abi >= 2 {
        r |= REFER;
    }
    if abi >= 3 {
        r |= TRUNCATE;
    }
    r
}

fn open_path(path: &Path) -> Option<OwnedFd> {
    let c = CString::new(path.as_os_str().as_bytes()).ok()?;
    // SAFETY: open on a NUL-terminated path; the result is owned.
    let fd = unsafe {
        libc::open(
            c.as_ptr(),
            libc::O_PATH | libc::O_NOFOLLOW | libc::O_CLOEXEC,
        )
    };
    // SAFETY: a descriptor just opened and owned by nobody else.
    (fd >= 0).then(|| unsafe { OwnedFd::from_raw_fd(fd) })
}

/// Makes `store` (and everything beneath it) read-only for this process and its future
/// children, for good. Call before any other thread exists: Landlock restricts the calling
/// thread and the threads and processes it starts afterwards.
pub fn read_only(store: &Path) -> Result<(), String> {
    if std::env::var_os(SANDBOX_ENV).is_some_and(|v| v == "off") {
        return Err(format!("{SANDBOX_ENV}=off"));
    }
    let abi = abi()?;
    let store = std::fs::canonicalize(store)
        .map_err(|e| format!("{}: cannot resolve: {e}", store.display()))?;
    let handled = handled(abi);
    let attr = RulesetAttr {
        handled_access_fs: handled,
    };
    // SAFETY: a ruleset attribute of the documented layout and size.
    let fd = unsafe {
        libc::syscall(
            libc::SYS_landlock_create_ruleset,
            &attr as *const RulesetAttr,
            std::mem::size_of::<RulesetAttr>(),
            0u32,
        )
    };
    if fd < 0 {
        return Err(format!(
            "cannot create a Landlock ruleset: {}",
            std::io::Error::last_os_error()
        ));
    }
    // SAFETY: a descriptor just returned and owned by nobody else.
    let ruleset = unsafe { OwnedFd::from_raw_fd(fd as i32) };
    let file_rights = handled & (WRITE_FILE | TRUNCATE);
    let grant = |path: &Path| {
        let Some(fd) = open_path(path) else {
            return;
        };
        let Ok(meta) = std::fs::symlink_metadata(path) else {
            return;
        };
        let allowed = if meta.is_dir() {
            handled
        } else if meta.file_type().is_symlink() {
            // Writes through a link reach its target, granted (or not) where it lies.
            return;
        } else {
            file_rights
        };
        let rule = PathBeneathAttr {
            allowed_access: allowed,
            parent_fd: fd.as_raw_fd(),
        };
        // SAFETY: a rule of the documented layout on descriptors we own. A refused rule
        // only leaves that entry read-only.
        unsafe {
            libc::syscall(
                libc::SYS_landlock_add_rule,
                ruleset.as_raw_fd(),
                RULE_PATH_BENEATH,
                &rule as *const PathBeneathAttr,
                0u32,
            )
        };
    };
    // Every entry beside the way from / to the store.
    let mut way: Vec<PathBuf> = store.ancestors().map(Path::to_path_buf).collect();
    way.reverse();
    for pair in way.windows(2) {
        let (folder, next) = (&pair[0], &pair[1]);
        let entries = std::fs::read_dir(folder)
            .map_err(|e| format!("{}: cannot list: {e}", folder.display()))?;
        for e in entries.flatten() {
            let p = e.path();
            if p != *next {
                grant(&p);
            }
        }
    }
    // SAFETY: prctl with documented arguments; needed to restrict oneself unprivileged.
    if unsafe { libc::prctl(libc::PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) } != 0 {
        return Err(format!(
            "cannot set no_new_privs: {}",
            std::io::Error::last_os_error()
        ));
    }
    // SAFETY: restricting the calling thread with a ruleset we own.
    let r = unsafe { libc::syscall(libc::SYS_landlock_restrict_self, ruleset.as_raw_fd(), 0u32) };
    if r != 0 {
        return Err(format!(
            "cannot enforce the Landlock ruleset: {}",
            std::io::Error::last_os_error()
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// In a child process (the restriction is for good): the store cannot be written, its
    /// sibling can.
    #[test]
    fn a_sandboxed_process_cannot_write_the_store_and_can_write_beside_it() {
        if let Err(why) = available() {
            // Under CI a missing sandbox is a failure, not a pass that tested nothing.
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set, and workers cannot be sandboxed here: {why}"
            );
            eprintln!("skipped: {why}");
            return;
        }
        let d = super::super::store::TestDir::new();
        let store = d.path().join("store");
        let beside = d.path().join("beside");
        std::fs::create_dir_all(store.join("x")).unwrap();
        std::fs::create_dir_all(&beside).unwrap();
        std::fs::write(store.join("x/lib.so"), b"good").unwrap();
        // SAFETY: fork in a test; the child only makes system calls and exits.
        let pid = unsafe { libc::fork() };
        if pid == 0 {
            let code = (|| {
                read_only(&store).ok()?;
                let refused = |r: std::io::Result<()>| {
                    r.err().and_then(|e| e.raw_os_error()) == Some(libc::EACCES)
                };
                let all = refused(std::fs::write(store.join("x/lib.so"), b"evil"))
                    && refused(std::fs::remove_file(store.join("x/lib.so")))
                    && refused(std::fs::write(store.join("x/new"), b"evil"))
                    && refused(std::fs::create_dir(store.join("y")))
                    && refused(std::fs::rename(store.join("x"), beside.join("x")))
                    && std::fs::write(beside.join("f"), b"ok").is_ok()
                    && std::fs::create_dir(beside.join("sub")).is_ok();
                all.then_some(())
            })()
            .map_or(1, |_| 0);
            // SAFETY: leaving the forked child without running the parent's destructors.
            unsafe { libc::_exit(code) };
        }
        let mut status = 0;
        // SAFETY: waiting for our own child.
        unsafe { libc::waitpid(pid, &mut status, 0) };
        assert!(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0);
        assert_eq!(std::fs::read(store.join("x/lib.so")).unwrap(), b"good");
        assert!(beside.join("f").exists());
    }
}
