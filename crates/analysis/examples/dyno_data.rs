//! Test data for `twinbench identify`: runs the dyno model natively through the FMI runtime
//! (torque control, defaults: dead time 0.5 ms, time constant 1 ms, cycle 0.1 ms; here with
//! ±20 µs jitter) and writes, sampled at the 0.1 ms controller cycle, with 5 N·m of
//! Gaussian noise added to the torque outputs:
//!
//! - `dyno_step.csv`: a 100 → 600 N·m setpoint step at 20 ms, 60 ms long;
//! - `dyno_noise.csv`: white-noise setpoint (200 ± 100 N·m), 6.5 s;
//! - `dyno_sweep.csv`: logarithmic sine sweep 5 Hz – 4 kHz (200 ± 100 N·m), 6.5 s.
//!
//! `cargo run --release -p tb-analysis --example dyno_data -- OUT_DIR`

use dyno::Dyno;
use fmu_export::{NullLogger, Runtime, Value};
use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::PathBuf;

use tb_testkit::Noise;

fn run(h: f64, n: usize, setpoint: &dyn Fn(usize) -> f64) -> String {
    let mut rt = Runtime::<Dyno>::new("dyno_rl", None, Box::new(NullLogger), false);
    for (name, v) in [
        ("jitter", 2e-5),
        ("torque_setpoint", setpoint(0)),
        ("shaft_torque", setpoint(0)),
    ] {
        assert_eq!(rt.set_by_name(name, Value::Real(v)).0, 0, "{name}");
    }
    rt.setup_experiment(0.0, None);
    rt.enter_initialization_mode();
    assert_eq!(rt.exit_initialization_mode().0, 0);
    let mut noise = Noise::new(2024);
    let mut out = String::from("time,torque_setpoint,torque_dyno,torque_measured,omega\n");
    for k in 0..n {
        let t = k as f64 * h;
        let get = |rt: &mut Runtime<Dyno>, v: &str| rt.get_by_name(v).unwrap().as_f64();
        let (td, tm, w) = (
            get(&mut rt, "torque_dyno"),
            get(&mut rt, "torque_measured"),
            get(&mut rt, "omega"),
        );
        let u = setpoint(k);
        rt.set_by_name("torque_setpoint", Value::Real(u));
        let _ = writeln!(
            out,
            "{t:.6},{u:.6},{:.6},{:.6},{w:.6}",
            td + 5.0 * noise.gauss(),
            tm + 5.0 * noise.gauss()
        );
        assert_eq!(rt.do_step(t, h).0, 0);
    }
    out
}

fn main() {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| ".".into()));
    std::fs::create_dir_all(&dir).expect("output directory");
    let h = 1e-4;
    let n = 1 << 16;
    let step = |k: usize| if k < 200 { 100.0 } else { 600.0 };
    let mut g = Noise::new(3);
    let white: Vec<f64> = (0..n).map(|_| 200.0 + 100.0 * g.gauss()).collect();
    let (f0, f1, dur) = (5.0_f64, 4000.0_f64, n as f64 * h);
    let k_rate = (f1 / f0).ln() / dur;
    let sweep = |k: usize| {
        let t = k as f64 * h;
        200.0 + 100.0 * (2.0 * PI * f0 * ((k_rate * t).exp() - 1.0) / k_rate).sin()
    };
    for (name, data) in [
        ("dyno_step.csv", run(h, 600, &step)),
        ("dyno_noise.csv", run(h, n, &|k| white[k])),
        ("dyno_sweep.csv", run(h, n, &sweep)),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, data).expect("write csv");
        println!("wrote {}", path.display());
    }
}
