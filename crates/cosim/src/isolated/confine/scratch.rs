//! The host's side of a worker's scratch folder: made private in the system's temporary
//! folder, locked for the host's life, removed after the worker; and the folders of hosts
//! that were killed, swept by the next twinbench that makes one.
//!
//! The worker mounts a tmpfs of the scratch limit's size on it in its own mount namespace,
//! so what the FMU writes lives in memory and goes with the namespace: a killed host leaves
//! an empty folder only, which the next run removes.

use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The name every scratch folder starts with.
const PREFIX: &str = "twinbench-worker-";
/// The name a scratch folder is made under, before it is locked and renamed to its own.
const MAKING: &str = ".twinbench-worker-making-";

/// A folder under [`MAKING`]'s name is left only by a host killed between two system calls;
/// it is removed once it is this old (a younger one may be one being made).
const ABANDONED_AFTER: Duration = Duration::from_secs(60);

/// One worker's scratch folder, removed with it.
pub(crate) struct Scratch {
    pub path: PathBuf,
    /// The folder itself, locked (`flock`) while this host lives: a later twinbench that
    /// can take the lock knows the host is gone.
    _lock: std::fs::File,
}

impl Scratch {
    pub fn new() -> std::io::Result<Scratch> {
        Scratch::new_in(&std::env::temp_dir())
    }

    pub fn new_in(dir: &Path) -> std::io::Result<Scratch> {
        use std::os::unix::fs::DirBuilderExt;
        static SWEPT: std::sync::Once = std::sync::Once::new();
        SWEPT.call_once(|| {
            let n = sweep(dir, ABANDONED_AFTER);
            if n > 0 {
                log::info!(
                    "removed {n} scratch folder(s) of isolated workers whose host was killed"
                );
            }
        });
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let name = format!("{}-{n}-{nanos:08x}", std::process::id());
        // Made and locked under a name no sweep takes, then renamed: a folder under its
        // own name is locked from the moment it has it, so a sweep may take any it can lock.
        let making = dir.join(format!("{MAKING}{name}"));
        std::fs::DirBuilder::new().mode(0o700).create(&making)?;
        let lock = std::fs::File::open(&making)?;
        // SAFETY: flock on a descriptor we own.
        if unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let e = std::io::Error::last_os_error();
            let _ = std::fs::remove_dir(&making);
            return Err(e);
        }
        let path = dir.join(format!("{PREFIX}{name}"));
        if let Err(e) = std::fs::rename(&making, &path) {
            let _ = std::fs::remove_dir(&making);
            return Err(e);
        }
        Ok(Scratch { path, _lock: lock })
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // remove_dir_all follows no link the FMU left in it.
        let _ = std::fs::remove_dir_all(&self.path);
    }
}

/// Removes the scratch folders in `dir` of this user whose host is gone (their lock can be
/// taken), and folders left half-made that are older than `after`; returns how many.
pub(crate) fn sweep(dir: &Path, after: Duration) -> usize {
    use std::os::unix::fs::MetadataExt;
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    // SAFETY: getuid has no preconditions.
    let me = unsafe { libc::getuid() };
    let mut removed = 0;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let half_made = name.starts_with(MAKING);
        if !name.starts_with(PREFIX) && !half_made {
            continue;
        }
        let path = e.path();
        // Not followed: a link of that name is nobody's scratch folder.
        let Ok(meta) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let old = meta
            .modified()
            .ok()
            .and_then(|m| m.elapsed().ok())
            .is_some_and(|age| age >= after);
        if !meta.is_dir() || meta.uid() != me || (half_made && !old) {
            continue;
        }
        let Ok(f) = std::fs::File::open(&path) else {
            continue;
        };
        // SAFETY: flock on a descriptor we own; held until the folder is gone.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0
            && std::fs::remove_dir_all(&path).is_ok()
        {
            removed += 1;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_whose_host_is_gone_is_swept_and_a_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        // A live host's folder (this process holds its lock).
        let live = Scratch::new_in(dir.path()).unwrap();
        // A killed host's: a folder nobody locks, with what its FMU left; swept at once.
        let dead = dir.path().join(format!("{PREFIX}999999-0-0"));
        std::fs::create_dir(&dead).unwrap();
        std::fs::write(dead.join("left.bin"), b"x").unwrap();
        // One left half-made: swept only when old (it could be one being made).
        let half = dir.path().join(format!("{MAKING}999999-1-0"));
        std::fs::create_dir(&half).unwrap();
        assert_eq!(sweep(dir.path(), Duration::from_secs(3600)), 1);
        assert!(!dead.exists());
        assert!(half.exists());
        assert_eq!(sweep(dir.path(), Duration::ZERO), 1);
        assert!(!half.exists());
        assert!(live.path.exists(), "a live host's folder was removed");
        let path = live.path.clone();
        drop(live);
        assert!(!path.exists());
    }
}
