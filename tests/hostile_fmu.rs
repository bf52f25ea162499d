//! A hostile FMU written in C (`tests/hostile/hostile.c`, built here with gcc) and a forged
//! worker: under `--isolate` none of the FMU's code runs in twinbench's process, so a
//! segfault, a hang, an `exit(0)` or a NULL version (in the library's load, in
//! `fmi2GetVersion` or in a step) and endless stderr end the run with a clear message and
//! exit code 1, and twinbench lives. A worker that forges its answers is stopped with a
//! protocol error, never a panic. In-process, an `exit(0)` from the FMU still leaves a
//! message and a failure code.

mod common;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::{Duration, Instant};
use tb_cosim::backend::BackendFactory;
use tb_cosim::isolated::{IsolatedFactory, IsolationOptions};
use tb_fmi::fmi2::fmi2Status;
use tb_fmi::{CallStatus, FmiFunction, FmuError};
use tb_testkit::assert_contains;

/// `hostile.fmu` built with `-DFAULT=<fault>` in `dir`.
fn hostile_fmu(dir: &Path, fault: &str) -> PathBuf {
    common::hostile::fmu(dir, fault).0
}

use common::hostile::system;

/// `twinbench ARGS`: its output, its stderr and how long it took.
fn twinbench<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> (Output, String, Duration) {
    let started = Instant::now();
    let out = common::twinbench(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, err, started.elapsed())
}

/// `twinbench run SYSTEM EXTRA --out CSV` on the FMU built with `fault`, in a scratch folder:
/// the folder, the CSV's path, the output and its stderr.
fn run_fault(fault: &str, extra: &[&str]) -> (tempfile::TempDir, PathBuf, Output, String) {
    let dir = tb_testkit::scratch("hostile");
    let fmu = hostile_fmu(dir.path(), fault);
    let sys = system(dir.path(), &fmu);
    let csv = dir.path().join("out.csv");
    let mut args = args!["run", sys].to_vec();
    args.extend(extra.iter().map(OsStr::new));
    args.extend(args!["--out", csv]);
    let (out, err, _) = twinbench(args);
    (dir, csv, out, err)
}

/// `twinbench run SYSTEM --isolate` on the FMU built with `fault`: exit code 1 (twinbench
/// reported it: not a signal, not the FMU's exit code) and the message.
fn run_isolated(fault: &str) -> String {
    let (_dir, csv, out, err) = run_fault(fault, &["--isolate", "--worker-timeout", "2"]);
    assert_eq!(out.status.code(), Some(1), "{fault}: {err}");
    assert!(
        !csv.exists(),
        "{fault}: a failed run wrote {}",
        csv.display()
    );
    err
}

/// An FMU that kills its parent (`kill(getppid(), SIGKILL)`) under `--isolate` ends the
/// worker's guard, not twinbench: the run completes with the right values.
#[test]
fn an_isolated_fmu_that_kills_its_parent_leaves_the_host_alive() {
    let (_dir, csv, out, err) = run_fault("KILL_PARENT", &["--isolate"]);
    assert!(out.status.success(), "{:?}: {err}", out.status);
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.lines().last().unwrap().ends_with(",1"), "{text}");
}

/// An in-process FMU that prints to stdout does not corrupt `--json`: the document is
/// stdout's only content (the FMU's text goes to stderr).
#[test]
fn an_in_process_fmus_stdout_stays_out_of_json() {
    let dir = tb_testkit::scratch("hostile");
    let fmu = hostile_fmu(dir.path(), "STDOUT_JSON");
    let sys = system(dir.path(), &fmu);
    let (out, err, _) = twinbench(["run", sys.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{err}");
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "stdout is not one JSON document ({e}): {:?}",
            String::from_utf8_lossy(&out.stdout)
        )
    });
    assert!(doc.get("steps").is_some(), "{doc}");
    assert!(
        err.contains("{\"lap_time\": 1.0}"),
        "the FMU's print went to stderr: {err}"
    );
}

