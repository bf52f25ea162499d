//! Faults in running FMUs: the `faulty` test FMU fails at `fault_time` as `fault_kind`
//! says. In-process, an error, a discard, a fatal error, a NaN output and a panic each stop
//! the run cleanly with the instance, the time and the reason. Isolated in a worker
//! process, an abort (the process dies) and a hang (the watchdog) do too, and the host lives.

mod common;

use common::kinds::{stopped_by, worker_failed};

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tb_cosim::isolated::IsolationOptions;
use tb_cosim::{LoadOptions, Plan, Simulation, SystemError, SystemFile};
use tb_fmi::fmi2::fmi2Status;
use tb_fmi::{FmuCache, Function};
use tb_testkit::assert_contains;

fn cache() -> Arc<FmuCache> {
    Arc::new(FmuCache::temporary(false).unwrap())
}

/// A system of one faulty instance `supplier` (fault at 1 s, stop at 2 s) feeding a healthy one.
fn system_text(kind: i32, isolate_supplier: bool) -> String {
    format!(
        r#"connections = ["supplier.steps -> healthy.u"]

[fmus]
faulty = "{f}"

[[instance]]
name = "supplier"
fmu = "faulty"
isolate = {isolate_supplier}

[[instance]]
name = "healthy"
fmu = "faulty"

[parameters]
"supplier.fault_kind" = {kind}
"supplier.fault_time" = 1.0
"supplier.u" = 1.0

[experiment]
step = 1e-2
stop = 2.0
"#,
        f = common::fmu("faulty").display()
    )
}

fn options(isolate: bool, timeout: Duration) -> LoadOptions {
    LoadOptions {
        isolate,
        isolation: IsolationOptions {
            timeout,
            worker_exe: Some(PathBuf::from(env!("CARGO_BIN_EXE_twinbench"))),
            ..Default::default()
        },
        ..Default::default()
    }
}

fn simulation(text: &str, opts: &LoadOptions) -> Simulation {
    let path = std::env::temp_dir().join(format!("tb-faults-{}.toml", std::process::id()));
    let file = SystemFile::parse(text, &path).unwrap();
    let sys = Plan::compile(file, &path, cache(), opts).unwrap();
    let mut sim = Simulation::new(sys).unwrap();
    sim.echo_fmu_log = false;
    sim
}

fn run_err(kind: i32, opts: &LoadOptions) -> (SystemError, String) {
    let mut sim = simulation(&system_text(kind, false), opts);
    let e = sim.run().unwrap_err();
    let s = e.to_string();
    (e, s)
}

fn in_process() -> LoadOptions {
    options(false, Duration::from_secs(10))
}

/// An error, a discard, a fatal error and a panic in a step stop the run with the
/// instance, the time, the step's status and the reason (each case the test it was).
#[test]
fn a_failed_step_stops_the_run_naming_instance_time_and_reason() {
    for (case, kind, status, why) in [
        (
            "an_error_stops_the_run_naming_instance_time_and_reason",
            1,
            fmi2Status::ERROR,
            "fault_kind = 1: the step fails on purpose",
        ),
        (
            "a_discard_stops_the_run_naming_instance_time_and_reason",
            7,
            fmi2Status::DISCARD,
            "fault_kind = 7: the step is discarded on purpose",
        ),
        (
            "a_fatal_error_stops_the_run_naming_instance_time_and_reason",
            8,
            fmi2Status::FATAL,
            "fault_kind = 8: a fatal error on purpose",
        ),
        (
            "a_panic_is_caught_by_the_fmu_and_stops_the_run",
            2,
            fmi2Status::ERROR,
            "the model panicked: fault_kind = 2: the model panics on purpose",
        ),
    ] {
        let (e, s) = run_err(kind, &in_process());
        assert!(
            stopped_by(&e, "supplier", Function::DoStep, status, 1.0),
            "{case}: {s}"
        );
        // The FMU's reason, from its log.
        assert!(s.contains(why), "{case}: {s}");
    }
}

#[test]
fn a_nan_output_stops_the_run_naming_instance_time_and_signal() {
    let (e, s) = run_err(3, &in_process());
    assert!(
        matches!(&e, SystemError::NotFinite { instance, signal, value, .. }
            if instance == "supplier" && signal == "supplier.y" && value.is_nan()),
        "{s}"
    );
    assert_contains(
        &s,
        &["supplier.y is not finite (NaN) at t = 1.01 s after the step of instance 'supplier'"],
    );
}

#[test]
fn an_error_in_initialization_names_the_instance() {
    let (e, s) = run_err(6, &in_process());
    // A getter in initialization mode defers a failed initialisation: the error is
    // fmi2ExitInitializationMode's, once.
    assert!(
        stopped_by(
            &e,
            "supplier",
            Function::ExitInitializationMode,
            fmi2Status::ERROR,
            0.0
        ),
        "{s}"
    );
    assert_eq!(
        s.matches("initialization fails on purpose").count(),
        1,
        "{s}"
    );
    assert_contains(&s, &["fault_kind = 6: initialization fails on purpose"]);
}

#[test]
fn after_a_fault_the_same_simulation_runs_again_once_repaired() {
    let mut sim = simulation(&system_text(1, false), &in_process());
    sim.run().unwrap_err();
    sim.set_parameter("supplier.fault_kind", toml::Value::Integer(0))
        .unwrap();
    let s = sim.run().unwrap();
    assert_eq!(s.steps, 200);
}

// ---- isolation ----

fn isolated(timeout: Duration) -> LoadOptions {
    options(true, timeout)
}

