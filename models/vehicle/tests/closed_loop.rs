//! The vehicle and the reference EDU in a closed loop through two rear-wheel inertias
//! integrated here (a stand-in for the dynos), both models through `fmu_export::Runtime`,
//! at the bench's 1 ms macro step.

mod common;

use common::*;
use edu::Edu;
use fmu_export::fmi2::fmi2Status;
use fmu_export::Runtime;
use vehicle::Vehicle;

const DT: f64 = 1e-3;
const R: f64 = 0.345;
const J_WHEEL: f64 = 0.8;

/// A rear wheel on a dyno-like plant: J·dω/dt = shaft − applied, the applied torque following
/// the held setpoint through a dead time and a first-order lag `tau` (0: none), integrated in
/// 0.1 ms sub-steps like a dyno model would.
struct Wheel {
    omega: f64,
    /// Setpoints of the last sub-steps, oldest first (length: dead time in sub-steps).
    queue: std::collections::VecDeque<f64>,
    applied: f64,
    tau: f64,
}

const SUB: usize = 10;

impl Wheel {
    fn new(omega: f64, dead_time: f64, tau: f64, torque0: f64) -> Wheel {
        let n = (dead_time / (DT / SUB as f64)).round() as usize;
        Wheel {
            omega,
            queue: vec![torque0; n].into(),
            applied: torque0,
            tau,
        }
    }
    fn step(&mut self, shaft: f64, setpoint: f64) {
        let h = DT / SUB as f64;
        for _ in 0..SUB {
            self.queue.push_back(setpoint);
            let target = self.queue.pop_front().unwrap();
            self.applied = if self.tau > 0.0 {
                target + (self.applied - target) * (-h / self.tau).exp()
            } else {
                target
            };
            self.omega += h * (shaft - self.applied) / J_WHEEL;
        }
    }
}

struct Bench {
    car: Runtime<Vehicle>,
    edu: Runtime<Edu>,
    wheels: [Wheel; 2],
    t: f64,
}

impl Bench {
    fn new(v0: f64, dead_time: f64, tau: f64) -> Bench {
        let dir = temp_resources(
            &format!("loop{}", (v0 * 1e3 + dead_time * 1e7) as u64),
            &uniform_track(2000.0, 0.0),
        );
        let (mut car, _) =
            runtime::<Vehicle>(Some(dir.path().to_path_buf()), &[("v_start", r(v0))]);
        let w0 = v0 / R;
        set(&mut car, "omega_rl", w0);
        set(&mut car, "omega_rr", w0);
        assert_eq!(car.exit_initialization_mode(), fmi2Status::OK);
        let (mut edu, _) = runtime::<Edu>(None, &[("omega_wheel_start", r(w0))]);
        set(&mut edu, "omega_left", w0);
        set(&mut edu, "omega_right", w0);
        assert_eq!(edu.exit_initialization_mode(), fmi2Status::OK);
        let wheels = [
            Wheel::new(w0, dead_time, tau, 0.0),
            Wheel::new(w0, dead_time, tau, 0.0),
        ];
        Bench {
            car,
            edu,
            wheels,
            t: 0.0,
        }
    }

    /// One macro step; returns (shaft torque left, setpoint left).
    fn step(&mut self, pedal: f64, brake: f64) -> (f64, f64) {
        let (wl, wr) = (self.wheels[0].omega, self.wheels[1].omega);
        set(&mut self.car, "omega_rl", wl);
        set(&mut self.car, "omega_rr", wr);
        set(&mut self.car, "brake_pedal", brake);
        set(&mut self.edu, "omega_left", wl);
        set(&mut self.edu, "omega_right", wr);
        set(&mut self.edu, "accel_pedal", pedal);
        let shaft = [
            get(&mut self.edu, "torque_left"),
            get(&mut self.edu, "torque_right"),
        ];
        let setp = [
            get(&mut self.car, "torque_setpoint_rl"),
            get(&mut self.car, "torque_setpoint_rr"),
        ];
        assert_eq!(self.car.do_step(self.t, DT), fmi2Status::OK);
        assert_eq!(self.edu.do_step(self.t, DT), fmi2Status::OK);
        for i in 0..2 {
            self.wheels[i].step(shaft[i], setp[i]);
        }
        self.t += DT;
        (shaft[0], setp[0])
    }
}

/// Resistance of the nominal car on a flat road [N].
fn resistance(v: f64) -> f64 {
    let fz = 880.0 * 9.81 + 0.5 * (1.653 + 2.027) * 1.5 * 1.18 * v * v;
    0.5 * 1.18 * 0.767 * 1.5 * v * v + 0.02 * fz
}

