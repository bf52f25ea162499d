//! Result files are written safely: `--out` onto a FIFO, a device, a symbolic link, a folder
//! or an input of the run is refused before the run; a symbolic link planted where a
//! temporary file could be expected changes nothing; two optimisations cannot share a folder.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use tb_testkit::assert_contains;

/// `twinbench run SYSTEM --out OUT`.
fn run_out(system: &Path, out: &Path) -> Output {
    common::twinbench(args!["run", system, "--out", out])
}

/// A one-second system of the test FMU (quick), written in `dir`.
fn small_system(dir: &Path) -> PathBuf {
    let fmu = common::fmu("faulty");
    common::system_file(
        &dir.join("small.toml"),
        "",
        &[("f", &fmu)],
        "[[instance]]\nname = \"a\"\nfmu = \"f\"\n\n[parameters]\n\"a.u\" = 1.0\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n",
    )
}

fn refused(o: &Output, what: &str) -> String {
    assert!(!o.status.success(), "{what}: accepted");
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    // Refused before the run: no summary was printed.
    assert!(o.stdout.is_empty(), "{what}: the run went ahead");
    e
}

/// A system of the `faulty` test FMU as instance `a` (u = 1: y = t), with more parameter
/// lines and the stop time, in `dir`.
fn faulty_system(dir: &Path, parameters: &str, stop: &str) -> PathBuf {
    common::system_file(
        &dir.join("t.toml"),
        "",
        &[("f", &common::fmu("faulty"))],
        &format!("[[instance]]\nname = \"a\"\nfmu = \"f\"\n\n[parameters]\n\"a.u\" = 1.0\n{parameters}\n[experiment]\nstep = 1e-3\nstop = {stop}\n"),
    )
}

/// A one-second [`faulty_system`] whose instance `a` fails with `fault_kind` at `fault_time`.
fn fault_at(dir: &Path, fault_kind: u32, fault_time: &str) -> PathBuf {
    let parameters = format!("\"a.fault_kind\" = {fault_kind}\n\"a.fault_time\" = {fault_time}\n");
    faulty_system(dir, &parameters, "1.0")
}

#[test]
fn out_onto_a_fifo_a_device_a_link_a_folder_or_an_input_is_refused_before_the_run() {
    let dir = tb_testkit::scratch("outs");
    let sys = small_system(dir.path());
    // A FIFO (mkfifo).
    let fifo = dir.path().join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let e = refused(&run_out(&sys, &fifo), "FIFO");
    assert!(e.contains("not a regular file"), "{e}");
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo_like());
    // A device.
    let e = refused(&run_out(&sys, Path::new("/dev/null")), "/dev/null");
    assert!(e.contains("/dev/null: is not a regular file"), "{e}");
    // A symbolic link (to a file the link must not let us replace).
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "keep me").unwrap();
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let e = refused(&run_out(&sys, &link), "symlink");
    assert!(e.contains("is a symbolic link"), "{e}");
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
    // A folder.
    let e = refused(&run_out(&sys, dir.path()), "folder");
    assert!(e.contains("is a folder"), "{e}");
    // The system file itself.
    let e = refused(&run_out(&sys, &sys), "input");
    assert!(e.contains("is an input of this run"), "{e}");
    assert!(std::fs::read_to_string(&sys)
        .unwrap()
        .contains("[experiment]"));
}

#[test]
fn a_planted_temporary_link_redirects_nothing() {
    let dir = tb_testkit::scratch("planted");
    let sys = small_system(dir.path());
    let victim = dir.path().join("victim.txt");
    std::fs::write(&victim, "keep me").unwrap();
    // Links at the names a predictable writer would use (".NAME.tmpPID", ".NAME.tmp").
    for pid in 0..64 {
        let _ = std::os::unix::fs::symlink(&victim, dir.path().join(format!(".lap.csv.tmp{pid}")));
    }
    std::os::unix::fs::symlink(&victim, dir.path().join(".lap.csv.tmp")).unwrap();
    let out = dir.path().join("lap.csv");
    let o = run_out(&sys, &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
    assert!(std::fs::read_to_string(&out).unwrap().starts_with("time,"));
}

#[test]
fn two_writers_cannot_share_an_output_folder() {
    let dir = tb_testkit::scratch("lock");
    let first = tb_table::FolderLock::acquire(dir.path()).unwrap();
    let second = tb_table::FolderLock::acquire(dir.path()).err().unwrap();
    // Busy, not refused; the message names the holder.
    assert!(
        matches!(second.kind(), std::io::ErrorKind::WouldBlock),
        "{second}"
    );
    assert_contains(
        &second.to_string(),
        &["another twinbench", &std::process::id().to_string()],
    );
    drop(first);
    tb_table::FolderLock::acquire(dir.path()).unwrap();
}

trait FifoLike {
    fn is_fifo_like(&self) -> bool;
}

impl FifoLike for std::fs::FileType {
    fn is_fifo_like(&self) -> bool {
        use std::os::unix::fs::FileTypeExt;
        self.is_fifo()
    }
}

#[test]
fn a_complete_run_keeps_its_results_when_an_instance_fails_to_end() {
    let dir = tb_testkit::scratch("terminate");
    let sys = fault_at(dir.path(), 9, "100.0");
    let out = dir.path().join("r.csv");
    let o = run_out(&sys, &out);
    assert!(!o.status.success(), "the terminate error is an error");
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("fmi2Terminate returned fmi2Error"), "{e}");
    assert!(e.contains("fault_kind = 9"), "{e}");
    assert!(e.contains("the run completed (stop time 1 s)"), "{e}");
    // The recording is complete: 1001 rows, y = 1 at the end.
    let t = tb_table::Table::read_path(&out).unwrap();
    assert_eq!(t.len(), 1001);
    assert_eq!(
        *t.require("a.y").unwrap().last().unwrap(),
        1.0000000000000007
    );
}

