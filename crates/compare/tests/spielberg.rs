//! The bundled Spielberg measurement (`data/spielberg_lap.csv`, repository root).

use std::path::PathBuf;
use tb_compare::{
    CompareSettings, DistanceSource, Error, Measurement, PreparedMeasurement, Table, Workspace,
};
use tb_table::TableError;

fn lap_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/spielberg_lap.csv")
}

const LOADS: [&str; 4] = ["Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"];

/// A "simulation" table made from the measurement's own columns, with `f(name, v, load)`
/// applied to each wheel load.
fn sim_from(meas: &Measurement, f: impl Fn(&str, f64, f64) -> f64) -> Table {
    let t = meas.table();
    let v = meas.require("v").unwrap();
    let mut names = vec!["time".to_string(), "vehicle.distance".to_string()];
    let mut cols = vec![meas.time().to_vec(), meas.distance().to_vec()];
    for l in LOADS {
        names.push(format!("vehicle.{l}"));
        cols.push(
            t.require(l)
                .unwrap()
                .iter()
                .zip(v)
                .map(|(&x, &v)| f(l, v, x))
                .collect(),
        );
    }
    Table::from_columns("sim", names, cols).unwrap()
}

#[test]
fn loads_and_compares_with_itself() {
    let meas = Measurement::read_path(lap_path()).unwrap();
    assert_eq!(meas.distance_source(), DistanceSource::Column);
    assert_eq!(meas.time().len(), 19498);
    let signals = [
        "Fz_sum", "Fz_front", "Fz_rear", "Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr",
    ];
    let settings = CompareSettings::default();
    let prepared = PreparedMeasurement::new(&meas, &signals, &settings).unwrap();
    assert!((prepared.sample_rate_hz() - 200.0).abs() < 1e-6);
    let mut ws = Workspace::new();
    let cmp = prepared
        .compare(&sim_from(&meas, |_, _, x| x), &mut ws)
        .unwrap();
    assert!((cmp.coverage - 1.0).abs() < 1e-12);
    for s in &cmp.signals {
        let m = &s.metrics;
        // Identical data through identical arithmetic: exact up to rounding (1e-12).
        assert!(m.e.abs() < 1e-12, "{}: e = {:e}", s.signal, m.e);
        assert!(
            (m.slope - 1.0).abs() < 1e-12,
            "{}: m = {}",
            s.signal,
            m.slope
        );
        assert!(m.bias.abs() < 1e-12 && m.rms < 1e-9, "{}: {m:?}", s.signal);
    }
    // Also the measurement's own table as the "simulation" (plain names, `distance`).
    let cmp = prepared.compare(meas.table(), &mut ws).unwrap();
    assert!(cmp.get("Fz_sum").unwrap().e.abs() < 1e-12);
}

/// Lift too high (the bench's initial c_lift twice the truth, README): extra downforce
/// grows with v², so the simulated Fz_sum swings more than the measured: m > 1.
/// A pure offset is invisible to e (m = 1, R² = 1) but not to the bias.
#[test]
fn lift_too_high_and_offset() {
    let meas = Measurement::read_path(lap_path()).unwrap();
    let settings = CompareSettings::default();
    let prepared = PreparedMeasurement::new(&meas, &["Fz_sum", "Fz_rear"], &settings).unwrap();
    let mut ws = Workspace::new();

    // Half of (1.653 + 2.027) extra lift coefficient, A = 1.5 m², rho = 1.18, split
    // evenly over the wheels.
    let dc = 0.5 * (1.653 + 2.027);
    let extra = |v: f64| 0.5 * dc * 1.5 * 1.18 * v * v / 4.0;
    let cmp = prepared
        .compare(&sim_from(&meas, |_, v, x| x + extra(v)), &mut ws)
        .unwrap();
    let m = cmp.get("Fz_sum").unwrap();
    println!("lift too high: {m:?}");
    assert!(m.slope > 1.2, "m = {} should exceed 1", m.slope);
    assert!(m.e > 0.1 && m.bias > 0.05, "{m:?}");
    assert!(cmp.get("Fz_rear").unwrap().slope > 1.0);

    // Lift too low: m < 1.
    let cmp = prepared
        .compare(&sim_from(&meas, |_, v, x| x - 0.5 * extra(v)), &mut ws)
        .unwrap();
    assert!(cmp.get("Fz_sum").unwrap().slope < 0.95);

    // 100 N per wheel.
    let cmp = prepared
        .compare(&sim_from(&meas, |_, _, x| x + 100.0), &mut ws)
        .unwrap();
    let m = cmp.get("Fz_sum").unwrap();
    let mean = prepared.measured("Fz_sum").unwrap().iter().sum::<f64>()
        / prepared.measured("Fz_sum").unwrap().len() as f64;
    assert!(m.e.abs() < 1e-9, "e blind to an offset: {m:?}");
    assert!((m.bias - 400.0 / mean).abs() < 1e-9, "bias {m:?}");
    assert!((m.rms - 400.0).abs() < 1e-6 && (m.intercept - 400.0).abs() < 1e-6);
}

