//! Bring your own lap (slow tier): a circuit the suite makes itself, unlike Spielberg, and
//! a "measurement" of it made by the twin with known lift coefficients and geometry. Then
//! `twinbench lap` and `twinbench optimize` on the packed FMUs, as a user would: the known
//! values come back, with and without the circuit's track; the same measurement as MDF 4
//! with a logger's channel names and units gives the same Tab. 1.

mod common;

use common::synthetic::{self, twinbench, TRUTH};

use std::path::{Path, PathBuf};
use std::process::Command;

/// The twin's lap with the true values, as a measurement file (CSV, SI, a units row).
fn measurement(dir: &Path) -> (PathBuf, PathBuf) {
    let circuit = synthetic::own_circuit(dir);
    let lap = synthetic::truth_lap(dir, &circuit, &TRUTH);
    let p = synthetic::measurement(&lap, &dir.join("measurement.csv"), None);
    (p, circuit.track.unwrap())
}

fn optimise(study: &Path) -> serde_json::Value {
    let out_dir = study.parent().unwrap().join("optimize");
    let mut j = synthetic::optimize(study, &out_dir, &["--threads", "2"]);
    j["table1"] =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("table1.json")).unwrap())
            .unwrap();
    j
}

fn final_value(result: &serde_json::Value, name: &str) -> f64 {
    result["parameters_final"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p[0] == name)
        .unwrap_or_else(|| panic!("no {name}"))[1]
        .as_f64()
        .unwrap()
}

fn assert_recovered(result: &serde_json::Value, what: &str) {
    for (name, truth) in TRUTH {
        let got = final_value(result, name);
        let rel = (got / truth - 1.0).abs();
        // Lift coefficients within 5 %, the track widths within 3 %; the wheelbase is seen
        // only through the longitudinal load transfer (weakly: the identifiability report
        // says so), 10 %.
        let bound = match name {
            "vehicle.l" => 0.10,
            n if n.contains("lift") => 0.05,
            _ => 0.03,
        };
        eprintln!(
            "{what}: {name} = {got:.4} (truth {truth}, {:.2} %)",
            100.0 * rel
        );
        assert!(rel < bound, "{what}: {name} = {got} against {truth}");
    }
}

#[test]
fn an_own_lap_recovers_its_lift_coefficients_and_geometry_with_and_without_its_track() {
    let dir = tb_testkit::scratch("own-lap");
    let (meas, track) = measurement(dir.path());
    // With the circuit's track.
    let with = dir.path().join("with_track");
    synthetic::lap(&[&meas], &[&track], &with, &[]);
    assert_recovered(&optimise(&with.join("study.toml")), "with --track");
    // With a track derived from the measurement.
    let derived = dir.path().join("derived_track");
    synthetic::lap(&[&meas], &[], &derived, &[]);
    assert_recovered(&optimise(&derived.join("study.toml")), "derived track");
}

