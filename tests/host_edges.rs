//! What other hosts do at the edges, through the C API of our FMUs: a host that sums its
//! steps in floating point reaches the stop time a little late, and a host that ends an
//! instance whose initialisation failed calls fmi2Terminate from the error state.

mod common;

use common::kinds::refused;

use tb_fmi::fmi2::fmi2Status;
use tb_fmi::FmiFunction::Fmi2;
use tb_fmi::{FmuError, FmuInstance, Function, Instance};
use tb_testkit::assert_contains;

fn instance(model: &str) -> Instance {
    let fmu = common::load(model);
    let mut i = common::instantiate(&fmu, "host", true);
    i.set_echo(false);
    i.set_debug_categories(true, &[]).unwrap();
    i
}

/// [`instance`] of `model`, and the value references of its variables `names`.
fn instance_with<const N: usize>(model: &str, names: [&str; N]) -> (Instance, [u32; N]) {
    let fmu = common::load(model);
    (instance(model), names.map(|n| common::vr(&fmu, n)))
}

/// 100,000 steps of 1 ms summed as a host does end 1.1e-10 s past stopTime = 100 s: every
/// step is accepted (the rule: up to 1e-9·max(|stopTime|, 1 s) past it).
#[test]
fn a_host_that_sums_its_steps_reaches_the_stop_time_with_fmi2ok() {
    let mut i = instance("dyno");
    i.setup_experiment(tb_fmi::Experiment {
        start: 0.0,
        stop: Some(100.0),
        tolerance: None,
    })
    .unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
    let mut t = 0.0f64;
    for k in 0..100_000 {
        i.do_step(t, 0.001)
            .unwrap_or_else(|e| panic!("step {k} at t = {t}: {e}"));
        t += 0.001;
    }
    assert!(t > 100.0 && t - 100.0 < 1e-9, "t = {t}");
    // Well past the stop time is still refused.
    let e = i.do_step(t, 0.001).unwrap_err();
    assert!(refused(&e, Function::DoStep, fmi2Status::ERROR), "{e}");
    assert!(e.to_string().contains("ends after stopTime 100"), "{e}");
    i.terminate().ok();
}

/// fmi2Terminate after a failed initialisation: a warning saying what the standard allows
/// there, not an error; the instance is then freed cleanly.
#[test]
fn terminate_after_a_failed_initialisation_is_a_warning() {
    let (mut i, [vr]) = instance_with("driver", ["target_speed_file"]);
    i.set_string(&[vr], &["/nonexistent/target.csv"]).unwrap();
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    let e = i.exit_initialization_mode();
    assert!(e.is_err(), "a missing target file fails the initialisation");
    i.terminate()
        .expect("fmi2Terminate is accepted with a warning");
    let log = i.last_log_lines().join("\n");
    assert_contains(
        &log,
        &[
            "fmi2Terminate in state 'error' ignored",
            "FMI 2.0 allows only fmi2Reset or fmi2FreeInstance here",
        ],
    );
    // Reset brings it back to a usable instance.
    i.reset().unwrap();
}

/// A Real input a float32 rounding outside its range is taken as the bound; further out it
/// is refused as before.
#[test]
fn an_input_a_rounding_outside_its_range_is_the_bound() {
    let (mut i, [pedal]) = instance_with("edu", ["accel_pedal"]);
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    // 1 as float32, widened: what OMSimulator's solver sent.
    i.set_real(&[pedal], &[1.0f32 as f64 + f32::EPSILON as f64 / 8.0])
        .unwrap();
    i.set_real(&[pedal], &[1.0000000149011612]).unwrap();
    let mut x = [0.0];
    i.get_real(&[pedal], &mut x).unwrap();
    assert_eq!(x[0], 1.0);
    i.set_real(&[pedal], &[-1.0000009]).unwrap();
    i.get_real(&[pedal], &mut x).unwrap();
    assert_eq!(x[0], -1.0);
    let e = i.set_real(&[pedal], &[1.01]).unwrap_err();
    assert!(refused(&e, Function::SetReal, fmi2Status::ERROR), "{e}");
    let log = i.last_log_lines().join("\n");
    assert_contains(&log, &["'accel_pedal' = 1.01 is outside its range [-1, 1]"]);
}

