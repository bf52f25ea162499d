//! The output folder's lock: exclusive while held, free once dropped, also when a process
//! forked while it was held (a process pool of a distributed study) still lives.

use tb_table::FolderLock;

#[test]
fn a_dropped_lock_is_free_even_while_a_forked_child_lives() {
    let dir = tempfile::tempdir().unwrap();
    let lock = FolderLock::acquire(dir.path()).unwrap();
    let again = FolderLock::acquire(dir.path()).map(|_| ()).unwrap_err();
    assert!(
        again.to_string().contains("is writing into this folder"),
        "{again}"
    );
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
