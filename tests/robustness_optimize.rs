//! Faults in `twinbench optimize`: a supplier FMU that fails (error, discard, fatal, NaN,
//! panic in-process; abort and hang isolated in a worker process with a short watchdog)
//! makes a penalised candidate with its reason, and the study goes on to its end.
//!
//! The study's system is the RLS/v bench plus the faulty FMU (instance `supplier`), whose
//! `fault_time` is the optimised parameter: the start value (past the lap) runs clean,
//! candidates below the lap time fail at that time.

mod common;

use common::study;
use std::path::Path;
use std::sync::Arc;
use tb_compare::PreparedMeasurement;
use tb_cosim::SystemError;
use tb_fmi::FmuCache;
use tb_optimize::{run_study, FailureKind, RunError, RunOptions, Study, StudyOutcome, WorkerPool};

/// rls_v.toml with absolute paths and the supplier instance.
fn system_text(kind: i32, isolate: bool) -> String {
    let root = twinbench::pack::workspace_root();
    let text = std::fs::read_to_string(root.join("systems/rls_v.toml")).unwrap();
    let fmu_dir = root.join("target/fmu");
    let text = text.replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()));
    let text = text.replace(
        "[fmus]\n",
        &format!(
            "[fmus]\nfaulty = \"{}\"\n",
            fmu_dir.join("test/faulty.fmu").display()
        ),
    );
    let text = text.replace(
        "[parameters]\n",
        &format!(
            "[parameters]\n\"supplier.fault_kind\" = {kind}\n\"supplier.u\" = 1.0\n\"supplier.fault_time\" = 150.0\n"
        ),
    );
    format!(
        "{text}\n[[instance]]\nname = \"supplier\"\nfmu = \"faulty\"\nisolate = {isolate}\nwatchdog = 1.0\n"
    )
}

fn study_text(system: &Path) -> String {
    let head = study::head(
        "faults",
        system,
        "seed = 5\npenalty = 10.0",
        &["supplier.y"],
    );
    format!(
        r#"{head}[optimizer]
kind = "ga"
generations = 1
[optimizer.ga]
population = 4
elites = 1
[[step]]
name = "supplier"
signals = ["Fz_sum"]
[[step.parameter]]
name = "supplier.fault_time"
min = 0.2
max = 150.0
start = 150.0
"#
    )
}

fn run_faulty_study(kind: i32, isolate: bool) -> (usize, Vec<String>, f64) {
    common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    let sys = dir.path().join("system.toml");
    std::fs::write(&sys, system_text(kind, isolate)).unwrap();
    let study_path = dir.path().join("study.toml");
    std::fs::write(&study_path, study_text(&sys)).unwrap();
    let study = Study::load(&study_path).unwrap();
    let options = RunOptions {
        threads: 2,
        checkpoint: Some(dir.path().join("cp.json")),
        ..RunOptions::default()
    };
    let r = match run_study(&study, &options).unwrap() {
        StudyOutcome::Finished(r) => *r,
        StudyOutcome::Interrupted { .. } => panic!("interrupted"),
    };
    let s = &r.steps[0];
    (s.failures, s.failure_reasons.clone(), s.cost_after)
}

fn check(kind: i32, isolate: bool, cause: &str) {
    let (failures, reasons, best) = run_faulty_study(kind, isolate);
    assert!(
        failures >= 1,
        "kind {kind}: the seed was chosen to draw failing candidates"
    );
    assert_eq!(reasons.len(), failures);
    for r in &reasons {
        assert!(
            r.contains("'supplier'") && r.contains(" at t = "),
            "kind {kind}: {r}"
        );
        assert!(r.contains(cause), "kind {kind}: {cause:?} not in {r}");
    }
    // The study went on: the clean start value stays the best, with a finite cost.
    assert!(best < 10.0, "kind {kind}: best cost {best}");
}

#[test]
fn in_process_faults_are_penalised_candidates_with_their_reason() {
    check(1, false, "fmi2DoStep returned fmi2Error");
    check(7, false, "fmi2DoStep returned fmi2Discard");
    check(8, false, "fmi2DoStep returned fmi2Fatal");
    check(2, false, "the model panicked");
    check(3, false, "supplier.y is not finite (NaN)");
}

#[test]
fn an_isolated_abort_is_a_penalised_candidate_with_its_reason() {
    check(4, true, "killed by signal 6 (SIGABRT: abort)");
}

#[test]
fn an_isolated_hang_is_a_penalised_candidate_with_its_reason() {
    check(5, true, "no answer within 1s (watchdog)");
}

