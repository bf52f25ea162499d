//! The assembled virtual bench on the bundled Spielberg lap, and the orchestrator's errors.

mod common;

use common::kinds::{algebraic_loop, invalid, stopped_by};

use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::plan::ConversionError;
use tb_cosim::{Plan, Simulation, SystemError};
use tb_fmi::fmi2::fmi2Status;
use tb_fmi::{FmuCache, Function};
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

fn cache() -> Arc<FmuCache> {
    Arc::new(FmuCache::temporary(false).unwrap())
}

fn simulate(system: &Path, set: &[(&str, toml::Value)]) -> (tb_cosim::RunSummary, tb_cosim::Table) {
    common::fmu_dir();
    let mut sim = Simulation::new(Plan::load(system, cache()).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    for (k, v) in set {
        sim.set_parameter(k, v.clone()).unwrap();
    }
    let s = sim.run().unwrap();
    (s, sim.recording().clone())
}

struct Measured {
    distance: Vec<f64>,
    v: Vec<f64>,
    lap_time: f64,
}

fn measured() -> Measured {
    let m = tb_compare::Measurement::read_path(root().join("data/spielberg_lap.csv")).unwrap();
    let truth: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root().join("data/spielberg_lap_truth.json")).unwrap(),
    )
    .unwrap();
    Measured {
        distance: m.distance().to_vec(),
        v: m.require("v").unwrap().to_vec(),
        lap_time: truth["lap_time"].as_f64().unwrap(),
    }
}

/// RMS and max of the speed difference over distance [km/h], inside the measured range.
fn speed_error_kmh(rec: &tb_cosim::Table, meas: &Measured) -> (f64, f64) {
    let d = rec.require("vehicle.distance").unwrap();
    let v = rec.require("vehicle.v").unwrap();
    let dmax = *meas.distance.last().unwrap();
    let vm = tb_compare::resample::interp(&meas.distance, &meas.v, d);
    let errs: Vec<f64> = d
        .iter()
        .zip(v)
        .zip(&vm)
        .filter(|((d, _), _)| **d <= dmax)
        .map(|((_, v), m)| (v - m) * 3.6)
        .collect();
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    (rms, errs.iter().fold(0.0f64, |a, e| a.max(e.abs())))
}

#[test]
fn rls_v_drives_the_spielberg_lap() {
    let meas = measured();
    let (s, rec) = simulate(&root().join("systems/rls_v.toml"), &[]);
    let lap = s.value("vehicle.lap_time").expect("lap completed");
    // The twin drives the lap as the car did: the initial twin's lap time within 0.15 s of
    // the car's 97.49 s (measured here: +0.07 s; it was +0.63 s when the driver lagged a
    // target of the speed alone and the driveline lost 4 % the car did not).
    assert!(
        (lap - meas.lap_time).abs() < 0.15,
        "lap time {lap} s vs {}",
        meas.lap_time
    );
    // RMS speed error over distance below 1 km/h (measured here: 0.30 km/h; 1.56 before).
    let (rms, max) = speed_error_kmh(&rec, &meas);
    assert!(rms < 1.0, "RMS speed error {rms} km/h (max {max})");
    // Its a_x over distance follows the measured (filtered, 1 m grid, as the study compares):
    // R² at least 0.97 (measured here: 0.996).
    let cmp = twinbench::bench::compare_table(
        &rec,
        &root().join("data/spielberg_lap.csv"),
        None,
        &["a_x".to_string()],
        &tb_compare::CompareSettings::default(),
    )
    .unwrap();
    let r2 = cmp.get("a_x").unwrap().r_squared;
    eprintln!("lap {lap} s, speed RMS {rms} km/h, a_x R² {r2}");
    assert!(r2 >= 0.97, "a_x R² {r2}");
    // Eq. 17 along the lap: Fz_sum is the sum of the four loads (1e-9 relative), and never
    // below the weight by more than the road excitation can take away (lift presses down).
    let sum = rec.require("vehicle.Fz_sum").unwrap();
    let four: Vec<&[f64]> = [
        "vehicle.Fz_fl",
        "vehicle.Fz_fr",
        "vehicle.Fz_rl",
        "vehicle.Fz_rr",
    ]
    .iter()
    .map(|n| rec.require(n).unwrap())
    .collect();
    for (k, s) in sum.iter().enumerate() {
        let total: f64 = four.iter().map(|c| c[k]).sum();
        assert!(
            (s - total).abs() <= 1e-9 * s.abs(),
            "row {k}: Fz_sum {s} vs {total}"
        );
        assert!(*s > 0.9 * 880.0 * 9.81 - 2000.0, "row {k}: Fz_sum {s}");
    }
}

