//! Red team findings on the store of unpacked FMUs (docs/robustness.md, "The store of
//! unpacked FMUs"), each a real `twinbench` process on a store of the test's own:
//!
//! - N2: an isolated FMU cannot plant code that a later in-process run loads (the worker
//!   cannot write the store; without the sandbox the planted library is found and never
//!   loaded);
//! - N3: a changed byte of a library in the store is found, reported and repaired, in
//!   process and isolated, also after deleting the index and touching the FMU;
//! - N19: a complete folder without its library is repaired;
//! - N27: with umask 000 the store's folders and files are private, and a folder others can
//!   write is not used;
//! - the remote worker's input digest covers the unpacked content it runs on.

mod common;

use std::io::Write;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use tb_testkit::assert_contains;
use zip::write::SimpleFileOptions;

use common::hostile::{confinement_here, run, system};

/// The hostile FMU with `fault` ([`common::hostile::fmu`]).
fn hostile_fmu(dir: &Path, fault: &str) -> (PathBuf, Vec<u8>) {
    common::hostile::fmu(dir, fault)
}

/// [`run`], which must succeed: its stderr and the last recorded y.
fn ran(
    store: &Path,
    sys: &Path,
    isolate: bool,
    env: &[(&str, &str)],
    shell: Option<&str>,
) -> (String, Option<f64>) {
    let (out, err, y) = run(store, sys, isolate, env, shell);
    assert!(out.status.success(), "isolate {isolate}: {err}");
    (err, y)
}

/// The store folder of an FMU (named by the first 32 digits of its SHA-256).
fn folder_of(store: &Path, fmu: &Path) -> PathBuf {
    use sha2::Digest;
    let sha = format!("{:x}", sha2::Sha256::digest(std::fs::read(fmu).unwrap()));
    store.join(&sha[..32])
}

/// A file's bytes replaced keeping its mode.
fn rewrite(path: &Path, bytes: &[u8]) {
    let mode = std::fs::metadata(path).unwrap().permissions().mode();
    std::fs::write(path, bytes).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
}

/// Runs the victim FMU (`NONE`) in-process after the attacker (`PLANT`) ran isolated on the
/// same store, with `attack_env` for the attacker's run. Returns the attacker's and the
/// victim's stderr.
fn attack(tag: &str, attack_env: &[(&str, &str)]) -> (String, String) {
    let dir = tb_testkit::scratch(tag);
    let store = dir.path().join("store");
    let (victim, library) = hostile_fmu(dir.path(), "NONE");
    let (attacker, _) = hostile_fmu(dir.path(), "PLANT");
    let (victim_sys, attacker_sys) = (system(dir.path(), &victim), system(dir.path(), &attacker));
    // The victim is in the store first.
    let (_, y) = ran(&store, &victim_sys, false, &[], None);
    assert_eq!(y, Some(1.0));
    let stored = folder_of(&store, &victim).join("binaries/linux64/hostile.so");
    assert_eq!(std::fs::read(&stored).unwrap(), library);
    // The attacker runs isolated: it runs (its y is u + 100) whatever became of its attack.
    let mut env = vec![
        ("HOSTILE_PLANT", "1"),
        ("TWINBENCH_WORKER_ENV", "HOSTILE_PLANT"),
    ];
    env.extend_from_slice(attack_env);
    let (attack_err, y) = ran(&store, &attacker_sys, true, &env, None);
    assert_eq!(y, Some(101.0), "{attack_err}");
    // Unconfined, the attack reaches the victim's library; confined, not even the store.
    assert!(
        attack_err.contains(&format!("{}", stored.display()))
            || attack_err.contains("hostile: cannot list the store"),
        "the attack was not tried: {attack_err}"
    );
    // The victim in-process: its own values, none of the attacker's code.
    let (victim_err, y) = ran(&store, &victim_sys, false, &[], None);
    assert_eq!(y, Some(1.0), "{victim_err}");
    assert!(
        !victim_err.contains("PLANT code runs"),
        "planted code ran in the host: {victim_err}"
    );
    assert_eq!(std::fs::read(&stored).unwrap(), library);
    (attack_err, victim_err)
}

