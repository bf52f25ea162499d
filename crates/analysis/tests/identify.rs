//! Identification of the dyno loop on data produced by the dyno model itself (run natively
//! through the FMI runtime), with its controller cycle, dead time, jitter and added
//! measurement noise; and the group delay of a pure delay.

use dyno::Dyno;
use fmu_export::{NullLogger, Runtime, Value};
use std::f64::consts::PI;
use tb_analysis::fit::{self, FitConfig, LagOrder, Sampling};
use tb_analysis::frf::{self, WelchConfig};
use tb_analysis::signal::TimeSeries;
use tb_analysis::step::{self, StepConfig};
use tb_analysis::{AnalysisError, Complex64};
use tb_testkit::assert_contains;

use tb_testkit::Noise;

struct Bench {
    dead_time: f64,
    time_constant: f64,
    cycle_time: f64,
    jitter: f64,
    lag_order: i32,
    damping: f64,
}

impl Bench {
    fn first_order(dead_time: f64, time_constant: f64, cycle_time: f64, jitter: f64) -> Self {
        Bench {
            dead_time,
            time_constant,
            cycle_time,
            jitter,
            lag_order: 1,
            damping: 0.7,
        }
    }

    /// Drive the dyno with `setpoint(k)` at sampling step `h`; record (t, setpoint,
    /// torque_dyno + noise) at each communication point, the output read before the
    /// step that starts there (the value at t).
    fn run(&self, h: f64, n: usize, noise_std: f64, setpoint: impl Fn(usize) -> f64) -> TimeSeries {
        let mut rt = Runtime::<Dyno>::new("dyno_rl", None, Box::new(NullLogger), false);
        let reals = [
            ("dead_time", self.dead_time),
            ("time_constant", self.time_constant),
            ("cycle_time", self.cycle_time),
            ("jitter", self.jitter),
            ("damping", self.damping),
            ("torque_setpoint", setpoint(0)),
            ("shaft_torque", setpoint(0)),
        ];
        for (name, v) in reals {
            assert_eq!(rt.set_by_name(name, Value::Real(v)).0, 0, "{name}");
        }
        assert_eq!(
            rt.set_by_name("lag_order", Value::Integer(self.lag_order))
                .0,
            0
        );
        assert_eq!(rt.set_by_name("jitter_seed", Value::Integer(7)).0, 0);
        rt.setup_experiment(0.0, None);
        rt.enter_initialization_mode();
        assert_eq!(rt.exit_initialization_mode().0, 0);
        let mut noise = Noise::new(42);
        let (mut t, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..n {
            let tk = k as f64 * h;
            let yk = rt.get_by_name("torque_dyno").unwrap().as_f64();
            let uk = setpoint(k);
            rt.set_by_name("torque_setpoint", Value::Real(uk));
            t.push(tk);
            u.push(uk);
            y.push(yk + noise_std * noise.gauss());
            assert_eq!(rt.do_step(tk, h).0, 0);
        }
        TimeSeries::from_columns(
            "dyno",
            t,
            vec![("torque_setpoint".into(), u), ("torque_dyno".into(), y)],
        )
        .unwrap()
    }
}

fn sampling_name(s: Sampling) -> &'static str {
    match s {
        Sampling::Continuous => "continuous",
        Sampling::HeldInput => "held",
        Sampling::DynoCycle { .. } => "dyno cycle",
    }
}

fn white_setpoint(seed: u64, n: usize) -> Vec<f64> {
    let mut g = Noise::new(seed);
    (0..n).map(|_| 200.0 + 100.0 * g.gauss()).collect()
}

fn frf_fit(
    bench: &Bench,
    h: f64,
    noise_std: f64,
    order: LagOrder,
    sampling: Sampling,
) -> fit::FrfFit {
    let n = 1 << 16;
    let sp = white_setpoint(3, n);
    let ts = bench.run(h, n, noise_std, |k| sp[k]);
    let u = ts.column("torque_setpoint").unwrap();
    let y = ts.column("torque_dyno").unwrap();
    let frf = frf::h1(u, y, ts.fs(), &WelchConfig::new(1024), "dyno").unwrap();
    let cfg = FitConfig {
        order,
        f_max: 0.4 * ts.fs(),
        sampling,
        ..FitConfig::default()
    };
    fit::fit(&frf, &cfg).unwrap()
}