/// Full power from 40 m/s: the car settles where drive force equals resistance. Tolerances:
/// ΣF_x = F_resistance within 0.5% at the end; the speed within 1% of the speed where the
/// gearbox output power (power_max·η_g) equals resistance × speed (tyre slip losses, under 1%,
/// are the difference); and within 0.1% of that balance when the measured slip is included.
#[test]
fn full_power_reaches_the_speed_where_drive_force_equals_resistance() {
    let mut b = Bench::new(40.0, 0.0, 0.0);
    for _ in 0..80_000 {
        b.step(1.0, 0.0);
    }
    let car = &mut b.car;
    let v = get(car, "v");
    let fx: f64 = ["Fx_fl", "Fx_fr", "Fx_rl", "Fx_rr"]
        .iter()
        .map(|n| get(car, n))
        .sum();
    let res = get(car, "F_resistance");
    let slip = 0.5 * (get(car, "slip_rl") + get(car, "slip_rr"));
    let p_wheel = 200_000.0 * 0.96;
    // Bisection on P = R(v)·v·(1 + slip) (slip 0: the idealised balance).
    let balance = |slip: f64| {
        let (mut lo, mut hi) = (1.0, 200.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if resistance(mid) * mid * (1.0 + slip) < p_wheel {
                lo = mid
            } else {
                hi = mid
            }
        }
        lo
    };
    let (v_ideal, v_slip) = (balance(0.0), balance(slip));
    println!(
        "full power: v {v:.3} m/s; ideal balance {v_ideal:.3} ({:+.2}%), with slip {slip:.4}: {v_slip:.3} ({:+.3}%); ΣFx {fx:.1} N vs resistance {res:.1} N",
        (v / v_ideal - 1.0) * 100.0,
        (v / v_slip - 1.0) * 100.0
    );
    assert!((fx / res - 1.0).abs() < 5e-3);
    assert!((v / v_ideal - 1.0).abs() < 0.01);
    assert!((v / v_slip - 1.0).abs() < 1e-3);
    assert!(
        (get(&mut b.edu, "motor_torque") * get(&mut b.edu, "motor_speed") / 200_000.0 - 1.0).abs()
            < 1e-6
    );
}

/// Ripple of `x`: peak-to-peak of its deviation from a centred 51 ms moving average (slow
/// trends such as the power limit coming in are not ripple; the wheel/tyre/dyno modes at
/// 10–50 Hz are).
fn ripple(x: &[f64]) -> f64 {
    let w = 25;
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for i in w..x.len() - w {
        let mean = x[i - w..=i + w].iter().sum::<f64>() / (2 * w + 1) as f64;
        lo = lo.min(x[i] - mean);
        hi = hi.max(x[i] - mean);
    }
    hi - lo
}

/// Stability at 1 ms: a pedal step to half torque at 0.1 s and a brake pulse at 1 s, from 5,
/// 10, 20 and 50 m/s, on an ideal plant and on a dyno-like one (0.5 ms dead time, 1 ms lag,
/// docs/bench.md's clean case). The rear setpoint's ripple (around its trend) over the last 0.5 s of
/// 2 s stays below 2 N·m. Longer dead times are printed, not asserted: that ringing is the
/// bench effect the paper studies (2 ms: ripple up to ~15 N·m; 5 ms: a limit cycle bounded
/// by the tyre friction, kN·m; dead-time compensation belongs to the dyno).
#[test]
fn loop_is_stable_at_1ms() {
    for (dead, tau, check) in [
        (0.0, 0.0, true),
        (5e-4, 1e-3, true),
        (2e-3, 1e-3, false),
        (5e-3, 1e-3, false),
    ] {
        for v0 in [5.0, 10.0, 20.0, 50.0] {
            let mut b = Bench::new(v0, dead, tau);
            let mut tail = Vec::new();
            let mut settle = Vec::new();
            for k in 0..2000 {
                let pedal = if k >= 100 { 0.5 } else { 0.0 };
                let brake = if (1000..1100).contains(&k) { 0.3 } else { 0.0 };
                let (_, sp) = b.step(pedal, brake);
                if (500..1000).contains(&k) {
                    settle.push(sp);
                }
                if k >= 1500 {
                    tail.push(sp);
                }
            }
            let (r1, r2) = (ripple(&settle), ripple(&tail));
            println!(
                "dead time {:.1} ms, lag {:.1} ms, v0 {v0:>2} m/s: setpoint ripple {r1:.3} N.m (0.5-1 s), {r2:.3} N.m (1.5-2 s), v end {:.2} m/s",
                dead * 1e3,
                tau * 1e3,
                get(&mut b.car, "v")
            );
            if check {
                assert!(r2 < 2.0);
            }
        }
    }
}