#[test]
fn the_hostile_fmu_behaves_when_built_without_a_fault() {
    let dir = tb_testkit::scratch("hostile");
    let fmu = hostile_fmu(dir.path(), "NONE");
    let sys = system(dir.path(), &fmu);
    for isolate in [false, true] {
        let csv = dir.path().join(format!("none-{isolate}.csv"));
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
        if isolate {
            args.push("--isolate");
        }
        let (out, err, _) = twinbench(&args);
        assert!(out.status.success(), "{err}");
        let text = std::fs::read_to_string(&csv).unwrap();
        // y follows u = 1 (its start value) from the first step.
        let last = text.lines().last().unwrap();
        assert!(last.ends_with(",1"), "{last}");
    }
}

#[test]
fn a_null_version_is_refused_in_process_and_isolated() {
    let err = run_isolated("VERSION_NULL");
    assert_contains(
        &err,
        &[
            "fmi2GetVersion returned 'NULL', expected '2.0'",
            "hostile-VERSION_NULL.fmu",
        ],
    );
    let dir = tb_testkit::scratch("hostile");
    let fmu = hostile_fmu(dir.path(), "VERSION_NULL");
    let (out, err, _) = twinbench(["run", system(dir.path(), &fmu).to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_contains(&err, &["hostile-VERSION_NULL.fmu: cannot load shared library: binaries/linux64/hostile.so: fmi2GetVersion returned 'NULL'"]);
}

/// A segfault or a hang in fmi2GetVersion, and a segfault, a hang or an exit in a step,
/// isolated: the run ends saying so and the host lives (each case the test it was).
#[test]
fn a_crash_or_a_hang_of_an_isolated_fmu_leaves_the_host_alive() {
    let in_a_step = "a_segfault_a_hang_and_an_exit_in_a_step_leave_the_host_alive";
    for (case, fault, says) in [
        (
            "a_segfault_in_fmi2_get_version_leaves_the_host_alive",
            "VERSION_SEGV",
            "instance 'h' at t = 0 s: fmi2Instantiate in the isolated worker process: the worker process was killed by signal 11 (SIGSEGV: segmentation fault)",
        ),
        (
            "a_hang_in_fmi2_get_version_is_ended_by_the_watchdog",
            "VERSION_HANG",
            "no answer within 2s (watchdog): the FMU hangs; killed",
        ),
        (
            in_a_step,
            "STEP_SEGV",
            "instance 'h' at t = 0.5 s: fmi2DoStep in the isolated worker process: the worker process was killed by signal 11",
        ),
        (
            in_a_step,
            "STEP_HANG",
            "at t = 0.5 s: fmi2DoStep in the isolated worker process: no answer within 2s (watchdog)",
        ),
        (
            in_a_step,
            "STEP_EXIT",
            "at t = 0.5 s: fmi2DoStep in the isolated worker process: the worker process exited with code 3",
        ),
    ] {
        let err = run_isolated(fault);
        assert!(err.contains(says), "{case} ({fault}): {err}");
    }
}

#[test]
fn exit_in_the_library_load_or_fmi2_get_version_is_a_crash_not_a_success() {
    for fault in ["VERSION_EXIT", "LOAD_EXIT"] {
        let err = run_isolated(fault);
        assert!(
            err.contains("fmi2Instantiate in the isolated worker process: the worker process exited with code 3 (crashed)")
                && err.contains("the FMU called exit() in its isolated worker")
                // Not told to isolate what is isolated already (red team M17).
                && !err.contains("Run the FMU with --isolate"),
            "{fault}: {err}"
        );
    }
}

#[test]
fn endless_stderr_without_newlines_keeps_the_host_bounded() {
    // The worker writes gigabytes without a newline until the watchdog kills it; the host
    // keeps cut lines (a reader that waited for a newline grew until an allocation aborted).
    let err = run_isolated("STEP_FLOOD");
    assert!(
        err.contains("no answer within 2s (watchdog)") && err.contains("[line cut]"),
        "{}",
        &err[..err.len().min(2000)]
    );
    // One cut line of at most 4 KiB, echoed once and kept in the crash report.
    assert!(err.len() < 20_000, "{} bytes on stderr", err.len());
}

#[test]
fn exit_zero_inside_an_in_process_fmu_is_reported_with_a_failure_code() {
    let (_dir, csv, out, err) = run_fault("STEP_EXIT", &[]);
    assert_eq!(out.status.code(), Some(3), "{err}");
    assert_contains(&err, &["error: the process was ended by a call to exit() before the command finished, from inside an FMU's code"]);
    assert!(!csv.exists());
}

#[test]
fn info_runs_none_of_the_fmus_code_unless_asked_and_isolates_the_check() {
    let dir = tb_testkit::scratch("hostile");
    for fault in ["VERSION_SEGV", "VERSION_EXIT", "LOAD_EXIT", "VERSION_NULL"] {
        let fmu = hostile_fmu(dir.path(), fault);
        let path = fmu.to_str().unwrap();
        // Reading the description runs no code: it works whatever the library does.
        let (out, err, _) = twinbench(["info", path]);
        assert!(out.status.success(), "{fault}: {err}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            text.contains("library: binaries/linux64/hostile.so (not loaded"),
            "{text}"
        );
        // The check in a worker: a clear error, exit code 1.
        let (out, err, _) = twinbench(["info", "--isolate", path]);
        assert_eq!(out.status.code(), Some(1), "{fault}: {err}");
        assert!(
            err.contains("in the isolated worker process"),
            "{fault}: {err}"
        );
    }
    let fmu = hostile_fmu(dir.path(), "VERSION_HANG");
    let (out, err, took) = twinbench(args!["info", "--isolate", "--worker-timeout", "1", fmu]);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no answer within 1s (watchdog)"), "{err}");
    assert!(took < Duration::from_secs(30), "{took:?}");
    let fmu = hostile_fmu(dir.path(), "NONE");
    let (out, err, _) = twinbench(["info", "--isolate", fmu.to_str().unwrap()]);
    assert!(out.status.success(), "{err}");
    let text = String::from_utf8_lossy(&out.stdout);
    assert_contains(&text, &["library: binaries/linux64/hostile.so loads; fmi2GetVersion \"2.0\"; optional functions missing: fmi2GetFMUstate"]);
}

// ---- a forged worker: the host checks every frame ----

/// Answers of a worker, as frames.
struct Frames(Vec<u8>);

impl Frames {
    fn new() -> Self {
        Frames(Vec::new())
    }
    fn raw(mut self, bytes: &[u8]) -> Self {
        self.0.extend_from_slice(bytes);
        self
    }
    fn frame(self, body: &[u8]) -> Self {
        let len = (body.len() as u32).to_le_bytes();
        self.raw(&len).raw(body)
    }
    /// A well-formed "ok, no results" answer.
    fn ok(self) -> Self {
        self.frame(&answer(0, 0, &[]))
    }
}

/// An answer's head: ok flag, number of results, time; then `rest`.
fn answer(failed: u8, results: u32, rest: &[u8]) -> Vec<u8> {
    let mut b = vec![failed];
    b.extend_from_slice(&results.to_le_bytes());
    b.extend_from_slice(&0.0f64.to_le_bytes());
    b.extend_from_slice(rest);
    b
}

/// A failed call as the worker reports it (kind CALL, an FMI 2.0 function and status, at
/// t = 0) announcing `log_lines` lines of log and carrying none.
fn call_failure(function: tb_fmi::Function, status: i32, log_lines: u32) -> Vec<u8> {
    let mut rest = vec![0u8, 2, function as u8, 2];
    rest.extend_from_slice(&status.to_le_bytes());
    rest.extend_from_slice(&0.0f64.to_le_bytes());
    rest.extend_from_slice(&log_lines.to_le_bytes());
    rest
}

/// A fake worker that writes `frames` onto its socket whatever it is asked, then waits.
fn forged_worker(dir: &Path, name: &str, frames: Frames) -> PathBuf {
    let data = dir.join(format!("{name}.bin"));
    std::fs::write(&data, frames.0).unwrap();
    let script = dir.join(format!("{name}.sh"));
    std::fs::write(
        &script,
        format!("#!/bin/sh\ncat '{}' >&0\nexec sleep 30\n", data.display()),
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).unwrap();
    script
}

/// Why an instance on the forged worker `worker` could not be created.
/// The error creating an instance on `worker` gives: the worker's, lost (why: in its cause).
fn refused(worker: PathBuf) -> FmuError {
    let e = factory(worker).create("forged", false).err().unwrap();
    assert!(
        matches!(&e, FmuError::Isolated { instance, .. } if instance == "forged"),
        "{e}"
    );
    e
}

fn factory(worker: PathBuf) -> IsolatedFactory {
    let fmu = common::load("dyno");
    IsolatedFactory {
        run: tb_cosim::backend::RunAs::default_for(&fmu),
        fmu,
        options: IsolationOptions {
            timeout: Duration::from_secs(2),
            worker_exe: Some(worker),
            ..Default::default()
        },
    }
}

#[test]
fn forged_frames_are_protocol_errors_not_panics() {
    let dir = tb_testkit::scratch("hostile");
    // A length that would allocate 2 GiB.
    let w = forged_worker(
        dir.path(),
        "huge",
        Frames::new().raw(&[0xff, 0xff, 0xff, 0x7f]),
    );
    let e = refused(w);
    assert_contains(
        &e.to_string(),
        &["answer of 2147483647 bytes is too large", "killed"],
    );
    // Trailing bytes after an ok answer.
    let w = forged_worker(
        dir.path(),
        "trailing",
        Frames::new().frame(&answer(0, 0, &[1, 2, 3])),
    );
    let e = refused(w);
    assert!(
        e.to_string().contains("protocol error (trailing bytes)"),
        "{e}"
    );

    // Instantiated, then each forged answer to a get.
    let get_answers: [(&str, Vec<u8>, &str); 5] = [
        ("no_result", answer(0, 0, &[]), "no result for the get"),
        ("too_many", answer(0, 5, &[]), "5 results for 1 gets"),
        ("short", answer(0, 1, &[0, 0, 0]), "truncated message"),
        (
            "bad_function",
            answer(1, 0, &[0, 2, 250, 0, 0, 0, 0]), // kind CALL, FMI 2.0, function 250
            "unknown function code 250",
        ),
        (
            "huge_log",
            answer(1, 0, &call_failure(tb_fmi::Function::GetReal, 3, u32::MAX)),
            "exceeds the message",
        ),
    ];
    for (name, body, expected) in get_answers {
        let w = forged_worker(dir.path(), name, Frames::new().ok().frame(&body));
        let mut b = factory(w).create("forged", false).unwrap();
        let mut out = [0.0];
        let e = b.get_real(&[0], &mut out).unwrap_err();
        assert!(
            matches!(&e, FmuError::Isolated { instance, .. } if instance == "forged"),
            "{name}: {e}"
        );
        assert_contains(&e.to_string(), &["protocol error", expected]);
        // The worker is gone; the next call fails at once with the same cause.
        let again = b.do_step(0.0, 0.1).unwrap_err();
        assert!(
            matches!(&again, FmuError::Isolated { instance, .. } if instance == "forged"),
            "{name}: {again}"
        );
        assert!(again.to_string().contains(expected), "{name}: {again}");
    }

    // An unknown status is shown with its value.
    let rest = call_failure(tb_fmi::Function::DoStep, 77, 0);
    let w = forged_worker(
        dir.path(),
        "status",
        Frames::new().ok().frame(&answer(1, 0, &rest)),
    );
    let mut b = factory(w).create("forged", false).unwrap();
    let e = b.do_step(0.0, 0.1).unwrap_err();
    assert!(
        matches!(
            &e,
            FmuError::Call {
                function: FmiFunction::Fmi2(tb_fmi::Function::DoStep),
                status: CallStatus::Fmi2(fmi2Status(77)),
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("an unknown fmi2Status (77)"), "{e}");

    // Half a frame, then silence: the watchdog.
    let w = forged_worker(dir.path(), "half", Frames::new().raw(&[13, 0, 0, 0, 0, 0]));
    let started = Instant::now();
    let e = refused(w);
    assert!(
        e.to_string().contains("no answer within 2s (watchdog)"),
        "{e}"
    );
    assert!(started.elapsed() < Duration::from_secs(20));
}