/// A simulation at another sample rate (1 kHz, linear interpolation of the measurement in
/// time, distance integrated from v) compares with e < 1e-3: the pipeline is consistent
/// across sample rates and distance sources.
#[test]
fn other_sample_rate_and_integrated_distance() {
    let meas = Measurement::read_path(lap_path()).unwrap();
    let settings = CompareSettings::default();
    let prepared = PreparedMeasurement::new(&meas, &["Fz_sum", "Fz_rl"], &settings).unwrap();
    let t = meas.time();
    let n = ((t[t.len() - 1] - t[0]) / 1e-3).floor() as usize + 1;
    let ts: Vec<f64> = (0..n).map(|i| t[0] + i as f64 * 1e-3).collect();
    let mut names = vec!["time".to_string(), "vehicle.v".to_string()];
    let mut cols = vec![
        ts.clone(),
        tb_compare::resample::interp(t, meas.require("v").unwrap(), &ts),
    ];
    for l in LOADS {
        names.push(format!("vehicle.{l}"));
        cols.push(tb_compare::resample::interp(
            t,
            meas.require(l).unwrap(),
            &ts,
        ));
    }
    let sim = Table::from_columns("sim1k", names, cols).unwrap();
    let started = std::time::Instant::now();
    let mut ws = Workspace::new();
    let cmp = prepared.compare(&sim, &mut ws).unwrap();
    let first = started.elapsed();
    let started = std::time::Instant::now();
    let reps = 20;
    for _ in 0..reps {
        prepared.compare(&sim, &mut ws).unwrap();
    }
    println!(
        "{n} samples, 2 signals: first {:?}, then {:?} per comparison; {cmp:?}",
        first,
        started.elapsed() / reps
    );
    for s in &cmp.signals {
        assert!(s.metrics.e < 1e-3, "{}: {:?}", s.signal, s.metrics);
    }
    assert!(cmp.coverage > 0.99);
}

#[test]
fn short_or_nonuniform_simulation_is_an_error() {
    let meas = Measurement::read_path(lap_path()).unwrap();
    let prepared =
        PreparedMeasurement::new(&meas, &["Fz_sum"], &CompareSettings::default()).unwrap();
    let mut ws = Workspace::new();
    // Only the first half of the lap.
    let full = sim_from(&meas, |_, _, x| x);
    let half = meas.time().len() / 2;
    let names = full.names().to_vec();
    let cols = (0..names.len())
        .map(|i| full.column_at(i)[..half].to_vec())
        .collect();
    let sim = Table::from_columns("half.csv", names.clone(), cols).unwrap();
    let e = prepared.compare(&sim, &mut ws).unwrap_err();
    assert!(
        matches!(&e, Error::InsufficientOverlap { file, coverage, min_coverage, .. }
            if file == "half.csv" && coverage < min_coverage),
        "{e}"
    );

    // A jump in the time base between index 999 and 1000 (line 1002 for in-memory tables).
    let mut cols: Vec<Vec<f64>> = (0..names.len())
        .map(|i| full.column_at(i).to_vec())
        .collect();
    for t in &mut cols[0][1000..] {
        *t += 0.5;
    }
    let sim = Table::from_columns("gap.csv", names.clone(), cols).unwrap();
    let e = prepared.compare(&sim, &mut ws).unwrap_err();
    assert!(
        matches!(&e, Error::NonUniformSampling { file, row: 1002, column, .. }
            if file == "gap.csv" && column == "time"),
        "{e}"
    );

    // NaN in a simulated load: line = index + 2 for an in-memory table.
    let mut cols: Vec<Vec<f64>> = (0..names.len())
        .map(|i| full.column_at(i).to_vec())
        .collect();
    cols[4][500] = f64::NAN;
    let sim = Table::from_columns("nan.csv", names, cols).unwrap();
    let e = prepared.compare(&sim, &mut ws).unwrap_err();
    assert!(
        matches!(&e, Error::Table(TableError::NonFinite { file, row: 502, column, value })
            if file == "nan.csv" && column == "vehicle.Fz_rl" && value.is_nan()),
        "{e}"
    );
}

#[test]
fn settings_from_toml() {
    let s: CompareSettings = toml::from_str("cutoff_hz = 3\nfilter_order = 4\n").unwrap();
    assert_eq!(s.cutoff_hz, 3.0);
    assert_eq!(s.filter_order, 4);
    assert_eq!(s.distance_step_m, 1.0);
    assert!(toml::from_str::<CompareSettings>("cutof_hz = 3\n").is_err());
    let bad = CompareSettings {
        cutoff_hz: 150.0,
        ..CompareSettings::default()
    };
    let meas = Measurement::read_path(lap_path()).unwrap();
    let e = PreparedMeasurement::new(&meas, &["Fz_sum"], &bad).unwrap_err();
    assert!(matches!(e, Error::Settings(_)), "{e}");
    // Why 150 Hz cannot be: the limit it is above.
    assert!(e.to_string().contains("half the sample rate"), "{e}");
}