#[test]
fn n02_an_isolated_fmu_cannot_write_the_store_that_a_later_in_process_run_loads_from() {
    if !confinement_here() {
        return;
    }
    let (attack, victim) = attack("n02-sandbox", &[]);
    // The confined worker cannot even list the store (its own FMU's folder is all it reads).
    assert_contains(
        &attack,
        &["hostile: cannot list the store", "Permission denied"],
    );
    assert!(!attack.contains("hostile: planted into"), "{attack}");
    // Nothing to repair afterwards.
    assert!(!victim.contains("unpacking it again"), "{victim}");
}

/// A scratch folder with a store, a victim FMU already run into it, and the `ESCAPE`
/// attacker: (folder, store, victim FMU, victim's system, attacker's system).
fn victim_and_attacker(tag: &str) -> (tempfile::TempDir, PathBuf, PathBuf, PathBuf, PathBuf) {
    let dir = tb_testkit::scratch(tag);
    let store = dir.path().join("store");
    let (victim, _) = hostile_fmu(dir.path(), "NONE");
    let (attacker, _) = hostile_fmu(dir.path(), "ESCAPE");
    let (victim_sys, attacker_sys) = (system(dir.path(), &victim), system(dir.path(), &attacker));
    ran(&store, &victim_sys, false, &[], None);
    (dir, store, victim, victim_sys, attacker_sys)
}