#[test]
fn a_tenth_millisecond_step_agrees_with_the_millisecond_step() {
    let path = root().join("systems/rls_v.toml");
    let (s1, r1) = simulate(&path, &[]);
    let mut file = tb_cosim::SystemFile::load(&path).unwrap();
    file.experiment.step = 1e-4;
    file.record.decimation = 50;
    common::fmu_dir();
    let mut sim = Simulation::new(Plan::from_file(file, &path, cache()).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    let s2 = sim.run().unwrap();
    let (l1, l2) = (
        s1.value("vehicle.lap_time").unwrap(),
        s2.value("vehicle.lap_time").unwrap(),
    );
    // Lap times within 0.3% and speed over distance within 1 km/h RMS of each other.
    assert!((l1 / l2 - 1.0).abs() < 3e-3, "1 ms: {l1} s, 0.1 ms: {l2} s");
    let other = Measured {
        distance: sim
            .recording()
            .require("vehicle.distance")
            .unwrap()
            .to_vec(),
        v: sim.recording().require("vehicle.v").unwrap().to_vec(),
        lap_time: l2,
    };
    let (rms, _) = speed_error_kmh(&r1, &other);
    assert!(
        rms < 1.0,
        "speed over distance differs by {rms} km/h RMS between 1 ms and 0.1 ms"
    );
}

#[test]
fn jacobi_drives_the_same_lap() {
    let path = root().join("systems/rls_v.toml");
    let mut file = tb_cosim::SystemFile::load(&path).unwrap();
    file.experiment.algorithm = tb_cosim::Algorithm::Jacobi;
    common::fmu_dir();
    let mut sim = Simulation::new(Plan::from_file(file, &path, cache()).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    let lap = s.value("vehicle.lap_time").unwrap();
    assert!(
        (lap / measured().lap_time - 1.0).abs() < 0.03,
        "Jacobi lap {lap} s"
    );
}

#[test]
fn rls_alpha_and_n_alpha_run_the_lap_from_replayed_channels() {
    let meas = measured();
    let (s, rec) = simulate(&root().join("systems/rls_alpha.toml"), &[]);
    let lap = s.value("vehicle.lap_time").unwrap();
    // Open-loop pedals by distance: the lap completes near the measured time (within 5%).
    assert!(
        (lap / meas.lap_time - 1.0).abs() < 0.05,
        "RLS/α lap {lap} s"
    );
    assert!(rec
        .require("pedals.brake_pedal")
        .unwrap()
        .iter()
        .any(|&b| b > 0.5));
    let (s, rec) = simulate(&root().join("systems/n_alpha.toml"), &[]);
    assert!((s.simulated_time - 97.48).abs() < 1e-9);
    // Speed-controlled dynos follow the measured wheel speeds (RMS within 1 rad/s).
    let w = rec.require("dyno_rl.omega").unwrap();
    let wm = rec.require("meas.omega_rl").unwrap();
    let rms = (w.iter().zip(wm).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / w.len() as f64).sqrt();
    assert!(rms < 1.0, "n/α speed tracking RMS {rms} rad/s");
    assert!(rec
        .require("edu.electric_power")
        .unwrap()
        .iter()
        .any(|&p| p > 1e5));
}

#[test]
fn reruns_of_one_simulation_reuse_instances_and_repeat_exactly() {
    common::fmu_dir();
    let path = root().join("systems/rls_v.toml");
    let mut file = tb_cosim::SystemFile::load(&path).unwrap();
    file.experiment.stop = tb_cosim::StopConfig::Time(5.0);
    let mut sim = Simulation::new(Plan::from_file(file, &path, cache()).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    sim.run().unwrap();
    let first = sim.recording().clone();
    sim.set_parameter("vehicle.c_lift_front", toml::Value::Float(0.8))
        .unwrap();
    sim.run().unwrap();
    let changed = sim.recording().require("vehicle.Fz_sum").unwrap().to_vec();
    sim.set_parameter("vehicle.c_lift_front", toml::Value::Float(1.653))
        .unwrap();
    sim.run().unwrap();
    assert_eq!(
        first.require("vehicle.Fz_sum").unwrap(),
        sim.recording().require("vehicle.Fz_sum").unwrap()
    );
    assert!(changed
        .iter()
        .zip(first.require("vehicle.Fz_sum").unwrap())
        .all(|(a, b)| a < b));
}

// ---- errors, each asserting its message ----

fn system_text(body: &str) -> String {
    let dir = common::fmu_dir();
    format!(
        "{body}\n[fmus]\nvehicle = \"{v}\"\ndyno = \"{d}\"\nfaulty = \"{f}\"\n",
        v = dir.join("vehicle.fmu").display(),
        d = dir.join("dyno.fmu").display(),
        f = dir.join("test/faulty.fmu").display(),
    )
}

/// The system's error, as the library returns it.
fn load_error(body: &str) -> SystemError {
    let text = system_text(body);
    let path = std::env::temp_dir().join(format!("tb-bench-err-{}.toml", std::process::id()));
    let file = tb_cosim::SystemFile::parse(&text, &path).unwrap();
    match Plan::from_file(file, &path, cache()) {
        Ok(_) => panic!("expected an error for:\n{body}"),
        Err(e) => e,
    }
}

const TWO: &str = "[[instance]]\nname = \"vehicle\"\nfmu = \"vehicle\"\n\n[[instance]]\nname = \"dyno_rl\"\nfmu = \"dyno\"\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n";

#[test]
fn unknown_variable_suggests_the_closest_names() {
    let e = load_error(&format!(
        "connections = [\"vehicle.torque_setpoint_rll -> dyno_rl.torque_setpoint\"]\n{TWO}"
    ));
    assert!(
        invalid(
            &e,
            "connection \"vehicle.torque_setpoint_rll -> dyno_rl.torque_setpoint\""
        ),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["unknown variable 'vehicle.torque_setpoint_rll'"],
    );
    assert_contains(
        &e.to_string(),
        &["closest names: torque_setpoint_rl, torque_setpoint_rr"],
    );
    let e = load_error(&format!(
        "connections = [\"vehicle.v -> dyno_rx.shaft_torque\"]\n{TWO}"
    ));
    assert!(
        invalid(&e, "connection \"vehicle.v -> dyno_rx.shaft_torque\""),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["unknown instance 'dyno_rx'; instances: dyno_rl"],
    );
}

#[test]
fn output_connected_to_an_output_is_refused() {
    let e = load_error(&format!(
        "connections = [\"vehicle.torque_setpoint_rl -> dyno_rl.omega\"]\n{TWO}"
    ));
    assert!(
        invalid(
            &e,
            "connection \"vehicle.torque_setpoint_rl -> dyno_rl.omega\""
        ),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["'dyno_rl.omega' is continuous output, not an input"],
    );
}

#[test]
fn incompatible_units_are_refused_and_compatible_ones_converted() {
    let e = load_error(&format!(
        "connections = [\"vehicle.v -> dyno_rl.shaft_torque\"]\n{TWO}"
    ));
    assert!(
        matches!(&e, SystemError::Conversion { error: ConversionError::Incompatible { from, to }, .. } if from == "m/s" && to == "N.m"),
        "{e}"
    );
}

#[test]
fn a_direct_feed_through_cycle_is_reported_with_its_variables() {
    let body = "connections = [\"a.y_direct -> b.u\", \"b.y_direct -> a.u\"]\n[[instance]]\nname = \"a\"\nfmu = \"faulty\"\n\n[[instance]]\nname = \"b\"\nfmu = \"faulty\"\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n";
    let e = load_error(body);
    assert!(algebraic_loop(&e), "{e}");
    let e = e.to_string();
    assert_contains(&e, &["a.y_direct", "b.u", "b.y_direct", "a.u"]);
    // The same wiring through a stepped output (no feed-through) is fine.
    let ok = system_text("connections = [\"a.steps -> b.u\", \"b.steps -> a.u\"]\n[[instance]]\nname = \"a\"\nfmu = \"faulty\"\n\n[[instance]]\nname = \"b\"\nfmu = \"faulty\"\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n");
    let path = std::env::temp_dir().join("tb-bench-ok.toml");
    Plan::from_file(
        tb_cosim::SystemFile::parse(&ok, &path).unwrap(),
        &path,
        cache(),
    )
    .unwrap();
}

#[test]
fn an_fmu_failing_at_one_second_stops_the_run_with_instance_time_and_log() {
    let body = "[[instance]]\nname = \"supplier\"\nfmu = \"faulty\"\n\n[parameters]\n\"supplier.fault_kind\" = 1\n\"supplier.u\" = 1.0\n\n[experiment]\nstep = 1e-3\nstop = 2.0\n";
    let text = system_text(body);
    let path = std::env::temp_dir().join("tb-bench-fail.toml");
    let sys = Plan::from_file(
        tb_cosim::SystemFile::parse(&text, &path).unwrap(),
        &path,
        cache(),
    )
    .unwrap();
    let mut sim = Simulation::new(sys).unwrap();
    sim.echo_fmu_log = false;
    let e = sim.run().unwrap_err();
    assert!(
        stopped_by(&e, "supplier", Function::DoStep, fmi2Status::ERROR, 1.0),
        "{e}"
    );
    // The FMU's log: why.
    assert_contains(
        &e.to_string(),
        &["fault_kind = 1: the step fails on purpose"],
    );
}

#[test]
fn bad_parameters_and_experiments_are_refused_before_the_first_step() {
    let e = load_error(&format!("[parameters]\n\"vehicle.m\" = -5.0\n{TWO}"));
    assert!(invalid(&e, "parameter \"vehicle.m\""), "{e}");
    assert_contains(
        &e.to_string(),
        &["-5 is outside the declared range [1, 100000] of 'vehicle.m'"],
    );
    let e = load_error(&format!("[parameters]\n\"vehicle.v\" = 5.0\n{TWO}"));
    assert!(invalid(&e, "parameter \"vehicle.v\""), "{e}");
    assert!(
        e.to_string()
            .contains("only parameters and inputs can be set"),
        "{e}"
    );
    let e = load_error(&TWO.replace("step = 1e-3", "step = -1e-3"));
    assert!(invalid(&e, ".toml"), "{e}");
    assert!(
        e.to_string().contains("experiment.step must be positive"),
        "{e}"
    );
    let e = load_error(&format!("connections = [\"vehicle.torque_setpoint_rl -> dyno_rl.torque_setpoint\", \"vehicle.torque_setpoint_rr -> dyno_rl.torque_setpoint\"]\n{TWO}"));
    assert!(
        invalid(
            &e,
            "connection \"vehicle.torque_setpoint_rr -> dyno_rl.torque_setpoint\""
        ),
        "{e}"
    );
    assert!(e.to_string().contains("already connected"), "{e}");
}
