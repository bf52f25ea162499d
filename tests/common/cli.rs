//! The `twinbench` command line of this build: run with arguments (`&str`s, `String`s and
//! paths mixed, by [`args!`](crate::args)), and what it printed.

use std::ffi::{OsStr, OsString};
use std::fmt::Display;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The arguments of a command line, `&str`s, `String`s and paths mixed, as `&OsStr`s:
/// `args!["run", system, "--out", out]`.
#[macro_export]
macro_rules! args {
    ($($arg:expr),* $(,)?) => {
        [$(::std::ffi::OsStr::new(&$arg)),*]
    };
}

/// `twinbench ARGS`: its output, whether it succeeded or not.
pub fn twinbench<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(args)
        .output()
        .unwrap()
}

/// `twinbench ARGS` run in folder `cwd`: its output.
pub fn twinbench_in<S: AsRef<OsStr>>(cwd: &Path, args: impl IntoIterator<Item = S>) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

/// `twinbench ARGS` must succeed (else the test fails with its standard error): its output.
pub fn run_ok<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> Output {
    let args = collect(args);
    let o = twinbench(&args);
    succeeded(&o, format!("twinbench {args:?}"));
    o
}

/// `twinbench ARGS` in folder `cwd` must succeed: its output.
pub fn run_ok_in<S: AsRef<OsStr>>(cwd: &Path, args: impl IntoIterator<Item = S>) -> Output {
    let args = collect(args);
    let o = twinbench_in(cwd, &args);
    succeeded(&o, format!("twinbench {args:?} in {}", cwd.display()));
    o
}

/// `twinbench ARGS` must succeed: its standard output, as text.
pub fn ok<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> String {
    stdout(&run_ok(args))
}

/// `twinbench ARGS` in folder `cwd` must succeed: its standard output, as text.
pub fn ok_in<S: AsRef<OsStr>>(cwd: &Path, args: impl IntoIterator<Item = S>) -> String {
    stdout(&run_ok_in(cwd, args))
}

/// `twinbench ARGS` must fail: its standard error.
pub fn fails<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> String {
    let args = collect(args);
    failed(twinbench(&args), format!("twinbench {args:?}"))
}

/// `twinbench ARGS` in folder `cwd` must fail: its standard error.
pub fn fails_in<S: AsRef<OsStr>>(cwd: &Path, args: impl IntoIterator<Item = S>) -> String {
    let args = collect(args);
    let what = format!("twinbench {args:?} in {}", cwd.display());
    failed(twinbench_in(cwd, &args), what)
}

/// `twinbench ARGS` in folder `cwd`, interrupted as by Ctrl-C (SIGINT) once `file` is
/// there (within two minutes): its output.
pub fn interrupted_in<S: AsRef<OsStr>>(
    cwd: &Path,
    args: impl IntoIterator<Item = S>,
    file: &Path,
) -> Output {
    let child = Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(args)
        .current_dir(cwd)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    tb_testkit::wait_for_file(file, 120);
    // SAFETY: a signal to our own child process.
    unsafe { libc::kill(child.id() as i32, libc::SIGINT) };
    child.wait_with_output().unwrap()
}

/// `cmd` (a run with `--trace-fmi TRACE`) started, sent `signal` once `trace` shows a step
/// (within a minute), and ended within a minute after it with exit code 130 (else the test
/// fails): its standard error.
pub fn interrupted_while_stepping(cmd: &mut Command, trace: &Path, signal: i32) -> String {
    let mut child = cmd.stderr(Stdio::piped()).spawn().unwrap();
    // The run is under way once the trace shows steps (no race with the start-up).
    let started = Instant::now();
    while !std::fs::read_to_string(trace).is_ok_and(|t| t.contains("fmi2DoStep")) {
        assert!(started.elapsed().as_secs() < 60, "the run did not start");
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: a signal to our own child process.
    unsafe { libc::kill(child.id() as i32, signal) };
    // A watchdog for a run that would not end (a sleep of a paced run, say), not a measure
    // of how promptly it ends.
    let waited = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if waited.elapsed().as_secs() > 60 {
            let _ = child.kill();
            panic!("the run did not end on signal {signal}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let o = child.wait_with_output().unwrap();
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(130), "{e}");
    e
}

/// `o` is of a command that succeeded, else the test fails naming `what`, with its
/// standard error.
pub fn succeeded(o: &Output, what: impl Display) {
    assert!(
        o.status.success(),
        "{what} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// `cmd`, a command other than twinbench (Python, OMSimulator), must succeed (else the test
/// fails naming it, with its standard error and output): its output.
pub fn output_ok(cmd: &mut Command) -> Output {
    let o = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        o.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    o
}

/// `o` is of a command that succeeded, else the test fails with its standard error.
pub fn assert_success(o: &Output) {
    succeeded(o, "the command");
}

/// `o` is of a command that failed (else the test fails naming `what`): its standard error.
pub fn failed(o: Output, what: impl Display) -> String {
    assert!(!o.status.success(), "{what} succeeded");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The standard output of `o`, as text.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn collect<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> Vec<OsString> {
    args.into_iter().map(|a| a.as_ref().to_owned()).collect()
}