#[test]
fn a_failed_run_keeps_what_it_recorded_in_a_file_named_incomplete() {
    let dir = tb_testkit::scratch("incomplete");
    let sys = fault_at(dir.path(), 1, "0.5");
    let out = dir.path().join("r.csv");
    // A complete result from an earlier run stays where it is.
    std::fs::write(&out, "time,a.y\n0,0\n").unwrap();
    let o = common::twinbench(args!["run", sys, "--out", out, "--json"]);
    assert!(!o.status.success(), "the step error is an error");
    let e = String::from_utf8_lossy(&o.stderr);
    let partial = dir.path().join("r.incomplete.csv");
    assert!(e.contains("fault_kind = 1"), "{e}");
    assert_contains(&e, &[&format!("{} (incomplete)", partial.display())]);
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "time,a.y\n0,0\n");
    // Recorded up to the failing step at t = 0.5 s: y = t (gain 1, u 1) within rounding.
    let t = tb_table::Table::read_path(&partial).unwrap();
    let last_t = *t.require("time").unwrap().last().unwrap();
    assert!((last_t - 0.5).abs() < 2e-3, "recorded until {last_t}");
    let last_y = *t.require("a.y").unwrap().last().unwrap();
    assert!(
        (last_y - last_t).abs() < 1e-9,
        "y = {last_y} at t = {last_t}"
    );
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["complete"], false);
    assert_eq!(j["recorded_rows"].as_u64().unwrap() as usize, t.len());
}

#[test]
fn a_replayed_column_without_a_unit_takes_the_inputs_and_a_wrong_one_names_the_fix() {
    let dir = tb_testkit::scratch("replayunit");
    let fmu = common::fmu("faulty");
    let sys = dir.path().join("t.toml");
    let system = |units: &str| {
        format!(
            "connections = [\"in.drive -> a.u\"]\n\n[fmus]\nf = {:?}\n\n[[instance]]\nname = \"a\"\nfmu = \"f\"\n\n[[replay]]\nname = \"in\"\nfile = \"in.csv\"\nbasis = \"time\"\n{units}\n[experiment]\nstep = 1e-2\nstop = 1.0\n",
            fmu.display().to_string()
        )
    };
    // An FMPy-style input file: a header, no unit row.
    std::fs::write(dir.path().join("in.csv"), "time,drive\n0,2\n1,2\n").unwrap();
    std::fs::write(&sys, system("")).unwrap();
    let out = dir.path().join("r.csv");
    let o = run_out(&sys, &out);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert_contains(&e, &["'in.drive' has no unit; taken as 'a.u''s unit 1"]);
    let t = tb_table::Table::read_path(&out).unwrap();
    let y = *t.require("a.y").unwrap().last().unwrap();
    assert!((y - 2.0).abs() < 1e-9, "y = ∫ 2 dt over 1 s = {y}");
    // A unit that does not fit the input: the message names the [[replay]] fix.
    std::fs::write(&sys, system("units = { drive = \"m\" }\n")).unwrap();
    let o = run_out(&sys, &out);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "m into a unit 1 input was accepted");
    assert!(e.contains("units = { drive = \"1\" }"), "{e}");
}

#[test]
fn ctrl_c_ends_a_run_after_its_step_and_keeps_its_rows_as_incomplete() {
    interrupted_run_keeps_its_rows_as_incomplete(libc::SIGINT);
}

/// SIGTERM (a batch system's stop, a container's) as Ctrl-C: the rows kept, marked.
#[test]
fn sigterm_ends_a_run_after_its_step_and_keeps_its_rows_as_incomplete() {
    interrupted_run_keeps_its_rows_as_incomplete(libc::SIGTERM);
}

fn interrupted_run_keeps_its_rows_as_incomplete(signal: i32) {
    let dir = tb_testkit::scratch(&format!("interrupted-{signal}"));
    // 1e8 steps: far longer than the test waits.
    let sys = faulty_system(dir.path(), "", "1e5");
    let (out, trace) = (dir.path().join("r.csv"), dir.path().join("calls.txt"));
    std::fs::write(&out, "time,a.y\n0,0\n").unwrap();
    let mut run = Command::new(env!("CARGO_BIN_EXE_twinbench"));
    run.args(["run", sys.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .args(["--trace-fmi", trace.to_str().unwrap()]);
    let e = common::cli::interrupted_while_stepping(&mut run, &trace, signal);
    let partial = dir.path().join("r.incomplete.csv");
    assert_contains(
        &e,
        &[
            "the run ended early; the ",
            "interrupted by SIGINT or SIGTERM (Ctrl-C) at t = ",
            &format!("{} (incomplete)", partial.display()),
        ],
    );
    // The earlier complete result stays; the rows go to the incomplete file, y = t each.
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "time,a.y\n0,0\n");
    let t = tb_table::Table::read_path(&partial).unwrap();
    let (time, y) = (t.require("time").unwrap(), t.require("a.y").unwrap());
    let last_t = *time.last().unwrap();
    assert!(last_t > 0.0 && last_t < 1e5, "recorded until {last_t}");
    assert_contains(&e, &[&format!("at t = {} s", tb_files::number(last_t))]);
    assert!((y.last().unwrap() - last_t).abs() < 1e-6 * last_t.max(1.0));
    // The trace was finished (its file complete) and no temporary file stays.
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
