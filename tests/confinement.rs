//! The confined worker leaves no door open (docs/robustness.md, "The confined worker"),
//! each a real `twinbench run --isolate` of the hostile C FMU on a store of the test's own:
//!
//! - P1, P2, P3, P6 (`DOORS`): no pathname or abstract Unix socket it did not make, no
//!   socket pair, no variable of the host's environment beyond the allowlist, no descriptor
//!   the host inherited; its own `/proc` entry readable, another process's not;
//! - P5: a disk fill, a fork bomb and a memory bomb each end the run with a message that
//!   names the limit, and the next run completes; a killed host's scratch folder is swept by
//!   the next run;
//! - the confined lap equals the in-process one.

mod common;

use common::hostile::{command, confinement_here, finish, run, system};
use std::os::unix::net::UnixListener;
use std::path::Path;
use tb_testkit::assert_contains;

/// A folder with a store, a hostile FMU built with `fault` and its system file.
fn setup(tag: &str, fault: &str) -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let dir = tb_testkit::scratch(tag);
    let store = dir.path().join("store");
    let (fmu, _) = common::hostile::fmu(dir.path(), fault);
    let sys = system(dir.path(), &fmu);
    (dir, store, sys)
}

/// The line the hostile FMU said about `what`.
fn said<'a>(err: &'a str, what: &str) -> &'a str {
    err.lines()
        .find(|l| l.contains(&format!("hostile: door {what}:")))
        .unwrap_or_else(|| panic!("no attempt at {what}: {err}"))
}

#[test]
fn no_socket_secret_or_inherited_descriptor_reaches_a_confined_fmu() {
    if !confinement_here() {
        return;
    }
    let (dir, store, sys) = setup("doors", "DOORS");
    // Decoy listeners: a pathname socket (as the Docker socket or an ssh-agent is) and an
    // abstract one.
    let path = dir.path().join("agent.sock");
    let pathname = UnixListener::bind(&path).unwrap();
    pathname.set_nonblocking(true).unwrap();
    use std::os::linux::net::SocketAddrExt;
    let abstract_name = format!("twinbench-doors-{}", std::process::id());
    let abstract_socket = UnixListener::bind_addr(
        &std::os::unix::net::SocketAddr::from_abstract_name(abstract_name.as_bytes()).unwrap(),
    )
    .unwrap();
    abstract_socket.set_nonblocking(true).unwrap();
    // A descriptor twinbench inherits (a shell's `7>>victim`), not close-on-exec.
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "precious\n").unwrap();
    let inherited = std::fs::OpenOptions::new()
        .append(true)
        .open(&victim)
        .unwrap();
    let pid = std::process::id().to_string();
    let env = [
        (
            "TWINBENCH_WORKER_ENV",
            "HOSTILE_SOCKET,HOSTILE_ABSTRACT,HOSTILE_SECRET,HOSTILE_FD,HOSTILE_OTHER_PID",
        ),
        ("HOSTILE_SOCKET", path.to_str().unwrap()),
        ("HOSTILE_ABSTRACT", abstract_name.as_str()),
        ("HOSTILE_SECRET", "AWS_SECRET_ACCESS_KEY"),
        ("HOSTILE_FD", "7"),
        ("HOSTILE_OTHER_PID", pid.as_str()),
        // A secret of the user's shell and its agent's socket: not for the FMU.
        ("AWS_SECRET_ACCESS_KEY", "decoy-secret"),
        ("SSH_AUTH_SOCK", path.to_str().unwrap()),
    ];
    let (mut cmd, csv) = command(&store, &sys, true, &env, None);
    let fd = std::os::fd::AsRawFd::as_raw_fd(&inherited);
    // SAFETY: dup2 between fork and exec: the inherited descriptor 7, without
    // close-on-exec, as a shell would hand it on.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(&mut cmd, move || {
            if libc::dup2(fd, 7) < 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let (out, err, y) = finish(cmd, &csv);
    assert!(out.status.success(), "{err}");
    assert_eq!(y, Some(1.0), "{err}");
    for what in [
        "pathname-socket",
        "abstract-socket",
        "socketpair",
        "env",
        "fd",
        "proc-other",
    ] {
        assert!(
            !said(&err, what).ends_with(": ok"),
            "{what} succeeded: {err}"
        );
    }
    // Its own /proc entry is its own (P6).
    assert!(said(&err, "proc-self").ends_with(": ok"), "{err}");
    assert!(!err.contains("decoy-secret"), "{err}");
    assert!(
        pathname.accept().is_err(),
        "the FMU reached the pathname socket"
    );
    assert!(
        abstract_socket.accept().is_err(),
        "the FMU reached the abstract socket"
    );
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious\n");
}