#[test]
fn the_same_lap_as_mdf4_with_a_loggers_names_and_units_gives_the_same_table_1() {
    let dir = tb_testkit::scratch("own-lap-mdf");
    let (meas, track) = measurement(dir.path());
    // A logger's file: other channel names, km/h, g and kN; and the same values converted
    // back to SI the way twinbench converts them, as CSV.
    let mf4 = dir.path().join("logger.mf4");
    let si = dir.path().join("logger_si.csv");
    let script = r#"
import csv, sys
import numpy as np
from asammdf import MDF, Signal
src, mf4, si = sys.argv[1:4]
rows = list(csv.reader(open(src)))
names, data = rows[0], np.array(rows[2:], dtype=float)
col = {n: data[:, i] for i, n in enumerate(names)}
logger = [  # twinbench name, logger channel, unit, factor to that unit
    ("v", "GPS_Speed", "km/h", 3.6), ("a_x", "AccLong", "g", 1 / 9.80665),
    ("a_y", "AccLat", "g", 1 / 9.80665), ("Fz_fl", "LoadFL", "kN", 1e-3),
    ("Fz_fr", "LoadFR", "kN", 1e-3), ("Fz_rl", "LoadRL", "kN", 1e-3),
    ("Fz_rr", "LoadRR", "kN", 1e-3), ("distance", "Dist", "m", 1.0),
]
t = col["time"]
raw = {ch: col[n] * f for n, ch, u, f in logger}
m = MDF(version="4.10")
m.append([Signal(samples=raw[ch], timestamps=t, name=ch, unit=u) for n, ch, u, f in logger])
m.save(mf4, overwrite=True)
# What twinbench reads: the logger's values times (unit factor / SI factor) plus 0.0.
si_factor = {"km/h": 1 / 3.6, "g": 9.80665, "kN": 1000.0, "m": 1.0}
with open(si, "w") as f:
    f.write("time," + ",".join(n for n, *_ in logger) + "\n")
    for k in range(len(t)):
        vals = [raw[ch][k] * si_factor[u] + 0.0 for n, ch, u, _ in logger]
        f.write(repr(float(t[k])) + "," + ",".join(repr(float(x)) for x in vals) + "\n")
"#;
    common::cli::output_ok(
        Command::new(common::python::python())
            .args(["-c", script])
            .args([&meas, &mf4, &si]),
    );
    let map = dir.path().join("channels.toml");
    std::fs::write(
        &map,
        "[channels]\nv = \"GPS_Speed\"\na_x = \"AccLong\"\na_y = \"AccLat\"\nFz_fl = \"LoadFL\"\nFz_fr = \"LoadFR\"\nFz_rl = \"LoadRL\"\nFz_rr = \"LoadRR\"\ndistance = \"Dist\"\n",
    )
    .unwrap();
    let (a, b) = (dir.path().join("from_mdf"), dir.path().join("from_csv"));
    synthetic::lap(
        &[&mf4],
        &[&track],
        &a,
        &["--channels", map.to_str().unwrap()],
    );
    synthetic::lap(&[&si], &[&track], &b, &[]);
    let (ra, rb) = (
        optimise(&a.join("study.toml")),
        optimise(&b.join("study.toml")),
    );
    // Every number of Tab. 1 to 1e-9 relative.
    fn numbers(v: &serde_json::Value, out: &mut Vec<f64>) {
        match v {
            serde_json::Value::Number(n) => out.push(n.as_f64().unwrap()),
            serde_json::Value::Array(a) => a.iter().for_each(|x| numbers(x, out)),
            serde_json::Value::Object(o) => o.values().for_each(|x| numbers(x, out)),
            _ => {}
        }
    }
    let (mut na, mut nb) = (Vec::new(), Vec::new());
    numbers(&ra["table1"]["steps"], &mut na);
    numbers(&rb["table1"]["steps"], &mut nb);
    assert_eq!(na.len(), nb.len());
    assert!(na.len() > 30);
    for (x, y) in na.iter().zip(&nb) {
        assert!(
            (x - y).abs() <= 1e-9 * x.abs().max(y.abs()).max(1e-300),
            "Tab. 1 differs: {x} (MDF 4) against {y} (CSV)"
        );
    }
    // `validate` on the logger-named lap with the study's channel map: the fitted lap's
    // column is the answer's e (the study's own, from its result), per signal, with no
    // note asking for a mapping the study already has.
    let val = dir.path().join("validate_mdf");
    let text = twinbench(&[
        "validate",
        a.join("optimize/result.json").to_str().unwrap(),
        mf4.to_str().unwrap(),
        "--channels",
        map.to_str().unwrap(),
        "--track",
        track.to_str().unwrap(),
        "--out",
        val.to_str().unwrap(),
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_slice(&text).unwrap();
    assert!(v["notes"].as_array().unwrap().is_empty(), "{v}");
    for row in v["rows"].as_array().unwrap() {
        let signal = row["signal"].as_str().unwrap();
        let answer = ra["joint"]["e"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["signal"] == signal)
            .unwrap_or_else(|| panic!("no joint e of {signal}"))["after"]["e"]
            .as_f64()
            .unwrap();
        assert_eq!(row["e_fitted"].as_f64().unwrap(), answer, "{row}");
        // The same lap prepared anew gives the answer's e again (1e-3).
        assert!((row["e"].as_f64().unwrap() - answer).abs() < 1e-3, "{row}");
    }
}