#[test]
fn frf_fit_recovers_dyno_dead_time_and_time_constant() {
    let h = 1e-4; // 10 kHz logging = the dyno's controller cycle
    for (td, tau, jitter, noise, continuous_ok) in [
        (5e-4, 1e-3, 0.0, 5.0, true), // defaults, 5 N·m noise on a 100 N·m excitation
        (5e-4, 1e-3, 5e-5, 10.0, true), // with ±50 µs jitter and 10 N·m noise
        (1.2e-3, 2.5e-3, 2e-5, 5.0, true),
        // 2.35 cycles dead time (interpolated by the dyno), lag of 6 cycles: only the
        // sampled model describes this well
        (2.35e-4, 6e-4, 0.0, 5.0, false),
    ] {
        let bench = Bench::first_order(td, tau, h, jitter);
        for sampling in [
            Sampling::Continuous,
            Sampling::HeldInput,
            Sampling::DynoCycle { cycle_time: h },
        ] {
            if sampling != (Sampling::DynoCycle { cycle_time: h }) && !continuous_ok {
                continue;
            }
            let f = frf_fit(&bench, h, noise, LagOrder::First, sampling);
            let tc = f.time_constant.unwrap();
            eprintln!(
                "{:<10} model: truth T_d {:.3} ms, T {:.3} ms, jitter ±{:.3} ms, noise {noise} N·m -> T_d {:.4} ms ({:+.2} samples), T {:.4} ms ({:+.2} %), K {:.4}",
                sampling_name(sampling),
                td * 1e3,
                tau * 1e3,
                jitter * 1e3,
                f.dead_time * 1e3,
                (f.dead_time - td) / h,
                tc * 1e3,
                (tc / tau - 1.0) * 100.0,
                f.gain
            );
            assert!(
                (f.dead_time - td).abs() <= h,
                "dead time {} vs {td}",
                f.dead_time
            );
            assert!(
                (tc / tau - 1.0).abs() <= 0.05,
                "time constant {tc} vs {tau}"
            );
            assert!((f.gain - 1.0).abs() < 0.03, "gain {}", f.gain);
            let snippet = f.parameters_toml("dyno_rl");
            let doc: toml::Table = toml::from_str(&snippet).unwrap();
            let p = doc["parameters"].as_table().unwrap();
            let written = |k: &str| p[k].as_float().unwrap();
            assert!((written("dyno_rl.dead_time") / f.dead_time - 1.0).abs() < 1e-3);
            assert!((written("dyno_rl.time_constant") / tc - 1.0).abs() < 1e-3);
            assert_eq!(p["dyno_rl.lag_order"].as_integer(), Some(1));
        }
    }
}

#[test]
fn sampled_fit_needs_data_at_the_cycle() {
    let bench = Bench::first_order(5e-4, 1e-3, 1e-4, 0.0);
    let sp = white_setpoint(3, 8192);
    let ts = bench.run(2e-4, 8192, 0.0, |k| sp[k]);
    let frf = frf::h1(
        ts.column("torque_setpoint").unwrap(),
        ts.column("torque_dyno").unwrap(),
        ts.fs(),
        &WelchConfig::new(512),
        "dyno",
    )
    .unwrap();
    let cfg = FitConfig {
        sampling: Sampling::DynoCycle { cycle_time: 1e-4 },
        ..FitConfig::default()
    };
    let e = fit::fit(&frf, &cfg).unwrap_err();
    assert!(matches!(e, AnalysisError::Fit(_)), "{e}");
    assert_contains(&e.to_string(), &["sampled at the controller cycle"]);
    // the held-input model is exact here (the input changes only at ticks)
    let f = fit::fit(
        &frf,
        &FitConfig {
            sampling: Sampling::HeldInput,
            ..FitConfig::default()
        },
    )
    .unwrap();
    eprintln!(
        "5 kHz data, 10 kHz cycle, held input: T_d {:.4} ms, T {:.4} ms",
        f.dead_time * 1e3,
        f.time_constant.unwrap() * 1e3
    );
    assert!((f.dead_time - 5e-4).abs() <= 0.1 * 2e-4);
    assert!((f.time_constant.unwrap() / 1e-3 - 1.0).abs() <= 0.01);
}