/// The default study end to end: the Spielberg lap (bundled track, road excitation on, default
/// parameters) driven by a simple test driver that follows the measured speed over distance
/// (30 ms preview, feed-forward, PI). Tolerances: lap time within 1.5% of the measurement's
/// 97.49 s, RMS speed error below 3 km/h, peak braking beyond −20 m/s², no wheel locking
/// (rear slip above −0.2) and no step failure.
#[test]
fn drives_the_spielberg_lap() {
    // A longer preview makes this driver brake early: the feed-forward already anticipates.
    const PREVIEW: f64 = 0.03;
    let csv = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../data/spielberg_lap.csv"
    ))
    .unwrap();
    let (mut dist, mut speed) = (Vec::new(), Vec::new());
    for line in csv.lines().skip(1) {
        let f: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        if !dist.last().is_some_and(|&d| f[1] <= d) {
            dist.push(f[1]);
            speed.push(f[2]);
        }
    }
    let target = |s: f64| -> f64 {
        let i = dist.partition_point(|&d| d <= s).clamp(1, dist.len() - 1);
        let t = ((s - dist[i - 1]) / (dist[i] - dist[i - 1])).clamp(0.0, 1.0);
        speed[i - 1] + t * (speed[i] - speed[i - 1])
    };
    let (mut car, _) = runtime::<Vehicle>(Some(bundled_resources()), &[("v_start", r(speed[0]))]);
    let w0 = speed[0] / R;
    set(&mut car, "omega_rl", w0);
    set(&mut car, "omega_rr", w0);
    assert_eq!(car.exit_initialization_mode(), fmi2Status::OK);
    let (mut edu, _) = runtime::<Edu>(None, &[("omega_wheel_start", r(w0))]);
    assert_eq!(edu.exit_initialization_mode(), fmi2Status::OK);
    let mut b = Bench {
        car,
        edu,
        wheels: [Wheel::new(w0, 0.0, 0.0, 0.0), Wheel::new(w0, 0.0, 0.0, 0.0)],
        t: 0.0,
    };
    let (m, integral_gain, kp) = (880.0, 1.0, 4.0);
    let mut integral = 0.0;
    let (mut sq, mut n, mut min_ax, mut min_slip): (f64, usize, f64, f64) = (0.0, 0, 0.0, 0.0);
    while get(&mut b.car, "lap") < 1.0 && b.t < 120.0 {
        let v = get(&mut b.car, "v");
        let s = get(&mut b.car, "distance");
        let ahead = s + PREVIEW * v;
        let vt = target(ahead);
        let ff = v * (target(ahead + 1.0) - target(ahead - 1.0)) / 2.0;
        let err = vt - v;
        let force = m * (ff + kp * err + integral) + get(&mut b.car, "F_resistance");
        let drive_max = (150.0 * 17.86 * 0.96 / R).min(200_000.0 * 0.96 / v.max(1.0));
        let (pedal, brake) = if force >= 0.0 {
            ((force / drive_max).min(1.0), 0.0)
        } else {
            (0.0, (-force / 22_000.0).min(1.0))
        };
        // Anti-windup: integrate only while the pedals are not saturated.
        if pedal < 1.0 && brake < 1.0 {
            integral += integral_gain * err * DT;
        }
        b.step(pedal, brake);
        let v_now = get(&mut b.car, "v");
        sq += (target(get(&mut b.car, "distance")) - v_now).powi(2);
        n += 1;
        min_ax = min_ax.min(get(&mut b.car, "a_x"));
        min_slip = min_slip
            .min(get(&mut b.car, "slip_rl"))
            .min(get(&mut b.car, "slip_rr"));
    }
    let lap_time = get(&mut b.car, "lap_time");
    let rms_kmh = (sq / n as f64).sqrt() * 3.6;
    println!(
        "Spielberg lap: {lap_time:.2} s (measured 97.49 s), RMS speed error {rms_kmh:.2} km/h, min a_x {min_ax:.1} m/s2, min rear slip {min_slip:.3}"
    );
    assert!((lap_time / 97.49 - 1.0).abs() < 0.015);
    assert!(rms_kmh < 3.0);
    assert!(min_ax < -20.0);
    assert!(min_slip > -0.2);
}
