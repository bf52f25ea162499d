//! The output folder's lock: exclusive while held, free once dropped, also when a process
//! forked while it was held (a process pool of a distributed study) still lives.

use std::io::ErrorKind;
use tb_table::FolderLock;

#[test]
fn a_dropped_lock_is_free_even_while_a_forked_child_lives() {
    let dir = tempfile::tempdir().unwrap();
    let lock = FolderLock::acquire(dir.path()).unwrap();
    let again = FolderLock::acquire(dir.path()).map(|_| ()).unwrap_err();
    // Held by another: busy (try again later), not refused.
    assert!(matches!(again.kind(), ErrorKind::WouldBlock), "{again}");
    // SAFETY: the child only sleeps and exits (async-signal-safe calls).
    let child = unsafe { libc::fork() };
    if child == 0 {
        unsafe {
            libc::sleep(30);
            libc::_exit(0);
        }
    }
    assert!(child > 0, "fork failed");
    drop(lock);
    let relocked = FolderLock::acquire(dir.path());
    unsafe {
        libc::kill(child, libc::SIGKILL);
        libc::waitpid(child, std::ptr::null_mut(), 0);
    }
    relocked.expect("the folder is free once the lock is dropped");
}

/// A folder the lock made and nothing else wrote into (a run refused before its first
/// result) is gone once the lock is dropped; one with a result in it, or one that was there
/// before, stays.
#[test]
fn a_folder_made_for_nothing_is_taken_away_again() {
    let base = tempfile::tempdir().unwrap();
    let fresh = base.path().join("refused");
    drop(FolderLock::acquire(&fresh).unwrap());
    assert!(!fresh.exists(), "the empty output folder is left behind");
    let written = base.path().join("written");
    let lock = FolderLock::acquire(&written).unwrap();
    std::fs::write(written.join("result.json"), "{}").unwrap();
    drop(lock);
    assert!(written.join("result.json").is_file());
    let before = base.path().join("before");
    std::fs::create_dir(&before).unwrap();
    drop(FolderLock::acquire(&before).unwrap());
    assert!(before.is_dir(), "a folder that was there before is kept");
}