/// The worker pool's error for a candidate whose supplier fails at t = 1 s (after a check
/// that a candidate of another length is refused before anything runs).
fn pool_failure(kind: i32, isolate: bool) -> RunError {
    common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    let sys = dir.path().join("system.toml");
    std::fs::write(&sys, system_text(kind, isolate)).unwrap();
    let study_path = dir.path().join("study.toml");
    std::fs::write(&study_path, study_text(&sys)).unwrap();
    let study = Study::load(&study_path).unwrap();
    let pool = WorkerPool::new(&study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let prepared =
        PreparedMeasurement::from_path(&study.measurement_path, &["Fz_sum"], &study.file.compare)
            .unwrap();
    let mut x: Vec<f64> = pool.assignment().iter().map(|a| a.1).collect();
    assert!(matches!(
        pool.run(&x[1..], &prepared),
        Err(RunError::Count { .. })
    ));
    x[pool.index_of("supplier.fault_time").unwrap()] = 1.0;
    pool.run(&x, &prepared)
        .err()
        .expect("the fault fails the run")
}

#[test]
fn a_failed_candidate_keeps_its_kind_through_the_pool_and_across_processes() {
    let e = pool_failure(1, false);
    assert!(
        matches!(&e, RunError::Simulation(s) if matches!(**s, SystemError::Fmu(_))),
        "{e}"
    );
    assert_eq!(e.kind(), FailureKind::Fmu);
    let e = pool_failure(3, false);
    assert!(
        matches!(&e, RunError::Simulation(s) if matches!(**s, SystemError::NotFinite { .. })),
        "{e}"
    );
    let e = pool_failure(4, true);
    assert_eq!(e.kind(), FailureKind::Worker, "{e}");
    // A Dask task's failure crosses processes as its kind and message, and comes back so.
    let back = RunError::from_wire(e.kind().name(), e.to_string());
    assert!(matches!(
        &back,
        RunError::Remote {
            kind: FailureKind::Worker,
            ..
        }
    ));
    assert_eq!(back.to_string(), e.to_string());
}

// ---- SIGKILL and resume ----

fn optimize_cli(study: &Path, out: &Path, resume: bool) -> std::process::Command {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"));
    c.args(["optimize", study.to_str().unwrap(), "--json", "--no-report"])
        .args(["--threads", "2", "--out", out.to_str().unwrap()]);
    if resume {
        c.arg("--resume");
    }
    c.stderr(std::process::Stdio::null());
    c
}

/// What the optimisation decided (not the timings of the session).
fn decisions(json: &[u8]) -> serde_json::Value {
    let v: serde_json::Value = serde_json::from_slice(json).expect("a JSON result");
    let steps: Vec<serde_json::Value> = v["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            serde_json::json!({
                "after_exact": s["after_exact"],
                "cost_after": s["cost_after"],
                "history": s["history"],
                "evaluations": s["evaluations"],
            })
        })
        .collect();
    serde_json::json!({ "steps": steps, "final": v["parameters_final"] })
}

#[test]
fn an_optimisation_killed_with_sigkill_and_resumed_ends_as_an_uninterrupted_one() {
    common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    let study = dir.path().join("study.toml");
    let head = study::head("killed", &study::rls_v(), "seed = 11", &[]);
    std::fs::write(
        &study,
        format!(
            r#"{head}[optimizer]
kind = "cmaes"
generations = 3
[optimizer.cmaes]
population = 4
[[step]]
name = "lift"
signals = ["Fz_sum"]
[[step.parameter]]
name = "vehicle.c_lift_front"
min = 0.2
max = 2.5
"#
        ),
    )
    .unwrap();
    let whole = optimize_cli(&study, &dir.path().join("a"), false)
        .output()
        .unwrap();
    assert!(whole.status.success());
    // Killed with SIGKILL right after its first checkpoint, then resumed.
    let out = dir.path().join("b");
    let checkpoint = out.join("killed.checkpoint.json");
    let mut child = optimize_cli(&study, &out, false)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !checkpoint.exists() && t0.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let _ = child.kill(); // SIGKILL
    let status = child.wait().unwrap();
    assert!(!status.success(), "finished before it could be killed");
    // The checkpoint on disk is whole (written atomically).
    serde_json::from_slice::<serde_json::Value>(&std::fs::read(&checkpoint).unwrap())
        .expect("a complete checkpoint");
    let resumed = optimize_cli(&study, &out, true).output().unwrap();
    assert!(resumed.status.success());
    let r: serde_json::Value = serde_json::from_slice(&resumed.stdout).unwrap();
    assert_eq!(r["resumed"], serde_json::Value::Bool(true));
    assert_eq!(decisions(&whole.stdout), decisions(&resumed.stdout));
}
