//! Result files written safely. A result never replaces anything but a regular file (not a
//! device, a FIFO, a symbolic link or a folder), never an input of the run, and is never seen
//! half-written: it goes into a temporary file created exclusively (`O_EXCL`, an
//! unpredictable name, in the target's folder, so a planted link cannot redirect it), is
//! synced, and is renamed over the target. A folder that several processes could write to
//! (an optimisation's output) is locked.

use std::hash::{BuildHasher, Hasher};
use std::io::{Error, ErrorKind, Write};
use std::os::fd::AsRawFd;
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
/// (a symbolic link, a FIFO, a device, a socket, a folder), and any of `inputs` (the files
/// the run reads). Checked before a run, so that a bad `--out` fails before the work.
pub fn check_output(path: &Path, inputs: &[&Path]) -> std::io::Result<()> {
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
    check_output(path, &[])?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let (tmp, mut file) = {
        let mut attempt = 0;
        loop {
            let tmp = dir.join(format!(".{name}.{:016x}.tmp", random()));
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&tmp)
            {
                Ok(f) => break (tmp, f),
                Err(e) if e.kind() == ErrorKind::AlreadyExists && attempt < 16 => attempt += 1,
                Err(e) => return Err(refuse(&tmp, e)),
            }
        }
    };
    let written = (|| {
        file.write_all(bytes)?;
        file.sync_all()?;
        drop(file);
        // The target may have changed while writing: check it again.
        check_output(path, &[])?;
        std::fs::rename(&tmp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// An exclusive lock on a folder (a `.twinbench.lock` file in it, `flock`ed), held until
/// dropped: two processes writing results into one folder is an error, not a race.
pub struct FolderLock {
    _file: std::fs::File,
    pub path: PathBuf,
}

impl FolderLock {
    pub fn acquire(dir: &Path) -> std::io::Result<FolderLock> {
        std::fs::create_dir_all(dir)
            .map_err(|e| refuse(dir, format!("cannot create the folder: {e}")))?;
        let path = dir.join(".twinbench.lock");
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| refuse(&path, e))?;
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
        Ok(FolderLock { _file: file, path })
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        // Unlocked explicitly, not only by closing: a process forked while the lock was
        // held (a process pool evaluating candidates) shares the open file description,
        // and closing our descriptor alone would leave the folder locked while it lives.
        // SAFETY: flock on an open descriptor of ours.
        unsafe { libc::flock(self._file.as_raw_fd(), libc::LOCK_UN) };
    }
}