#[test]
fn frf_fit_second_order_lag() {
    let h = 1e-4;
    let bench = Bench {
        dead_time: 5e-4,
        time_constant: 5e-4, // ω_n = 2000 rad/s
        cycle_time: h,
        jitter: 0.0,
        lag_order: 2,
        damping: 0.5,
    };
    for sampling in [
        Sampling::Continuous,
        Sampling::HeldInput,
        Sampling::DynoCycle { cycle_time: h },
    ] {
        let f = frf_fit(&bench, h, 5.0, LagOrder::Second, sampling);
        let wn = f.natural_frequency.unwrap();
        let z = f.damping_ratio.unwrap();
        eprintln!(
            "second order ({}): truth T_d 0.5 ms, ω_n 2000 rad/s, ζ 0.5 -> T_d {:.4} ms, ω_n {:.1} rad/s, ζ {:.3}",
            sampling_name(sampling),
            f.dead_time * 1e3,
            wn,
            z
        );
        assert!((f.dead_time - 5e-4).abs() <= h);
        assert!((wn / 2000.0 - 1.0).abs() <= 0.05);
        assert!((z / 0.5 - 1.0).abs() <= 0.1);
        let snippet = f.parameters_toml("dyno_rl");
        assert!(snippet.contains("\"dyno_rl.lag_order\" = 2"), "{snippet}");
        assert!(snippet.contains("\"dyno_rl.damping\" = "), "{snippet}");
    }
}

#[test]
fn step_response_of_the_dyno() {
    let h = 1e-4;
    for (td, tau, jitter, noise) in [(5e-4, 1e-3, 0.0, 2.0), (1e-3, 2e-3, 3e-5, 5.0)] {
        let bench = Bench::first_order(td, tau, h, jitter);
        // 500 N·m step at 20 ms, record 60 ms
        let ts = bench.run(h, 600, noise, |k| if k < 200 { 100.0 } else { 600.0 });
        let r = step::analyse(
            &ts,
            "torque_setpoint",
            "torque_dyno",
            &StepConfig::default(),
        )
        .unwrap();
        eprintln!(
            "step truth T_d {:.2} ms T {:.2} ms: T_d {:.3} ms, fit T_d {:.4} ms T {:.4} ms, rise {:.3} ms (ideal {:.3}), transient {:.3} ms",
            td * 1e3,
            tau * 1e3,
            r.dead_time * 1e3,
            r.fit.dead_time * 1e3,
            r.fit.time_constant * 1e3,
            r.rise_time * 1e3,
            tau * 9f64.ln() * 1e3,
            r.transient_time.unwrap() * 1e3
        );
        assert!((r.t_step - 0.02).abs() < 1e-12);
        assert!(
            (r.dead_time - td).abs() <= h,
            "detected dead time {}",
            r.dead_time
        );
        assert!(
            (r.fit.dead_time - td).abs() <= h,
            "fitted dead time {}",
            r.fit.dead_time
        );
        assert!((r.fit.time_constant / tau - 1.0).abs() <= 0.05);
        assert!((r.rise_time / (tau * 9f64.ln()) - 1.0).abs() <= 0.1);
        // ±2 % settling of a first-order lag: T_d + T·ln 50
        // (noise makes the last exit from the band later; bound it from below exactly and
        // from above loosely)
        let ideal = td + tau * 50f64.ln();
        let tt = r.transient_time.unwrap();
        assert!(tt >= ideal - 2.0 * h, "transient {tt} vs {ideal}");
        if noise < 3.0 {
            assert!(!r.noise_limited);
            assert!(tt <= ideal + 0.6 * tau, "transient {tt} vs {ideal}");
        } else {
            assert!(r.noise_limited);
        }
        assert!(r.response_start >= td - h && r.response_start <= td + 0.1 * tau + 2.0 * h);
    }
}

