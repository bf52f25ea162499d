//! `twinbench realtime-check`: the bench's four models, as FMI 2.0 and FMI 3.0 FMUs, are
//! clean through their C symbols on a whole lap at 1 kHz and a stretch at 10 kHz (no
//! allocation, lock, log message or system call after initialisation); the hostile FMU's
//! allocation, file write and sleep are each named; the Reference FMUs and the supplier's
//! pythonfmu EDU are checked as any supplier's FMU is; errors say what is wrong.

mod common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

fn check(args: &[&str]) -> Output {
    common::fmu_dir();
    Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .arg("realtime-check")
        .args(args)
        .output()
        .expect("twinbench runs")
}

fn json(out: &Output) -> Value {
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: stdout {} stderr {}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

fn item<'a>(report: &'a Value, name: &str) -> &'a Value {
    report["items"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["name"] == name)
        .unwrap_or_else(|| panic!("no item {name} in {report}"))
}

/// The bench's system with its FMUs of FMI `version` (absolute paths), in `dir`.
fn bench(dir: &Path, version: u8) -> PathBuf {
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml")).unwrap();
    let fmus = root().join("target/fmu");
    let suffix = if version == 3 { "-fmi3" } else { "" };
    let mut text = text;
    for m in ["vehicle", "driver", "dyno", "edu"] {
        text = text.replace(
            &format!("\"../target/fmu/{m}.fmu\""),
            &format!("\"{}\"", fmus.join(format!("{m}{suffix}.fmu")).display()),
        );
    }
    assert!(!text.contains("../target/fmu"), "every FMU replaced");
    let path = dir.join(format!("rls_v_fmi{version}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Every model of the bench clean, as the check of `args` saw it: the counters worked
/// (allocations and system calls seen), nothing counted, `steps` steps per pass.
fn assert_bench_clean(args: &[&str], steps: u64, what: &str) {
    let out = check(args);
    let reports = json(&out);
    let reports = reports.as_array().unwrap();
    let models: Vec<&str> = reports
        .iter()
        .map(|r| r["report"]["model"].as_str().unwrap())
        .collect();
    assert_eq!(models, ["vehicle", "driver", "dyno", "edu"], "{what}");
    for r in reports {
        let (instance, r) = (&r["instance"], &r["report"]);
        let m = &r["measurement"];
        assert_eq!(m["allocations_seen"], true, "{what} {instance}");
        assert_eq!(m["syscalls_seen"], true, "{what} {instance}");
        assert_eq!(
            r["steps_per_pass"].as_u64(),
            Some(steps),
            "{what} {instance}"
        );
        for name in ["allocations", "system calls", "locks", "log messages"] {
            assert_eq!(
                item(r, name)["verdict"],
                "clean",
                "{what} {instance}: {}",
                item(r, name)
            );
        }
        assert_eq!(m["counts"]["malloc"], 0);
        assert_eq!(m["counts"]["syscalls"].as_array().unwrap().len(), 0);
        assert_eq!(r["clean"], true, "{what} {instance}");
    }
    assert!(out.status.success(), "{what}: exit {:?}", out.status);
}

/// The models through their C symbols in a confined worker: a whole lap at 1 kHz (the
/// bench's step; 97,585 steps), then 10 s at 10 kHz, each with the inputs and parameters
/// the bench's own run gives them.
#[test]
fn the_bench_models_are_real_time_clean_as_fmi2_and_fmi3() {
    let dir = tempfile::tempdir().unwrap();
    for version in [2, 3] {
        let system = bench(dir.path(), version);
        let system = system.to_str().unwrap();
        let lap = json(&check(&[system, "--passes", "1", "--json"]));
        let steps = lap[0]["report"]["steps_per_pass"].as_u64().unwrap();
        // The lap is the bench's: about 97.6 s.
        assert!((90_000..110_000).contains(&steps), "{steps}");
        assert_bench_clean(
            &[system, "--passes", "1", "--json"],
            steps,
            &format!("FMI {version}.0 lap at 1 kHz"),
        );
        assert_bench_clean(
            &[
                system,
                "--passes",
                "1",
                "--step",
                "1e-4",
                "--duration",
                "10",
                "--json",
            ],
            100_000,
            &format!("FMI {version}.0 at 10 kHz"),
        );
    }
}

/// The hostile FMU's RT_UNSAFE: a malloc and free, a file written (open, write, close) and
/// a sleep in every step, each named; the exit code fails a CI gate.
#[test]
fn the_hostile_fmus_allocation_file_write_and_sleep_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (fmu, _) = common::hostile::fmu(dir.path(), "RT_UNSAFE");
    // Half a second in steps of 10 ms, `passes` times.
    let fmu = fmu.to_str().unwrap();
    let check_half_second = |passes: &str, more: &[&str]| {
        let head = [
            fmu,
            "--duration",
            "0.5",
            "--step",
            "0.01",
            "--passes",
            passes,
        ];
        check(&[&head[..], more].concat())
    };
    let out = check_half_second("2", &["--json"]);
    assert_eq!(out.status.code(), Some(1), "not clean: exit 1");
    let r = json(&out);
    let steps = 100; // 50 steps × 2 passes
    let counts = &r["measurement"]["counts"];
    assert_eq!(counts["malloc"], steps);
    assert_eq!(counts["free"], steps);
    let calls = |name: &str| {
        counts["syscalls"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["name"] == name)
            .map_or(0, |s| s["calls"].as_u64().unwrap())
    };
    for name in ["openat", "write", "close", "clock_nanosleep"] {
        assert_eq!(calls(name), steps, "{name}: {counts}");
    }
    assert_eq!(item(&r, "allocations")["verdict"], "fails");
    let said = item(&r, "system calls")["says"]
        .as_str()
        .unwrap()
        .to_string();
    assert_contains(&said, &["openat ×100 (file or terminal I/O)"]);
    assert_contains(&said, &["clock_nanosleep ×100 (a sleep or wait)"]);
    // The text report says the same, and the verdict.
    let text = check_half_second("1", &[]);
    let text = String::from_utf8_lossy(&text.stdout);
    assert!(text.contains("malloc ×50, free ×50"), "{text}");
    assert_contains(&text, &["verdict: not clean (allocations, system calls)"]);
    // The file was written in the worker's scratch folder, not beside the FMU.
    assert!(!dir.path().join("rt.log").exists());
}

/// Three Reference FMUs (FMI 2.0 and 3.0) are clean; their figures go to docs/realtime.md.
#[test]
fn reference_fmus_are_checked_as_any_suppliers() {
    for (model, version) in [("BouncingBall", 2), ("VanDerPol", 2), ("Feedthrough", 3)] {
        let fmu = common::reference::fmu(model, version);
        let out = check(&[fmu.to_str().unwrap(), "--json"]);
        let r = json(&out);
        assert_eq!(r["clean"], true, "{model} FMI {version}: {r}");
        assert_eq!(r["measurement"]["passes"], 10, "{model}");
        assert!(out.status.success());
    }
}

/// The supplier's EDU (pythonfmu: an interpreter in every step) is not fit for a
/// real-time target, and the check says why.
#[test]
fn the_suppliers_python_edu_is_not_clean_and_says_why() {
    let fmu = root().join("target/fmu/supplier_edu.fmu");
    let lib = root().join("target/fmu/libpython.so");
    assert!(
        fmu.exists() && lib.exists(),
        "build the supplier EDU: target/venv/bin/python tools/supplier_edu/build.py (tools/test.sh does)"
    );
    let out = check(&[
        fmu.to_str().unwrap(),
        "--preload",
        lib.to_str().unwrap(),
        "--duration",
        "0.2",
        "--passes",
        "1",
        "--json",
    ]);
    assert_eq!(out.status.code(), Some(1));
    let r = json(&out);
    assert_eq!(item(&r, "allocations")["verdict"], "fails");
    assert!(r["measurement"]["counts"]["malloc"].as_u64().unwrap() >= 200);
}

/// doStep's instructions per step under callgrind (10 s at 1 kHz of each bench model): no
/// step costs more than 3 times the mean.
#[test]
fn no_hidden_slow_path_in_the_bench_models_instructions() {
    assert!(
        Command::new("valgrind").arg("--version").output().is_ok(),
        "valgrind is needed (apt-get install valgrind; .ci/run installs it)"
    );
    let dir = tempfile::tempdir().unwrap();
    let system = bench(dir.path(), 2);
    let out = check(&[
        system.to_str().unwrap(),
        "--passes",
        "1",
        "--duration",
        "5",
        "--instructions",
        "--json",
    ]);
    let reports = json(&out);
    for r in reports.as_array().unwrap() {
        let ins = &r["report"]["instructions"];
        assert_eq!(ins["steps"], 5000, "{}", r["instance"]);
        let (mean, max) = (ins["mean"].as_f64().unwrap(), ins["max"].as_f64().unwrap());
        // The models' doStep is hundreds to thousands of instructions.
        assert!(mean > 300.0 && mean < 20_000.0, "{}: {mean}", r["instance"]);
        assert!(
            max <= 3.0 * mean,
            "{}: max {max}, mean {mean}",
            r["instance"]
        );
        assert_eq!(item(&r["report"], "instructions")["verdict"], "clean");
    }
    assert!(out.status.success());
}

/// What cannot be checked is said before anything runs, with exit code 2.
#[test]
fn bad_input_gets_a_clear_error_and_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let dyno = common::fmu("dyno");
    let dyno = dyno.to_str().unwrap();
    let csv = dir.path().join("in.csv");
    std::fs::write(&csv, "time,torque_setpont\n0,1\n1,2\n").unwrap();
    let missing = dir.path().join("nothere.fmu");
    for (args, says) in [
        (vec![missing.to_str().unwrap()], "nothere.fmu"),
        (
            vec![dyno, "--step", "0"],
            "--step 0: expected a step of more than 0 s",
        ),
        (vec![dyno, "--duration", "nan"], "--duration NaN"),
        (
            vec![dyno, "--input", csv.to_str().unwrap()],
            "column 'torque_setpont' is not a Real input of",
        ),
    ] {
        let out = check(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// An input file drives the inputs named by its columns (linear between rows).
#[test]
fn an_input_file_drives_the_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("in.csv");
    std::fs::write(&csv, "time,torque_setpoint,shaft_torque\n0,0,0\n2,100,90\n").unwrap();
    let out = check(&[
        common::fmu("dyno").to_str().unwrap(),
        "--input",
        csv.to_str().unwrap(),
        "--passes",
        "1",
        "--json",
    ]);
    let r = json(&out);
    assert_eq!(
        r["inputs"],
        serde_json::json!(["torque_setpoint", "shaft_torque"])
    );
    assert_eq!(
        r["steps_per_pass"], 2000,
        "to the file's end at the default 1 ms"
    );
    assert_eq!(r["clean"], true);
}