/// Tests that start worker processes run one at a time, so that counting this process's
/// children tells whether a test left one behind.
fn serial() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

/// Pids of this process's children that are still alive (zombies are not).
fn live_children() -> Vec<u32> {
    let me = std::process::id().to_string();
    let mut out = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid ...
        let Some(rest) = stat.rsplit_once(')').map(|r| r.1) else {
            continue;
        };
        let f: Vec<&str> = rest.split_whitespace().collect();
        if f.len() > 1 && f[1] == me && f[0] != "Z" {
            if let Ok(pid) = e.file_name().to_string_lossy().parse() {
                out.push(pid);
            }
        }
    }
    out
}

#[test]
fn isolated_runs_give_the_same_results_as_in_process_runs() {
    let _serial = serial();
    let text = system_text(0, false);
    let mut a = simulation(&text, &in_process());
    let mut b = simulation(&text, &isolated(Duration::from_secs(10)));
    a.run().unwrap();
    b.run().unwrap();
    assert_eq!(a.recording().names(), b.recording().names());
    for (x, y) in a.recording().columns().iter().zip(b.recording().columns()) {
        assert_eq!(x, y);
    }
    // Instance reuse: a second run on the same workers.
    b.set_parameter("supplier.gain", toml::Value::Float(2.0))
        .unwrap();
    b.run().unwrap();
    let y = b.recording().require("supplier.y").unwrap();
    assert!((y.last().unwrap() - 4.0).abs() < 1e-9, "{y:?}");
}

#[test]
fn isolated_errors_keep_their_fmi_status_and_log() {
    let _serial = serial();
    let timeout = Duration::from_secs(10);
    for (kind, status, why) in [
        (1, fmi2Status::ERROR, "the step fails on purpose"),
        (7, fmi2Status::DISCARD, "the step is discarded on purpose"),
        (8, fmi2Status::FATAL, "a fatal error on purpose"),
        (2, fmi2Status::ERROR, "the model panics on purpose"),
    ] {
        let (e, s) = run_err(kind, &isolated(timeout));
        // The worker's error as the in-process one: the call, its status, the time.
        assert!(
            stopped_by(&e, "supplier", Function::DoStep, status, 1.0),
            "{s}"
        );
        assert!(s.contains(why), "{s}");
    }
    let (e, s) = run_err(3, &isolated(timeout));
    assert!(matches!(e, SystemError::NotFinite { .. }), "{s}");
}

#[test]
fn an_abort_in_an_isolated_fmu_ends_the_run_and_the_host_lives() {
    let _serial = serial();
    let mut sim = simulation(&system_text(4, true), &in_process());
    let e = sim.run().unwrap_err();
    assert!(worker_failed(&e, "supplier", "fmi2DoStep", 1.0), "{e}");
    assert_contains(&e.to_string(), &["instance 'supplier' at t = 1 s: fmi2DoStep in the isolated worker process: the worker process was killed by signal 6 (SIGABRT: abort) (crashed)"]);
    // The host goes on: repaired, the same simulation runs (a new worker is started).
    sim.set_parameter("supplier.fault_kind", toml::Value::Integer(0))
        .unwrap();
    assert_eq!(sim.run().unwrap().steps, 200);
    drop(sim);
    assert_eq!(live_children(), Vec::<u32>::new());
}

#[test]
fn a_hang_in_an_isolated_fmu_is_ended_by_the_watchdog() {
    let _serial = serial();
    let mut sim = simulation(
        &system_text(5, false),
        &isolated(Duration::from_millis(1500)),
    );
    let t0 = Instant::now();
    let e = sim.run().unwrap_err();
    let waited = t0.elapsed();
    assert!(worker_failed(&e, "supplier", "fmi2DoStep", 1.0), "{e}");
    assert_contains(&e.to_string(), &["instance 'supplier' at t = 1 s: fmi2DoStep in the isolated worker process: no answer within 1.5s (watchdog): the FMU hangs; killed (the worker process was killed by signal 9 (SIGKILL))"]);
    assert!(waited < Duration::from_secs(5), "{waited:?}");
    drop(sim);
    assert_eq!(live_children(), Vec::<u32>::new());
}

// ---- the command line ----

#[test]
fn twinbench_run_isolate_survives_an_abort_and_a_hang() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let sys = dir.path().join("abort.toml");
    std::fs::write(&sys, system_text(4, false)).unwrap();
    let out = common::twinbench(["run", sys.to_str().unwrap(), "--isolate"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_contains(&err, &["error: instance 'supplier' at t = 1 s: fmi2DoStep in the isolated worker process: the worker process was killed by signal 6"]);
    // Per instance in the system file, with a short watchdog from the command line.
    std::fs::write(&sys, system_text(5, true)).unwrap();
    let out = common::twinbench(["run", sys.to_str().unwrap(), "--worker-timeout", "1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("no answer within 1s (watchdog)"), "{err}");
    // An error in-process is a clean stop too, with exit code 1.
    std::fs::write(&sys, system_text(7, false)).unwrap();
    let out = common::twinbench(["run", sys.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("fmi2DoStep returned fmi2Discard"), "{err}");
}

#[test]
fn an_isolated_simulation_can_move_between_threads() {
    // Workers must not die with the thread that started them (hosts pool simulations).
    let _serial = serial();
    let mut sim = std::thread::spawn(|| {
        let mut sim = simulation(&system_text(0, true), &in_process());
        sim.run().unwrap();
        sim
    })
    .join()
    .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(sim.run().unwrap().steps, 200);
}