/// FMPy runs the vehicle alone with its wheel-speed inputs at 0 (locked rear wheels): it
/// brakes to rest and stays there; the distance never decreases.
#[test]
fn fmpy_the_vehicle_with_locked_wheels_ends_at_rest() {
    let dir = tb_testkit::scratch("locked");
    let out = dir.path().join("locked.csv");
    let r = std::process::Command::new(common::python::python())
        .arg(twinbench::pack::workspace_root().join("tools/fmpy_simulate.py"))
        .arg(common::fmu("vehicle"))
        .arg(&out)
        .args(["--stop", "15", "--step", "0.001", "--set", "v_start=20"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let t = tb_cosim::Table::read_any(&out).unwrap();
    let v = t.require("v").unwrap();
    let d = t.require("distance").unwrap();
    let stopped = v
        .iter()
        .position(|x| *x == 0.0)
        .expect("the car comes to rest");
    assert!(
        t.column_at(0)[stopped] < 10.0,
        "at rest after {} s",
        t.column_at(0)[stopped]
    );
    assert!(
        v[stopped..].iter().all(|x| *x == 0.0),
        "stays at rest: min v {}",
        v.iter().cloned().fold(f64::INFINITY, f64::min)
    );
    assert!(v.iter().all(|x| *x >= 0.0));
    assert!(
        d.windows(2).all(|w| w[1] >= w[0]),
        "distance never decreases"
    );
}

/// The bench at a 5 ms communication step: a parallel (Jacobi) master makes the EDU-dyno
/// coupling diverge, which the EDU stops within the first fraction of a second naming the
/// coupling; the sequential master still drives the lap.
#[test]
fn a_diverging_coupling_is_stopped_early_and_named() {
    let dir = tb_testkit::scratch("diverge");
    let run = |algorithm: &str| {
        common::run_bench(&dir.path().join(format!("{algorithm}.toml")), |text| {
            text.replace("step = 1e-3", "step = 5e-3").replace(
                "algorithm = \"gauss-seidel\"",
                &format!("algorithm = \"{algorithm}\""),
            )
        })
    };
    let e = run("jacobi").unwrap_err();
    assert!(
        matches!(
            &e,
            tb_cosim::SystemError::Fmu(FmuError::Call {
                instance,
                function: Fmi2(Function::DoStep),
                ..
            }) if instance == "edu"
        ),
        "{e}"
    );
    // Why, in the FMU's words.
    assert_contains(&e.to_string(), &["the EDU-dyno coupling is diverging"]);
    let e = e.to_string();
    let t: f64 = e
        .split("at t = ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|x| x.parse().ok())
        .unwrap();
    assert!(t < 1.0, "stopped at {t} s");
    let lap = run("gauss-seidel").unwrap();
    let lap_time = lap.value("vehicle.lap_time").unwrap();
    // The lap at a 5 ms step: 97.54 s measured (the 1 ms bench 97.56 s, the car 97.49 s).
    assert!((lap_time - 97.54).abs() < 0.2, "lap {lap_time} s");
}

/// `range_check = 0`: an input outside its range is used as it is, with a warning.
#[test]
fn range_check_0_uses_an_out_of_range_input_with_a_warning() {
    let (mut i, [pedal, check]) = instance_with("edu", ["accel_pedal", "range_check"]);
    i.set_integer(&[check], &[0]).unwrap();
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    i.set_real(&[pedal], &[1.5])
        .expect("accepted with a warning");
    let mut x = [0.0];
    i.get_real(&[pedal], &mut x).unwrap();
    assert_eq!(x[0], 1.5);
    let log = i.last_log_lines().join("\n");
    assert_contains(
        &log,
        &["'accel_pedal' = 1.5 is outside its range [-1, 1]; used as it is (range_check = 0)"],
    );
}

/// A get or set whose value references and values differ in length is refused before the
/// FMU is called: FMI 2.0 passes no count of values, so the FMU would read or write past
/// the shorter slice.
#[test]
fn values_of_another_length_than_the_references_are_refused_before_the_call() {
    let mut i = instance("dyno");
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
    let mut two = [f64::NAN; 2];
    let e = i.get_real(&[1, 2, 3], &mut two).unwrap_err();
    assert!(
        matches!(
            &e,
            FmuError::Lengths {
                function: Function::GetReal,
                references: 3,
                values: 2,
                ..
            }
        ),
        "{e}"
    );
    let e = e.to_string();
    assert_eq!(
        e,
        "instance 'host': fmi2GetReal was given 3 value references and 2 values"
    );
    // Nothing was written.
    assert!(two.iter().all(|x| x.is_nan()));
    let e = i.set_integer(&[1], &[1, 2]).unwrap_err();
    assert!(
        matches!(
            &e,
            FmuError::Lengths {
                function: Function::SetInteger,
                references: 1,
                values: 2,
                ..
            }
        ),
        "{e}"
    );
    let mut one = [0];
    assert!(i.get_boolean(&[1, 2], &mut one).is_err());
    assert!(i.set_real(&[], &[1.0]).is_err());
    assert!(i.set_string(&[1, 2], &["one"]).is_err());
    // Equal lengths go through (the shaft torque and torque setpoint inputs, 0 N·m).
    i.get_real(&[1, 2], &mut two).unwrap();
    assert_eq!(two, [0.0, 0.0]);
    i.terminate().ok();
}
