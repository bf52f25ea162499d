//! Issue #47, item 4: `twinbench run --realtime [FACTOR]`, a paced run of the bench. Its
//! rows are the unpaced run's byte for byte, it takes at least the simulated time ÷ FACTOR
//! (a lower bound only: a noisy machine may make it longer), its summary has the lateness
//! statistics and what was asked of the system; `--overrun stop` ends it at the first
//! overrun keeping the rows; Ctrl-C ends it while it sleeps; a bad FACTOR is refused.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Instant;
use tb_testkit::assert_contains;

/// `systems/rls_v.toml` with the packed FMUs and a stop time of `stop` s.
fn bench(dir: &Path, stop: f64) -> PathBuf {
    let fmus = common::fmu_dir();
    let text =
        std::fs::read_to_string(twinbench::pack::workspace_root().join("systems/rls_v.toml"))
            .unwrap()
            .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()))
            .replace("stop = \"vehicle.lap >= 1\"", &format!("stop = {stop:?}"));
    let path = dir.join("bench.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn run(system: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .arg("run")
        .arg(system)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .unwrap()
}

fn succeeded(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Each thing asked of the system is in the JSON (asked, obtained; when refused, why and
/// what it means) and said in one line on stderr.
fn check_attempts(j: &serde_json::Value, stderr: &str) -> Vec<serde_json::Value> {
    let attempts = j["realtime"]["system"]
        .as_array()
        .expect("realtime.system")
        .clone();
    let asked: Vec<&str> = attempts
        .iter()
        .map(|a| a["asked"].as_str().unwrap())
        .collect();
    assert!(
        asked
            .iter()
            .any(|a| a.starts_with("SCHED_FIFO priority 80"))
            && asked.iter().any(|a| a.starts_with("mlockall"))
            && asked.iter().any(|a| a.starts_with("CPU ")),
        "{asked:?}"
    );
    for a in &attempts {
        let what = a["asked"].as_str().unwrap();
        match a["obtained"].as_bool().unwrap() {
            true => assert!(
                stderr.contains(&format!("realtime: {what} obtained")),
                "{stderr}"
            ),
            false => {
                let (why, means) = (
                    a["refused"].as_str().unwrap(),
                    a["consequence"].as_str().unwrap(),
                );
                assert!(means.contains("deadlines may be missed"), "{means}");
                assert_contains(
                    stderr,
                    &[&format!("realtime: {what} refused: {why}; {means}")],
                );
            }
        }
    }
    attempts
}

/// Factor 2 over 3 s of the bench: the CSV of the unpaced run byte for byte, at least
/// 1.5 s of wall time, and the lateness summary.
#[test]
fn a_paced_run_gives_the_unpaced_rows_takes_its_scheduled_time_and_reports_lateness() {
    let dir = tb_testkit::scratch("realtime-run");
    let (stop, factor) = (3.0, 2.0);
    let system = bench(dir.path(), stop);
    let (paced, plain) = (dir.path().join("paced.csv"), dir.path().join("plain.csv"));
    let started = Instant::now();
    let o = run(&system, &paced, &["--json", "--realtime", "2"]);
    let wall = started.elapsed().as_secs_f64();
    let j = succeeded(&o);
    succeeded(&run(&system, &plain, &["--json"]));
    assert!(
        std::fs::read(&paced).unwrap() == std::fs::read(&plain).unwrap(),
        "the paced run's CSV differs from the unpaced run's"
    );
    // A lower bound only (the schedule's floor); the deadlines are absolute, so the
    // process cannot end before the last one.
    assert!(wall >= stop / factor, "{wall} s < {} s", stop / factor);
    let r = &j["realtime"];
    assert_eq!(r["factor"], 2.0);
    assert_eq!(r["overrun_policy"], "continue");
    assert_eq!(r["steps"], 3000);
    assert_eq!(r["stopped_at_overrun"], false);
    assert!((r["scheduled_wall_time"].as_f64().unwrap() - stop / factor).abs() < 1e-9);
    assert!(r["wall_time"].as_f64().unwrap() >= stop / factor, "{r}");
    assert!(r["overruns"].as_u64().unwrap() <= 3000);
    let l = &r["lateness"];
    let q = |k: &str| {
        l[k].as_f64()
            .unwrap_or_else(|| panic!("lateness.{k} in {r}"))
    };
    assert!(q("min") <= q("median") && q("median") <= q("p99") && q("p99") <= q("p99_9"));
    assert!(q("p99_9") <= q("max"), "{l}");
    let h = &r["histogram"];
    let bins = [
        "slack",
        "late_0_to_10us",
        "late_10_to_100us",
        "late_100us_to_1ms",
        "late_over_1ms",
    ];
    let counted: u64 = bins.iter().map(|b| h[b].as_u64().unwrap()).sum();
    assert_eq!(counted, 3000, "{h}");
    assert_eq!(
        counted - h["slack"].as_u64().unwrap(),
        r["overruns"].as_u64().unwrap()
    );
    check_attempts(&j, &String::from_utf8_lossy(&o.stderr));
}

/// A factor no step can keep (10 ns of wall time per 1 ms step) with `--overrun stop`: the
/// run ends after its first step, complete, its rows the unpaced run's first; a CPU the
/// process may not use is refused in a line that says why.
#[test]
fn overrun_stop_ends_the_run_at_the_first_overrun_keeping_its_rows() {
    let dir = tb_testkit::scratch("realtime-stop");
    let system = bench(dir.path(), 3.0);
    let (stopped, plain) = (dir.path().join("stopped.csv"), dir.path().join("plain.csv"));
    let o = run(
        &system,
        &stopped,
        &[
            "--json",
            "--realtime",
            "1e5",
            "--overrun",
            "stop",
            "--realtime-cpu",
            "1023",
        ],
    );
    let j = succeeded(&o);
    assert!(
        j["stopped_by"]
            .as_str()
            .unwrap()
            .starts_with("overrun at t = 0.001 s: the step finished "),
        "{j}"
    );
    assert_eq!(j["steps"], 1);
    assert_eq!(j["realtime"]["stopped_at_overrun"], true);
    assert_eq!(j["realtime"]["overruns"], 1);
    assert_eq!(j["realtime"]["first_overrun"]["time"], 0.001);
    let stderr = String::from_utf8_lossy(&o.stderr);
    let attempts = check_attempts(&j, &stderr);
    let cpu = attempts
        .iter()
        .find(|a| a["asked"] == "CPU 1023 alone (sched_setaffinity)");
    assert_eq!(cpu.unwrap()["obtained"], false, "{stderr}");
    succeeded(&run(&system, &plain, &["--json"]));
    let (stopped, plain) = (
        std::fs::read_to_string(&stopped).unwrap(),
        std::fs::read_to_string(&plain).unwrap(),
    );
    assert!(stopped.lines().count() >= 2, "no rows kept: {stopped}");
    assert!(plain.starts_with(&stopped), "{stopped}");
}

/// A slowed-down run (factor 0.001: a second of wall time per step) sleeps nearly all the
/// time: Ctrl-C ends it during a sleep, keeping its rows as for an unpaced run.
#[test]
fn ctrl_c_ends_a_paced_run_during_its_sleep_and_keeps_the_rows() {
    let dir = tb_testkit::scratch("realtime-ctrl-c");
    let system = bench(dir.path(), 3.0);
    let (out, trace) = (dir.path().join("r.csv"), dir.path().join("calls.txt"));
    let mut run = Command::new(env!("CARGO_BIN_EXE_twinbench"));
    run.arg("run")
        .arg(&system)
        .arg("--out")
        .arg(&out)
        .args(["--realtime", "0.001", "--realtime-priority", "0"])
        .args(["--realtime-cpu", "none", "--trace-fmi"])
        .arg(&trace);
    // Under way once the trace shows a step: the run then sleeps to its first deadline (its
    // schedule is 3000 s), and Ctrl-C ends it there.
    let e = common::cli::interrupted_while_stepping(&mut run, &trace, libc::SIGINT);
    let partial = dir.path().join("r.incomplete.csv");
    assert_contains(
        &e,
        &[
            "interrupted by SIGINT or SIGTERM (Ctrl-C) at t = ",
            &format!("{} (incomplete)", partial.display()),
        ],
    );
    let t = tb_table::Table::read_path(&partial).unwrap();
    assert!(!t.require("time").unwrap().is_empty());
    // Nothing asked was left unsaid: the memory lock is the only thing asked here.
    assert_contains(&e, &["realtime: mlockall(MCL_CURRENT|MCL_FUTURE) "]);
    assert!(
        !e.contains("SCHED_FIFO") && !e.contains("sched_setaffinity"),
        "{e}"
    );
}

/// FACTOR must be a finite number above 0; the error names the option.
#[test]
fn a_bad_factor_is_refused_naming_the_option() {
    let dir = tb_testkit::scratch("realtime-bad");
    let system = bench(dir.path(), 0.01);
    for bad in ["0", "-1", "nan", "inf", "fast"] {
        let o = run(&system, &dir.path().join("r.csv"), &["--realtime", bad]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "--realtime {bad} was taken");
        assert!(
            e.contains(&format!("invalid value '{bad}' for '--realtime"))
                && (e.contains("is not a finite number above 0") || e.contains("is not a number")),
            "{e}"
        );
    }
    // The pacing options without --realtime say what they need.
    let o = run(&system, &dir.path().join("r.csv"), &["--overrun", "stop"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--realtime"));
    assert!(!dir.path().join("r.csv").exists());
}