/// Runs the hostile FMU built with `fault` confined under `limits`: the run fails with exit
/// code 1 and its message; the next run of a well-behaved FMU on the same store completes.
fn run_into_a_limit(tag: &str, fault: &str, limits: &str) -> String {
    let (dir, store, sys) = setup(tag, fault);
    let env = [("TWINBENCH_WORKER_LIMITS", limits)];
    let (out, err, _) = run(&store, &sys, true, &env, None);
    assert_eq!(out.status.code(), Some(1), "{fault}: {err}");
    let (fmu, _) = common::hostile::fmu(dir.path(), "NONE");
    let (out, next, y) = run(&store, &system(dir.path(), &fmu), true, &env, None);
    assert!(out.status.success(), "the run after {fault}: {next}");
    assert_eq!(y, Some(1.0));
    err
}

/// The number a line of `err` says after `prefix` (up to the next space).
fn number_after(err: &str, prefix: &str) -> u64 {
    err.lines()
        .find_map(|l| l.split_once(prefix)?.1.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no number after {prefix:?}: {err}"))
}

#[test]
fn a_disk_fill_ends_at_the_scratch_limit_and_says_so() {
    if !confinement_here() {
        return;
    }
    let err = run_into_a_limit("fill", "FILL", "scratch=8M");
    let wrote = number_after(&err, "hostile: fill: wrote ");
    assert!(
        wrote <= 8,
        "wrote {wrote} MiB into a scratch folder of 8 MiB: {err}"
    );
    assert!(err.contains("No space left on device"), "{err}");
    assert_contains(&err, &["its scratch folder is full", "the limit of 8 MiB"]);
}

#[test]
fn a_fork_bomb_starts_no_process_and_says_so() {
    if !confinement_here() {
        return;
    }
    let err = run_into_a_limit("fork", "FORK_BOMB", "");
    assert_contains(
        &err,
        &["hostile: fork: started 0: Resource temporarily unavailable"],
    );
    assert_contains(
        &err,
        &["the FMU tried to start 1 process", "no child processes"],
    );
}

#[test]
fn a_memory_bomb_ends_at_the_memory_limit_and_says_so() {
    if !confinement_here() {
        return;
    }
    let err = run_into_a_limit("memory", "MEMORY_BOMB", "memory=512M");
    let mib = number_after(&err, "hostile: memory: ");
    assert!(
        mib < 512,
        "allocated {mib} MiB under a limit of 512 MiB: {err}"
    );
    assert!(err.contains("memory limit of 512 MiB"), "{err}");
}

/// Whether a scratch folder of a worker is in `dir`.
fn scratch_folders(dir: &Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("twinbench-worker-"))
        })
        .collect()
}

#[test]
fn a_killed_hosts_scratch_folder_is_empty_and_swept_by_the_next_run() {
    if !confinement_here() {
        return;
    }
    let (dir, store, sys) = setup("swept", "FILL");
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    // The host is killed while the FMU, having filled its scratch folder, hangs (a long
    // watchdog).
    let tmp_s = tmp.to_str().unwrap().to_string();
    let env = [
        ("TMPDIR", tmp_s.as_str()),
        ("TWINBENCH_WORKER_LIMITS", "scratch=8M"),
        ("TWINBENCH_WORKER_ENV", "HOSTILE_HANG"),
        ("HOSTILE_HANG", "1"),
    ];
    let (mut cmd, _) = command(&store, &sys, true, &env, None);
    cmd.args(["--worker-timeout", "600"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    let mut host = cmd.spawn().unwrap();
    // Wait for the FMU's word that it filled its folder.
    let mut stderr = std::io::BufReader::new(host.stderr.take().unwrap());
    let mut line = String::new();
    while std::io::BufRead::read_line(&mut stderr, &mut line).unwrap() > 0
        && !line.contains("hostile: fill: wrote")
    {
        line.clear();
    }
    assert!(line.contains("hostile: fill: wrote "), "{line}");
    host.kill().unwrap();
    host.wait().unwrap();
    let left = scratch_folders(&tmp);
    assert_eq!(left.len(), 1, "{left:?}");
    // What the FMU wrote lived in its tmpfs, in its own mount namespace: never on the disk.
    let until = std::time::Instant::now() + std::time::Duration::from_secs(10);
    loop {
        let entries = std::fs::read_dir(&left[0]).map(|d| d.count()).unwrap_or(0);
        if entries == 0 || std::time::Instant::now() > until {
            assert_eq!(entries, 0, "the killed host's scratch folder holds files");
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    // The next run sweeps it (its lock is free: its host is gone).
    let (out, err, y) = run(&store, &sys, true, &env[..2], None);
    // FILL (not hanging) fails at t = 0.5 s; what matters is that the old folder is gone,
    // and the new one too.
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(y, None);
    assert!(
        scratch_folders(&tmp).is_empty(),
        "{:?}",
        scratch_folders(&tmp)
    );
}