/// Red team M1–M4 and issue #33's list: a hostile FMU run with `--isolate` tries to write
/// the user's home and the project, open a TCP connection, reach an abstract Unix socket
/// and a System V shared memory segment of the user's, chmod the store, read another FMU's
/// unpacked library and fork a daemon that outlives the run. Each fails; its own
/// scratch folder works; the lap runs; nothing of it is left afterwards, and the next run
/// does not hang.
#[test]
fn a_confined_fmu_can_write_only_its_scratch_folder_and_leaves_nothing_behind() {
    if !confinement_here() {
        return;
    }
    let (dir, store, victim, victim_sys, attacker_sys) = victim_and_attacker("confined-escape");
    let other = folder_of(&store, &victim).join("binaries/linux64/hostile.so");
    let home = dir.path().join("home");
    let project = dir.path().join("project");
    std::fs::create_dir_all(&home).unwrap();
    std::fs::create_dir_all(&project).unwrap();
    std::fs::write(home.join(".bashrc"), "precious\n").unwrap();
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let port = listener.local_addr().unwrap().port().to_string();
    // An abstract Unix socket and a System V shared memory segment of the user's.
    use std::os::linux::net::SocketAddrExt;
    let abstract_name = format!("twinbench-hostile-{port}");
    let unix = std::os::unix::net::UnixListener::bind_addr(
        &std::os::unix::net::SocketAddr::from_abstract_name(abstract_name.as_bytes()).unwrap(),
    )
    .unwrap();
    unix.set_nonblocking(true).unwrap();
    let shm = SharedMemory::new(std::process::id() as i32);
    let shm_key = shm.key.to_string();
    let mode_before = std::fs::metadata(&store).unwrap().permissions().mode() & 0o7777;
    let env = [
        // The confined worker's environment is an allowlist: the test's variables are
        // passed by name, as an FMU's documented ones would be.
        (
            "TWINBENCH_WORKER_ENV",
            "HOSTILE_HOME,HOSTILE_PROJECT,HOSTILE_PORT,HOSTILE_OTHER,HOSTILE_SHM",
        ),
        ("HOSTILE_HOME", home.to_str().unwrap()),
        ("HOSTILE_PROJECT", project.to_str().unwrap()),
        ("HOSTILE_PORT", port.as_str()),
        ("HOSTILE_OTHER", other.to_str().unwrap()),
        ("HOSTILE_SHM", shm_key.as_str()),
    ];
    let (err, y) = ran(&store, &attacker_sys, true, &env, None);
    assert_eq!(y, Some(1.0), "{err}");
    for what in [
        "home",
        "project",
        "tcp",
        "abstract-socket",
        "shm",
        "chmod-store",
        "other-fmu",
        // No child process at all (a confined worker runs none), so no daemon either.
        "daemon",
    ] {
        let line = err
            .lines()
            .find(|l| l.contains(&format!("hostile: escape {what}:")))
            .unwrap_or_else(|| panic!("no attempt at {what}: {err}"));
        assert!(!line.ends_with(": ok"), "{what} succeeded: {err}");
    }
    assert!(err.contains("hostile: escape scratch: ok"), "{err}");
    assert_eq!(
        std::fs::read_to_string(home.join(".bashrc")).unwrap(),
        "precious\n"
    );
    assert!(!project.join("planted.txt").exists());
    assert!(listener.accept().is_err(), "the FMU reached the listener");
    assert!(
        unix.accept().is_err(),
        "the FMU reached the abstract socket"
    );
    let mode_after = std::fs::metadata(&store).unwrap().permissions().mode() & 0o7777;
    assert_eq!(mode_before, mode_after);
    // The daemon ended with the run (its namespace ended with the worker).
    let daemons = || {
        std::fs::read_dir("/proc")
            .unwrap()
            .filter_map(|e| std::fs::read_to_string(e.ok()?.path().join("stat")).ok())
            // "<pid> (<comm>) <state> ...": a zombie is gone already, only unreaped.
            .filter(|s| s.contains("(tb-hostile-dmn) ") && !s.contains("(tb-hostile-dmn) Z"))
            .count()
    };
    let until = std::time::Instant::now() + std::time::Duration::from_secs(5);
    while daemons() > 0 && std::time::Instant::now() < until {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    assert_eq!(daemons(), 0, "a process of the FMU outlived the run");
    // No scratch folder is left, and the next run does not hang.
    let (_, y) = ran(&store, &victim_sys, true, &[], None);
    assert_eq!(y, Some(1.0));
}

/// M2: Landlock's rules were for the store's path, and a bind mount of the store beside it
/// let a worker write another FMU's library and its manifest. Now the worker writes only its
/// scratch folder, through any path: the library opened for writing through the alias is
/// refused, and the victim still runs its own code. (Run as root, where a test can mount;
/// skipped elsewhere, as the confinement is where it cannot be set up.)
#[test]
fn m02_a_bind_mount_of_the_store_reaches_nothing() {
    if !confinement_here() {
        return;
    }
    let (dir, store, victim, victim_sys, attacker_sys) = victim_and_attacker("m02-bind");
    let alias = dir.path().join("alias");
    std::fs::create_dir(&alias).unwrap();
    let Some(_mount) = BindMount::new(&store, &alias) else {
        eprintln!("skipped: cannot bind-mount here");
        return;
    };
    let library = folder_of(&store, &victim).join("binaries/linux64/hostile.so");
    let before = std::fs::read(&library).unwrap();
    let through_alias = folder_of(&alias, &victim).join("binaries/linux64/hostile.so");
    let env = [
        ("HOSTILE_ALIAS", through_alias.to_str().unwrap()),
        ("TWINBENCH_WORKER_ENV", "HOSTILE_ALIAS"),
    ];
    let (err, _) = ran(&store, &attacker_sys, true, &env, None);
    let line = err
        .lines()
        .find(|l| l.contains("hostile: escape alias:"))
        .unwrap_or_else(|| panic!("no attempt through the alias: {err}"));
    assert!(
        !line.ends_with(": ok"),
        "the write through the bind mount succeeded: {err}"
    );
    assert_eq!(std::fs::read(&library).unwrap(), before);
    let (err, y) = ran(&store, &victim_sys, false, &[], None);
    assert_eq!(y, Some(1.0), "{err}");
}

/// A bind mount made by the test (as root), unmounted with it.
struct BindMount {
    target: PathBuf,
}

impl BindMount {
    fn new(source: &Path, target: &Path) -> Option<BindMount> {
        let c = |p: &Path| std::ffi::CString::new(p.as_os_str().as_encoded_bytes()).unwrap();
        let (s, t) = (c(source), c(target));
        // SAFETY: mount with two NUL-terminated paths and no data.
        let r = unsafe {
            libc::mount(
                s.as_ptr(),
                t.as_ptr(),
                std::ptr::null(),
                libc::MS_BIND,
                std::ptr::null(),
            )
        };
        (r == 0).then(|| BindMount {
            target: target.to_path_buf(),
        })
    }
}

impl Drop for BindMount {
    fn drop(&mut self) {
        let t = std::ffi::CString::new(self.target.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: umount of the path this test mounted.
        unsafe { libc::umount2(t.as_ptr(), libc::MNT_DETACH) };
    }
}

/// A System V shared memory segment (mode 600) of the test's, removed with it.
struct SharedMemory {
    key: i32,
    id: i32,
}

impl SharedMemory {
    fn new(key: i32) -> SharedMemory {
        // SAFETY: shmget with documented arguments; no memory is handed over.
        let id = unsafe { libc::shmget(key, 4096, libc::IPC_CREAT | libc::IPC_EXCL | 0o600) };
        assert!(id >= 0, "shmget: {}", std::io::Error::last_os_error());
        SharedMemory { key, id }
    }
}

impl Drop for SharedMemory {
    fn drop(&mut self) {
        // SAFETY: IPC_RMID on the segment this test made.
        unsafe { libc::shmctl(self.id, libc::IPC_RMID, std::ptr::null_mut()) };
    }
}

/// M3: a library beside the FMU's own (a dependency it would load through `$ORIGIN`) is
/// verified before the FMU's library is loaded, in-process and isolated: one changed byte
/// is found, reported and repaired.
#[test]
fn m03_a_changed_dependency_beside_the_library_is_found_and_repaired() {
    let dir = tb_testkit::scratch("m03");
    let store = dir.path().join("store");
    let (plain, library) = hostile_fmu(dir.path(), "NONE");
    // The same FMU with a dependency beside its library.
    let fmu = dir.path().join("with-dep.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&fmu).unwrap());
    let o = SimpleFileOptions::default();
    zip.start_file("modelDescription.xml", o).unwrap();
    zip.write_all(common::hostile::MODEL_DESCRIPTION.as_bytes())
        .unwrap();
    zip.start_file("binaries/linux64/hostile.so", o).unwrap();
    zip.write_all(&library).unwrap();
    zip.start_file("binaries/linux64/libdep.so", o).unwrap();
    zip.write_all(b"the dependency's bytes").unwrap();
    zip.finish().unwrap();
    drop(plain);
    let sys = system(dir.path(), &fmu);
    let (_, y) = ran(&store, &sys, false, &[], None);
    assert_eq!(y, Some(1.0));
    let dep = folder_of(&store, &fmu).join("binaries/linux64/libdep.so");
    for isolate in [false, true] {
        let mut bytes = std::fs::read(&dep).unwrap();
        bytes[0] ^= 1;
        rewrite(&dep, &bytes);
        let (err, y) = ran(&store, &sys, isolate, &[], None);
        assert_eq!(y, Some(1.0));
        assert!(
            err.contains("libdep.so") && err.contains("unpacking it again"),
            "isolate {isolate}: the changed dependency went unnoticed: {err}"
        );
        assert_eq!(std::fs::read(&dep).unwrap(), b"the dependency's bytes");
    }
}

#[test]
fn n02_without_the_sandbox_the_planted_library_is_found_and_never_loaded() {
    let (attack, victim) = attack("n02-nosandbox", &[("TWINBENCH_WORKER_SANDBOX", "off")]);
    assert!(attack.contains("hostile: planted into"), "{attack}");
    assert_contains(
        &attack,
        &["isolated workers are not confined (crash-only isolation)"],
    );
    // Found before loading, reported once naming the store folder, unpacked again.
    assert_eq!(victim.matches("unpacking it again").count(), 1, "{victim}");
    assert_contains(&victim, &["differs from what was unpacked", "/store/"]);
}

/// A scratch folder `tag` with the FMU without a fault, its system file, and a store it ran
/// on once in process: the folder, the store, the FMU, its library's bytes, the system.
fn stored_once(tag: &str) -> (tempfile::TempDir, PathBuf, PathBuf, Vec<u8>, PathBuf) {
    let dir = tb_testkit::scratch(tag);
    let store = dir.path().join("store");
    let (fmu, library) = hostile_fmu(dir.path(), "NONE");
    let sys = system(dir.path(), &fmu);
    ran(&store, &sys, false, &[], None);
    (dir, store, fmu, library, sys)
}

#[test]
fn n03_a_changed_byte_of_a_stored_library_is_found_and_repaired_in_process_and_isolated() {
    let (_dir, store, fmu, library, sys) = stored_once("n03");
    let stored = folder_of(&store, &fmu).join("binaries/linux64/hostile.so");
    // "2.0" returned by fmi2GetVersion becomes "2.1": a library that loads and runs, one
    // byte changed, the size kept. Loaded, it would fail the version check.
    let at = library.windows(8).position(|w| w == b"default\0").unwrap();
    let at = at
        + library[at..]
            .windows(4)
            .position(|w| w == b"2.0\0")
            .unwrap();
    let mut evil = library.clone();
    evil[at + 2] = b'1';
    for isolate in [false, true] {
        rewrite(&stored, &evil);
        // The index deleted and the FMU touched too: nothing of that matters.
        let _ = std::fs::remove_dir_all(store.join("index"));
        std::fs::File::options()
            .write(true)
            .open(&fmu)
            .unwrap()
            .set_modified(std::time::SystemTime::now())
            .unwrap();
        let (err, y) = ran(&store, &sys, isolate, &[], None);
        assert_eq!(y, Some(1.0), "{err}");
        assert_eq!(err.matches("unpacking it again").count(), 1, "{err}");
        assert_contains(
            &err,
            &[
                &folder_of(&store, &fmu).display().to_string(),
                "its content is not the unpacked one",
            ],
        );
        assert_eq!(std::fs::read(&stored).unwrap(), library);
        // The next run finds nothing to repair.
        let (out, err, _) = run(&store, &sys, isolate, &[], None);
        assert!(
            out.status.success() && !err.contains("unpacking it again"),
            "{err}"
        );
    }
}

#[test]
fn n19_a_complete_folder_without_its_library_is_repaired() {
    let (_dir, store, fmu, library, sys) = stored_once("n19");
    let folder = folder_of(&store, &fmu);
    assert!(folder.join(".complete").is_file());
    std::fs::remove_file(folder.join("binaries/linux64/hostile.so")).unwrap();
    std::fs::remove_dir_all(store.join("index")).unwrap();
    let (err, y) = ran(&store, &sys, false, &[], None);
    assert_eq!(y, Some(1.0));
    assert_contains(&err, &["hostile.so: cannot open", "unpacking it again"]);
    assert_eq!(
        std::fs::read(folder.join("binaries/linux64/hostile.so")).unwrap(),
        library
    );
}

/// Every folder and file under `store`, with its mode.
fn modes(store: &Path) -> Vec<(PathBuf, u32)> {
    let mut out = Vec::new();
    let mut todo = vec![store.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let m = e.metadata().unwrap();
            if m.is_dir() {
                todo.push(e.path());
            }
            out.push((e.path(), m.permissions().mode() & 0o7777));
        }
    }
    out
}

#[test]
fn n27_with_umask_000_the_store_is_private_and_a_folder_others_can_write_is_not_used() {
    let dir = tb_testkit::scratch("n27");
    let store = dir.path().join("store");
    let (fmu, _) = hostile_fmu(dir.path(), "NONE");
    let sys = system(dir.path(), &fmu);
    let (_, y) = ran(&store, &sys, false, &[], Some("umask 000"));
    assert_eq!(y, Some(1.0));
    let all = modes(&store);
    assert!(all.len() > 6, "{all:?}");
    for (p, mode) in &all {
        assert_eq!(mode & 0o077, 0, "{} has mode {mode:o}", p.display());
    }
    let folder = folder_of(&store, &fmu);
    let mode_of = |p: &Path| all.iter().find(|(q, _)| q == p).unwrap().1;
    assert_eq!(mode_of(&folder), 0o700);
    assert_eq!(mode_of(&folder.join("binaries/linux64/hostile.so")), 0o700);
    assert_eq!(mode_of(&folder.join("modelDescription.xml")), 0o600);
    assert_eq!(mode_of(&store.join("index")), 0o700);
    // A folder on the way to the library that others can write: named with its mode and
    // unpacked again, in process and isolated.
    for isolate in [false, true] {
        let linux64 = folder.join("binaries/linux64");
        std::fs::set_permissions(&linux64, std::fs::Permissions::from_mode(0o777)).unwrap();
        let (err, y) = ran(&store, &sys, isolate, &[], Some("umask 000"));
        assert_eq!(y, Some(1.0));
        assert_contains(
            &err,
            &[
                &format!(
                    "{}: mode 777: group or others can write it",
                    linux64.display()
                ),
                "unpacking it again",
            ],
        );
        assert_eq!(mode_of(&linux64), 0o700);
        let now = std::fs::metadata(&linux64).unwrap().permissions().mode() & 0o7777;
        assert_eq!(now, 0o700);
    }
}

/// The remote worker's digest: a worker whose store copy of the driver's
/// `resources/target_speed.csv` was edited verifies it, repairs it and computes the
/// coordinator's cost; a worker whose unpacked content differs is refused by the digest.
#[test]
fn a_remote_workers_digest_covers_the_unpacked_content_it_runs_on() {
    use tb_optimize::{Candidate, StudyEvaluator};
    common::fmu_dir();
    let dir = tb_testkit::scratch("remote-digest");
    let store = dir.path().join("store");
    let path = twinbench::pack::workspace_root().join("studies/spielberg.toml");
    let evaluator = || {
        StudyEvaluator::load_with(
            &path,
            tb_fmi::FmuCache::temporary_with_store(&store).unwrap(),
        )
    };
    let coordinator = evaluator().unwrap();
    let x: Vec<f64> = coordinator
        .workers()
        .assignment()
        .iter()
        .map(|a| a.1)
        .collect();
    let candidate = Candidate { step: 0, values: x };
    let cost = coordinator.cost(&candidate).unwrap();
    let driver = coordinator
        .digest()
        .files
        .iter()
        .find(|(p, _)| p.ends_with("driver.fmu"))
        .unwrap()
        .clone();
    assert!(driver.1.contains(" unpacked "), "{driver:?}");
    // The worker's store copy of the target speed edited (the finding's case).
    let folder = std::fs::read_dir(&store)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.join("resources/target_speed.csv").is_file())
        .expect("the driver's unpacked folder");
    let csv = folder.join("resources/target_speed.csv");
    let good = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    let row = lines.len() / 2;
    lines[row] = lines[row].replacen('1', "2", 1);
    rewrite(&csv, format!("{}\n", lines.join("\n")).as_bytes());
    assert_ne!(std::fs::read_to_string(&csv).unwrap(), good);
    let worker = evaluator().unwrap();
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), good, "repaired");
    assert_eq!(worker.digest().mismatch(coordinator.digest()), None);
    assert_eq!(worker.cost(&candidate).unwrap().to_bits(), cost.to_bits());
    // A worker whose unpacked content differs (another manifest) is refused, naming the FMU.
    let mut other = coordinator.digest().clone();
    let i = other
        .files
        .iter()
        .position(|(p, _)| p.ends_with("driver.fmu"))
        .unwrap();
    let (sha, _) = other.files[i].1.split_once(" unpacked ").unwrap();
    other.files[i].1 = format!("{sha} unpacked {}", "0".repeat(64));
    let why = worker.digest().mismatch(&other).unwrap();
    assert!(why.contains("driver.fmu"), "{why}");
}

