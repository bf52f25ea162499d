//! Result files written safely. A result never replaces anything but a regular file (not a
//! device, a FIFO, a symbolic link or a folder), never an input of the run, and is never seen
//! half-written: it goes into a temporary file created exclusively (`O_EXCL`, an
//! unpredictable name, in the target's folder, so a planted link cannot redirect it), is
//! synced, and is renamed over the target. A folder that several processes could write to
//! (an optimisation's output) is locked.
//!
//! A temporary file does not outlive its writer: it is `flock`ed while written, removed by
//! [`remove_in_flight`] when the process is interrupted (the command line's SIGINT and
//! SIGTERM handlers call it), and a temporary of this tool's naming that is old and no
//! longer locked (its writer was killed outright) is swept by the next write into its
//! folder.

use std::hash::{BuildHasher, Hasher};
use std::io::{Error, ErrorKind, Write};
use std::os::fd::AsRawFd;
use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

fn refuse(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::new(
        ErrorKind::InvalidInput,
        format!("{}: {why}", path.display()),
    )
}

/// The path as the file system names it (links in its folders resolved), whether or not the
/// file exists yet.
fn resolved(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = path.canonicalize() {
        return Some(p);
    }
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    Some(parent.canonicalize().ok()?.join(path.file_name()?))
}

/// Can `path` take a result file? Refused: anything that exists and is not a regular file
/// (a symbolic link, a FIFO, a device, a socket, a folder), any of `inputs` (the files the
/// run reads), and a folder this process cannot create files in (tried, not guessed from
/// mode bits). Checked before a run, so that a bad `--out` fails before the work.
pub fn check_output(path: &Path, inputs: &[&Path]) -> std::io::Result<()> {
    check_target(path, inputs)?;
    probe_writable(path)
}

/// Whether a file can be created beside `path` (in its folder, or in the nearest existing
/// folder above it, which the write would create the rest in): a probe file is created
/// and removed.
fn probe_writable(path: &Path) -> std::io::Result<()> {
    let mut dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    while !dir.exists() {
        match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => dir = p.to_path_buf(),
            _ => {
                dir = PathBuf::from(".");
                break;
            }
        }
    }
    let probe = dir.join(format!(".twinbench-probe.{:016x}.tmp", random()));
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) => Err(refuse(
            path,
            format!(
                "cannot write into {}: {e} (checked before the run)",
                dir.display()
            ),
        )),
    }
}

