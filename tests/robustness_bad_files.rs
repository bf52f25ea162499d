//! The corpus of broken user files in `tests/bad_files/`: every `X.toml` (system file in
//! `systems/`, study file in `studies/`) or `X.csv` (measurement in `measurements/`) there
//! has a sidecar `X.expect` whose lines must each appear in the error message it produces. A new broken file is a new case: drop it in with its `.expect`.

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::{Plan, Simulation};
use tb_fmi::FmuCache;

fn corpus(sub: &str, ext: &str) -> Vec<PathBuf> {
    let dir = twinbench::pack::workspace_root()
        .join("tests/bad_files")
        .join(sub);
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == ext))
        .collect();
    v.sort();
    v
}

fn expected(case: &Path) -> Vec<String> {
    let e = case.with_extension("expect");
    std::fs::read_to_string(&e)
        .unwrap_or_else(|_| panic!("{} has no {}", case.display(), e.display()))
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_string)
        .collect()
}

/// Check every case; report all mismatches at once.
fn check_all(cases: &[PathBuf], error_of: impl Fn(&Path) -> Option<String>) {
    let mut failures = Vec::new();
    for case in cases {
        let want = expected(case);
        match error_of(case) {
            None => failures.push(format!("{}: accepted", case.display())),
            Some(msg) => {
                for w in &want {
                    if !msg.contains(w.as_str()) {
                        failures.push(format!(
                            "{}: message lacks {w:?}:\n    {msg}",
                            case.display()
                        ));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "\n{}", failures.join("\n"));
}

fn system_error(path: &Path) -> Option<String> {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    match Plan::load(path, cache) {
        Err(e) => Some(e.to_string()),
        Ok(sys) => Simulation::new(sys).err().map(|e| e.to_string()),
    }
}

#[test]
fn every_broken_system_file_gives_its_message() {
    common::fmu_dir();
    let cases = corpus("systems", "toml");
    assert!(cases.len() >= 30, "{} system cases", cases.len());
    check_all(&cases, system_error);
}

#[test]
fn every_broken_measurement_gives_its_message() {
    let cases = corpus("measurements", "csv");
    assert!(cases.len() >= 10, "{} measurement cases", cases.len());
    check_all(&cases, |p| {
        tb_compare::Measurement::read_path(p)
            .err()
            .map(|e| e.to_string())
    });
}

#[test]
fn every_broken_study_file_gives_its_message() {
    common::fmu_dir();
    let cases = corpus("studies", "toml");
    assert!(cases.len() >= 15, "{} study cases", cases.len());
    check_all(&cases, |p| {
        let study = match tb_optimize::Study::load(p) {
            Err(e) => return Some(e.to_string()),
            Ok(s) => s,
        };
        // Everything else is refused before the first simulation.
        let options = tb_optimize::RunOptions {
            threads: 1,
            generations: Some(1),
            ..Default::default()
        };
        tb_optimize::run_study(&study, &options)
            .err()
            .map(|e| e.to_string())
    });
}

/// `twinbench ARGS`: its exit code and stderr.
fn cli<S: AsRef<std::ffi::OsStr>>(args: impl IntoIterator<Item = S>) -> (Option<i32>, String) {
    let out = common::twinbench(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code(), err)
}

#[test]
fn the_command_line_exits_with_1_and_the_message_on_stderr() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root().join("tests/bad_files");
    for case in ["systems/unknown_variable.toml", "systems/toml_syntax.toml"] {
        let p = root.join(case);
        let (code, err) = cli(["run", p.to_str().unwrap()]);
        assert_eq!(code, Some(1), "{case}: {err}");
        assert!(err.starts_with("error: "), "{err}");
        for w in expected(&p) {
            assert!(err.contains(&w), "{case}: {w:?} not in {err}");
        }
    }
    // A broken measurement given to `compare` (the simulation side is a valid file).
    let meas = twinbench::pack::workspace_root().join("data/spielberg_lap.csv");
    let bad = root.join("measurements/distance_backwards.csv");
    let (code, err) = cli(args!["compare", meas, bad, "--signals", "v"]);
    assert_eq!(code, Some(1), "{err}");
    for w in expected(&bad) {
        assert!(err.contains(&w), "{w:?} not in {err}");
    }
}

#[test]
fn numbers_on_the_command_line_are_checked_for_range() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    // A valid system to run with bad numbers: the faulty FMU alone.
    let dir = tb_testkit::scratch("cli-numbers");
    let sys = common::system_file(
        &dir.path().join("sys.toml"),
        "",
        &[("f", &common::fmu("faulty"))],
        "[[instance]]\nname = \"f\"\nfmu = \"f\"\n\n[experiment]\nstep = 0.1\nstop = 1.0\n",
    );
    let sys = sys.to_str().unwrap();
    let meas = root.join("data/spielberg_lap.csv");
    let meas = meas.to_str().unwrap();
    for (args, expected) in [
        (
            vec!["run", sys, "--set", "f.fault_kind=4294967297"],
            "4294967297 does not fit the 32-bit Integer 'f.fault_kind'",
        ),
        (
            vec!["run", sys, "--set", "f.fault_time=nan"],
            "'f.fault_time' must be a finite number, got NaN",
        ),
        (
            vec!["run", sys, "--isolate", "--worker-timeout", "1e300"],
            "--worker-timeout: watchdog must be a number of seconds in [0.001, 86400], got 1e300",
        ),
        // Red team N23: a watchdog far below any round trip made every call a "hang".
        (
            vec!["run", sys, "--isolate", "--worker-timeout", "1e-12"],
            "--worker-timeout: watchdog must be a number of seconds in [0.001, 86400], got 1e-12",
        ),
        (
            vec!["compare", meas, meas, "--signals", "v", "--step", "1e-9"],
            "must be at least 0.001 m",
        ),
    ] {
        let (code, err) = cli(&args);
        assert_eq!(code, Some(1), "{args:?}: {err}");
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}

#[test]
fn an_fmu_error_is_printed_once() {
    common::fmu_dir();
    let p = twinbench::pack::workspace_root().join("tests/bad_files/systems/missing_fmu_file.toml");
    let (code, err) = cli(["run", p.to_str().unwrap()]);
    assert_eq!(code, Some(1), "{err}");
    assert_eq!(
        err.matches("vehicle_v2.fmu does not exist").count(),
        1,
        "{err}"
    );
}