/// The store keeps every FMU ever run (the finding's 1.9 GB bomb stayed): `twinbench cache
/// prune` removes the folders no running process uses, and keeps the one this test holds.
#[test]
fn cache_prune_removes_unused_folders_and_keeps_those_in_use() {
    let dir = tb_testkit::scratch("prune");
    let store = dir.path().join("store");
    let (a, _) = hostile_fmu(dir.path(), "NONE");
    let (b, _) = hostile_fmu(dir.path(), "STEP_EXIT");
    let cache = tb_fmi::FmuCache::temporary_with_store(&store).unwrap();
    let held = cache.load(&a).unwrap();
    drop(
        tb_fmi::FmuCache::temporary_with_store(&store)
            .unwrap()
            .load(&b)
            .unwrap(),
    );
    let twinbench = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .args(args)
            .env("TWINBENCH_CACHE", &store)
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let info = twinbench(&["cache", "info"]);
    assert!(
        info.contains("folders  2 (") && info.contains("1 in use"),
        "{info}"
    );
    // Each folder with the model its description names, not only its digest.
    let description = std::fs::read_to_string(held.dir.join("modelDescription.xml")).unwrap();
    let name = description
        .split("modelName=\"")
        .nth(1)
        .and_then(|r| r.split('"').next())
        .unwrap();
    assert!(info.contains(&format!("{name} (FMI ")), "{info}");
    let pruned = twinbench(&["cache", "prune", "--older-than", "0"]);
    assert_contains(
        &pruned,
        &["removed  1 folders", "kept     1 folders in use"],
    );
    assert!(held.dir.join(".complete").is_file());
    assert!(!folder_of(&store, &b).exists());
    drop(held);
    drop(cache);
    let pruned = twinbench(&["cache", "prune", "--max-size", "0"]);
    assert!(pruned.contains("removed  1 folders"), "{pruned}");
    assert!(!folder_of(&store, &a).exists());
    // The next run unpacks again.
    let (_, y) = ran(&store, &system(dir.path(), &a), false, &[], None);
    assert_eq!(y, Some(1.0));
}