/// [`check_output`] without the probe (a write finds out for itself).
fn check_target(path: &Path, inputs: &[&Path]) -> std::io::Result<()> {
    if path.file_name().is_none() {
        return Err(refuse(path, "not a file name"));
    }
    match std::fs::symlink_metadata(path) {
        Ok(m) => {
            let t = m.file_type();
            if t.is_symlink() {
                return Err(refuse(
                    path,
                    "is a symbolic link: refusing to replace it (name its target to write there)",
                ));
            }
            if t.is_dir() {
                return Err(refuse(path, "is a folder, not a file"));
            }
            if !t.is_file() {
                return Err(refuse(
                    path,
                    "is not a regular file (a device, a FIFO or a socket): refusing to replace it",
                ));
            }
        }
        Err(e) if e.kind() == ErrorKind::NotFound => {}
        Err(e) => return Err(refuse(path, e)),
    }
    if let Some(out) = resolved(path) {
        for input in inputs {
            if resolved(input).as_deref() == Some(out.as_path()) {
                return Err(refuse(
                    path,
                    format!(
                        "is an input of this run ({}): refusing to overwrite it",
                        input.display()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// An unpredictable 64-bit number (the standard library's randomly keyed hasher).
fn random() -> u64 {
    let mut h = std::collections::hash_map::RandomState::new().build_hasher();
    h.write_u32(std::process::id());
    h.write_u128(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0),
    );
    h.finish()
}

/// Write a file atomically: a reader sees the old file or the new one, never a part; see
/// the module's documentation for what is refused.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    check_target(path, &[])?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir).map_err(|e| refuse(dir, e))?;
    sweep(dir);
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    // Armed before it exists: a signal from the moment it is created removes it.
    let (tmp, mut file, slot) = {
        let mut attempt = 0;
        loop {
            let tmp = dir.join(format!(".{name}.{:016x}.tmp", random()));
            let slot = in_flight::arm(&tmp);
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&tmp)
            {
                Ok(f) => break (tmp, f, slot),
                Err(e) if e.kind() == ErrorKind::AlreadyExists && attempt < 16 => {
                    in_flight::disarm(slot);
                    attempt += 1
                }
                Err(e) => {
                    in_flight::disarm(slot);
                    return Err(refuse(&tmp, e));
                }
            }
        }
    };
    // Locked while written: a sweep by another process leaves it alone.
    // SAFETY: flock on an open descriptor of ours.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
    let written = (|| {
        let named = |e: Error| refuse(path, e);
        file.write_all(bytes).map_err(named)?;
        file.sync_all().map_err(named)?;
        drop(file);
        // The target may have changed while writing: check it again.
        check_target(path, &[])?;
        std::fs::rename(&tmp, path).map_err(named)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    in_flight::disarm(slot);
    written
}

/// A temporary of [`write_atomic`]'s naming: `.<name>.<16 hex digits>.tmp`.
fn is_our_temporary(name: &str) -> bool {
    let Some(rest) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else {
        return false;
    };
    let Some((stem, hex)) = rest.rsplit_once('.') else {
        return false;
    };
    !stem.is_empty() && hex.len() == 16 && hex.bytes().all(|b| b.is_ascii_hexdigit())
}

/// A temporary older than this whose writer holds no lock was left by a killed process.
const SWEEP_AFTER: std::time::Duration = std::time::Duration::from_secs(60);

/// Removes the temporaries of killed writers in `dir`: this tool's naming, regular files,
/// older than a minute, and not locked (a live writer holds its lock).
fn sweep(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        if !is_our_temporary(&name.to_string_lossy()) {
            continue;
        }
        let Ok(meta) = e.metadata() else { continue };
        let old = meta
            .modified()
            .ok()
            .and_then(|m| m.elapsed().ok())
            .is_some_and(|age| age > SWEEP_AFTER);
        if !meta.file_type().is_file() || !old {
            continue;
        }
        let path = e.path();
        let Ok(f) = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
            .open(&path)
        else {
            continue;
        };
        // SAFETY: flock on an open descriptor of ours.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// Removes the temporary files being written right now. Async-signal-safe: for a signal
/// handler that ends the process (nothing half-written is left behind).
pub fn remove_in_flight() {
    in_flight::remove_all();
}

/// The temporaries being written, in fixed slots a signal handler can read without locks
/// or allocation. A slot is free (0), being filled (1), armed (2) or pinned by a handler
/// that is removing its file (3); a writer waits for a pinned slot (the process is ending).
mod in_flight {
    use std::cell::UnsafeCell;
    use std::os::unix::ffi::OsStrExt;
    use std::path::Path;
    use std::sync::atomic::{AtomicU8, Ordering};

    const SLOTS: usize = 64;
    const MAX_PATH: usize = 4096;

    struct Slot {
        state: AtomicU8,
        path: UnsafeCell<[u8; MAX_PATH]>,
    }

    // SAFETY: `path` is written only by the writer that moved the state 0 -> 1, and read
    // only in state 2 or 3, which the writer does not touch.
    unsafe impl Sync for Slot {}

    #[allow(clippy::declare_interior_mutable_const)]
    const FREE: Slot = Slot {
        state: AtomicU8::new(0),
        path: UnsafeCell::new([0; MAX_PATH]),
    };
    static TABLE: [Slot; SLOTS] = [FREE; SLOTS];

    /// Records `path` as being written; None when it cannot be recorded (a full table, a
    /// path too long: the sweep still removes it later).
    pub fn arm(path: &Path) -> Option<usize> {
        let bytes = path.as_os_str().as_bytes();
        if bytes.len() >= MAX_PATH || bytes.contains(&0) {
            return None;
        }
        for (k, slot) in TABLE.iter().enumerate() {
            if slot
                .state
                .compare_exchange(0, 1, Ordering::Acquire, Ordering::Relaxed)
                .is_ok()
            {
                // SAFETY: state 1 is ours alone.
                let buf = unsafe { &mut *slot.path.get() };
                buf[..bytes.len()].copy_from_slice(bytes);
                buf[bytes.len()] = 0;
                slot.state.store(2, Ordering::Release);
                return Some(k);
            }
        }
        None
    }

    pub fn disarm(slot: Option<usize>) {
        let Some(k) = slot else { return };
        while TABLE[k]
            .state
            .compare_exchange(2, 0, Ordering::AcqRel, Ordering::Relaxed)
            .is_err()
        {
            // Pinned by a signal handler: the process is ending.
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
    }

    pub fn remove_all() {
        for slot in &TABLE {
            if slot
                .state
                .compare_exchange(2, 3, Ordering::AcqRel, Ordering::Relaxed)
                .is_ok()
            {
                // SAFETY: a pinned slot's path is complete and NUL-terminated; unlink is
                // async-signal-safe.
                unsafe { libc::unlink(slot.path.get().cast()) };
            }
        }
    }
}

/// An exclusive lock on a folder (a `.twinbench.lock` file in it, `flock`ed), held until
/// dropped: two processes writing results into one folder is an error, not a race.
pub struct FolderLock {
    _file: std::fs::File,
    pub path: PathBuf,
    /// The folder did not exist before: a run that wrote nothing into it (refused before
    /// its first result) takes it away again, instead of leaving a folder holding only
    /// the lock.
    created: bool,
}

impl FolderLock {
    pub fn acquire(dir: &Path) -> std::io::Result<FolderLock> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir)
            .map_err(|e| refuse(dir, format!("cannot create the folder: {e}")))?;
        // Results go only into a folder of this user: in another user's folder (a shared
        // /tmp) they would be that user's to read and replace.
        let meta = std::fs::metadata(dir).map_err(|e| refuse(dir, e))?;
        // SAFETY: geteuid has no preconditions and cannot fail.
        let me = unsafe { libc::geteuid() };
        if meta.uid() != me {
            return Err(refuse(
                dir,
                format!(
                    "the folder belongs to user id {}, not to this user ({me}): choose an --out of your own",
                    meta.uid()
                ),
            ));
        }
        let path = dir.join(".twinbench.lock");
        // Never through a link (a planted one would have us truncate its target), never
        // anything but a regular file.
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o644)
            .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC)
            .open(&path)
            .map_err(|e| match e.raw_os_error() {
                Some(libc::ELOOP) => refuse(
                    &path,
                    "is a symbolic link: refusing to open it (remove it; twinbench makes its own lock file)",
                ),
                _ => refuse(&path, e),
            })?;
        let lock_meta = file.metadata().map_err(|e| refuse(&path, e))?;
        if !lock_meta.is_file() {
            return Err(refuse(
                &path,
                "is not a regular file: refusing to use it as the folder's lock (remove it)",
            ));
        }
        // A hard link to another file (M18): writing our process id would change that
        // file. Checked before anything is written.
        if lock_meta.nlink() != 1 {
            return Err(refuse(
                &path,
                format!(
                    "has {} hard links (another file shares it): refusing to write into it (remove it; twinbench makes its own lock file)",
                    lock_meta.nlink()
                ),
            ));
        }
        // SAFETY: flock on an open descriptor of ours.
        let r = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
        if r != 0 {
            let holder = std::fs::read_to_string(&path).unwrap_or_default();
            return Err(Error::new(
                ErrorKind::WouldBlock,
                format!(
                    "{}: another twinbench{} is writing into this folder; wait for it or choose another --out",
                    dir.display(),
                    match holder.trim() {
                        "" => String::new(),
                        pid => format!(" (process {pid})"),
                    }
                ),
            ));
        }
        file.set_len(0)?;
        write!(file, "{}", std::process::id())?;
        Ok(FolderLock {
            _file: file,
            path,
            created,
        })
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        // Unlocked explicitly, not only by closing: a process forked while the lock was
        // held (a process pool evaluating candidates) shares the open file description,
        // and closing our descriptor alone would leave the folder locked while it lives.
        // SAFETY: flock on an open descriptor of ours.
        unsafe { libc::flock(self._file.as_raw_fd(), libc::LOCK_UN) };
        // A folder this lock made and nothing else wrote into: gone again (a folder that
        // holds anything else, or that was there before, stays as it is).
        if let (true, Some(dir)) = (self.created, self.path.parent()) {
            let only_the_lock = std::fs::read_dir(dir).is_ok_and(|entries| {
                entries
                    .map(|e| e.map(|e| e.path() == self.path))
                    .all(|same| same.unwrap_or(false))
            });
            if only_the_lock {
                let _ = std::fs::remove_file(&self.path);
                let _ = std::fs::remove_dir(dir);
            }
        }
    }
}
