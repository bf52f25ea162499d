//! Acceptance tests of the reference EDU (issue 3). Each states its tolerance.

use edu::{Edu, EduVars};
use fmu_export::fmi2::fmi2Status;
use fmu_export::{Runtime, Value};
use tb_testkit::Capture;

const DT: f64 = 1e-3;
const ETA_M: f64 = 0.9;
const ETA_G: f64 = 0.96;

fn start(params: &[(&str, f64)]) -> Runtime<Edu> {
    let mut rt = Runtime::<Edu>::new("edu", None, Capture::default().boxed(), false);
    for (n, x) in params {
        assert_eq!(rt.set_by_name(n, Value::Real(*x)), fmi2Status::OK, "{n}");
    }
    rt.setup_experiment(0.0, None);
    rt.enter_initialization_mode();
    assert_eq!(rt.exit_initialization_mode(), fmi2Status::OK);
    rt
}

fn get(rt: &mut Runtime<Edu>, n: &str) -> f64 {
    rt.get_by_name(n).unwrap().as_f64()
}

fn set(rt: &mut Runtime<Edu>, n: &str, x: f64) {
    assert_eq!(rt.set_by_name(n, Value::Real(x)), fmi2Status::OK, "{n}");
}

/// Hold the wheel-side speeds and the pedal for `seconds`.
fn hold(rt: &mut Runtime<Edu>, pedal: f64, wl: f64, wr: f64, seconds: f64) {
    set(rt, "accel_pedal", pedal);
    set(rt, "omega_left", wl);
    set(rt, "omega_right", wr);
    for _ in 0..(seconds / DT).round() as usize {
        let t = rt.time();
        assert_eq!(rt.do_step(t, DT), fmi2Status::OK);
    }
}

#[test]
fn table_is_consistent() {
    fmu_export::description::validate_table::<EduVars>().unwrap();
}

/// Steady motoring: shaft power = electric power · η_m · η_g within 0.5%; torques equal
/// (exactly); motor at ratio × wheel speed (1e-9).
#[test]
fn steady_motoring_efficiency() {
    for (pedal, w) in [(0.5, 100.0), (1.0, 60.0), (1.0, 150.0), (0.3, 20.0)] {
        let mut rt = start(&[("omega_wheel_start", w)]);
        hold(&mut rt, pedal, w, w, 3.0);
        let (pe, ps) = (get(&mut rt, "electric_power"), get(&mut rt, "shaft_power"));
        let err = ps / (pe * ETA_M * ETA_G) - 1.0;
        println!(
            "motoring pedal {pedal}, {w} rad/s: P_el {pe:.1} W, P_shaft {ps:.1} W, error {:.2e}",
            err
        );
        assert!(pe > 0.0 && err.abs() < 5e-3);
        assert_eq!(get(&mut rt, "torque_left"), get(&mut rt, "torque_right"));
        assert!((get(&mut rt, "motor_speed") / (17.86 * w) - 1.0).abs() < 1e-9);
        let t_avail = 150f64.min(200_000.0 / (17.86 * w));
        assert!((get(&mut rt, "motor_torque") / (pedal * t_avail) - 1.0).abs() < 1e-9);
    }
}

/// Steady regenerative braking: shaft power = electric power / (η_m · η_g) within 0.5%.
#[test]
fn steady_braking_efficiency() {
    for (pedal, w) in [(-0.5, 100.0), (-1.0, 150.0)] {
        let mut rt = start(&[("omega_wheel_start", w)]);
        hold(&mut rt, pedal, w, w, 3.0);
        let (pe, ps) = (get(&mut rt, "electric_power"), get(&mut rt, "shaft_power"));
        let err = ps / (pe / (ETA_M * ETA_G)) - 1.0;
        println!(
            "braking pedal {pedal}, {w} rad/s: P_el {pe:.1} W, P_shaft {ps:.1} W, error {:.2e}",
            err
        );
        assert!(pe < 0.0 && ps < pe && err.abs() < 5e-3);
        assert_eq!(get(&mut rt, "torque_left"), get(&mut rt, "torque_right"));
    }
}

/// Open differential: in a steady turn (left wheel slower) both shafts carry the same torque
/// (1e-9 relative) and the motor runs at ratio × the mean wheel speed.
#[test]
fn differential_splits_torque_equally_in_a_turn() {
    let mut rt = start(&[("omega_wheel_start", 100.0)]);
    hold(&mut rt, 0.7, 95.0, 105.0, 3.0);
    let (tl, tr) = (get(&mut rt, "torque_left"), get(&mut rt, "torque_right"));
    assert!(tl > 0.0 && ((tl - tr) / tl).abs() < 1e-9);
    assert!((get(&mut rt, "motor_speed") / (17.86 * 100.0) - 1.0).abs() < 1e-9);
    // Gearbox: total shaft torque = i·η_g·motor torque (1e-9).
    let tm = get(&mut rt, "motor_torque");
    assert!(((tl + tr) / (17.86 * ETA_G * tm) - 1.0).abs() < 1e-9);
}