#[test]
fn group_delay_of_a_pure_delay_is_the_delay() {
    // Exact: H = e^{-jωτ}
    let tau = 7.5e-4;
    let freq: Vec<f64> = (1..400).map(|k| k as f64 * 10.0).collect();
    let h: Vec<Complex64> = freq
        .iter()
        .map(|f| Complex64::from_polar(1.0, -2.0 * PI * f * tau))
        .collect();
    let frf = frf::Frf::from_response(freq, &h);
    for g in &frf.group_delay {
        assert!((g - tau).abs() < 1e-12 * tau.max(1.0), "{g}");
    }
    // Estimated: white noise delayed by 12 samples, through Welch/H1.
    let n = 1 << 15;
    let d = 12;
    let mut g = Noise::new(9);
    let u: Vec<f64> = (0..n).map(|_| g.gauss()).collect();
    let y: Vec<f64> = (0..n)
        .map(|k| if k >= d { u[k - d] } else { 0.0 })
        .collect();
    let fs = 10_000.0;
    let est = frf::h1(&u, &y, fs, &WelchConfig::new(512), "delay").unwrap();
    let mut gd: Vec<f64> = est.group_delay[1..est.group_delay.len() - 1].to_vec();
    gd.sort_by(f64::total_cmp);
    let median = gd[gd.len() / 2];
    assert!(
        (median - d as f64 / fs).abs() < 0.02 / fs,
        "median group delay {median}"
    );
    let worst = gd
        .iter()
        .map(|x| (x - d as f64 / fs).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.2 * d as f64 / fs, "worst {worst}");
    // and the fit calls it a pure dead time
    let f = fit::fit(&est, &FitConfig::default()).unwrap();
    assert!(
        (f.dead_time - d as f64 / fs).abs() < 0.1 / fs,
        "{}",
        f.dead_time
    );
    assert!(f.time_constant.unwrap() < 0.1 / fs);
}

#[test]
fn csv_errors_name_the_cause() {
    let e = TimeSeries::parse_csv(
        "time,u,y\n0,1,2\n0.001,1,2\n0.0025,1,2\n",
        "sweep.csv",
        "time",
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("sweep.csv: uneven sampling: the time step before line 3"),
        "{e}"
    );
    let ts = TimeSeries::parse_csv("time,u,y\n0,1,2\n0.001,1,2\n", "sweep.csv", "time").unwrap();
    let e = ts.column("torque").unwrap_err();
    assert_eq!(
        e.to_string(),
        "sweep.csv: column 'torque' not found (columns: time, u, y)"
    );
    let e = TimeSeries::parse_csv("t,u\n0,1\n0.1,x\n", "a.csv", "t").unwrap_err();
    assert!(
        matches!(&e, AnalysisError::Csv { file, line: 3, .. } if file == "a.csv"),
        "{e}"
    );
    assert_eq!(
        e.to_string(),
        "a.csv, line 3: column 'u': 'x' is not a number"
    );
    let e = TimeSeries::parse_csv("t,u\n0,1\n0.1,1\n", "a.csv", "time").unwrap_err();
    assert!(
        matches!(&e, AnalysisError::MissingColumn { file, column, .. }
            if file == "a.csv" && column == "time"),
        "{e}"
    );
    let e = step::analyse(&ts, "u", "y", &StepConfig::default()).unwrap_err();
    assert!(
        matches!(&e, AnalysisError::NoStep { column, .. } if column == "u"),
        "{e}"
    );
}