/// Torque never beyond torque_max nor power_max / |ω|, through pedal steps, regeneration and
/// a speed sweep 0 → 250 rad/s (1e-12 relative).
#[test]
fn torque_never_exceeds_its_limits() {
    let mut rt = start(&[("omega_wheel_start", 0.0)]);
    let mut max_power: f64 = 0.0;
    let mut max_torque: f64 = 0.0;
    for k in 0..10_000 {
        let t = k as f64 * DT;
        let pedal = match (k / 250) % 6 {
            0 => 1.0,
            1 => 0.0,
            2 => 1.0,
            3 => -1.0,
            4 => 0.4,
            _ => -0.2,
        };
        let w = 25.0 * t;
        set(&mut rt, "accel_pedal", pedal);
        set(&mut rt, "omega_left", w);
        set(&mut rt, "omega_right", w * 1.02);
        assert_eq!(rt.do_step(t, DT), fmi2Status::OK);
        let (tm, wm) = (get(&mut rt, "motor_torque"), get(&mut rt, "motor_speed"));
        assert!(tm.abs() <= 150.0 * (1.0 + 1e-12), "torque {tm} at t {t}");
        assert!(
            (tm * wm).abs() <= 200_000.0 * (1.0 + 1e-12),
            "power {} at t {t}",
            tm * wm
        );
        max_power = max_power.max((tm * wm).abs());
        max_torque = max_torque.max(tm.abs());
    }
    println!("limits: max |T_m| {max_torque:.3} N.m, max |P_m| {max_power:.1} W");
    assert!(
        max_torque > 149.0 && max_power > 199_000.0,
        "the sweep should reach both limits"
    );
}

/// The current loop lags: after one time constant the torque is at 1 − 1/e of the step (1%).
#[test]
fn current_loop_lag() {
    let mut rt = start(&[("omega_wheel_start", 50.0), ("current_time_constant", 0.01)]);
    hold(&mut rt, 0.5, 50.0, 50.0, 0.01);
    let tm = get(&mut rt, "motor_torque");
    let want = 75.0 * (1.0 - (-1f64).exp());
    assert!((tm / want - 1.0).abs() < 0.01, "{tm} vs {want}");
}

/// FMU state: a state saved mid-run and restored gives the same continuation bit for bit,
/// in memory, serialized into the same instance and into a fresh one.
#[test]
fn state_restore_repeats_bit_for_bit() {
    let mut rt = start(&[]);
    let run = |rt: &mut Runtime<Edu>, k0: usize| -> Vec<u64> {
        let mut out = Vec::new();
        for k in k0..k0 + 500 {
            let t = k as f64 * DT;
            set(rt, "accel_pedal", (t * 4.0).sin());
            set(rt, "omega_left", 150.0 + (t * 30.0).sin());
            set(rt, "omega_right", 152.0);
            assert_eq!(rt.do_step(t, DT), fmi2Status::OK);
            for n in [
                "torque_left",
                "motor_speed",
                "motor_torque",
                "electric_power",
                "shaft_twist_left",
            ] {
                out.push(get(rt, n).to_bits());
            }
        }
        out
    };
    run(&mut rt, 0);
    let snap = rt.snapshot().ok().unwrap();
    let bytes = rt.serialize(&snap);
    let first = run(&mut rt, 500);
    assert_eq!(rt.restore(&snap), fmi2Status::OK);
    assert_eq!(run(&mut rt, 500), first);
    let back = rt.deserialize(&bytes).ok().unwrap();
    assert_eq!(rt.restore(&back), fmi2Status::OK);
    assert_eq!(run(&mut rt, 500), first);
    // Into a fresh instance, which initialises its model from the saved parameters.
    let mut other = start(&[]);
    let back = other.deserialize(&bytes).ok().unwrap();
    assert_eq!(other.restore(&back), fmi2Status::OK);
    assert_eq!(run(&mut other, 500), first);
}

/// Out-of-range parameters are refused, naming the variable.
#[test]
fn bad_parameters_are_refused_naming_the_variable() {
    for (n, x) in [
        ("motor_inertia", -0.01),
        ("gear_ratio", 0.0),
        ("gearbox_efficiency", 1.2),
        ("motor_efficiency", 0.0),
        ("shaft_stiffness", -1.0),
        ("torque_max", -150.0),
    ] {
        let cap = Capture::default();
        let mut rt = Runtime::<Edu>::new("edu", None, cap.boxed(), true);
        assert_eq!(rt.set_by_name(n, Value::Real(x)), fmi2Status::ERROR, "{n}");
        assert!(cap.text().contains(&format!("'{n}'")));
    }
}
