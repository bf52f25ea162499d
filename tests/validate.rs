//! `twinbench validate RESULT.json MEASUREMENT`: the fitted twin on a lap it was not fitted
//! on. On the fitted lap itself (prepared anew by `lap` from the measurement and its track)
//! it must give the e the same twin reaches on the study's own bench; a file that is not a
//! study result is refused by name; and the system and measurement a result file names are
//! never run or read (red team P4).

mod common;

use common::{fails_in, ok_in, run_ok_in};
use tb_testkit::assert_contains;

#[test]
fn validate_on_the_fitted_lap_gives_the_fitted_e_and_writes_its_table() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    let dir = tb_testkit::scratch("validate");
    let d = dir.path();
    let study = root.join("studies/spielberg.toml");
    // A short study (one generation per step) for a result to validate.
    // Its stdout is no terminal (`optimize … > log.txt`): a plain line per generation, with
    // an ETA, before Tab. 1.
    let log = ok_in(
        d,
        args!["optimize", study, "--generations", "1", "--out", "opt"],
    );
    for step in ["step 1 ", "step 2 "] {
        let line = log
            .lines()
            .find(|l| l.starts_with(step) && l.contains("generation 1/1"))
            .unwrap_or_else(|| panic!("no generation line of {step}in {log}"));
        assert_contains(line, &["best cost", "ETA"]);
    }
    assert!(
        log.find("generation 1/1").unwrap() < log.find("| all |").unwrap(),
        "{log}"
    );
    // The joint refinement after the steps says where it stands too, and when it is done.
    let refined = log
        .lines()
        .find(|l| l.starts_with("joint refinement: ") && l.ends_with(", done"))
        .unwrap_or_else(|| panic!("no line of the joint refinement in {log}"));
    assert!(refined.contains(" laps of 5 parameters"), "{refined}");
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("opt/result.json")).unwrap()).unwrap();
    // Every parameter of the study's answer carries an interval (or a statement why not)
    // and its method.
    let answer = result["joint"]["parameters"].as_array().unwrap();
    assert_eq!(answer.len(), 5);
    for p in answer {
        assert_eq!(p["interval_method"], "gauss-newton-hac", "{p}");
        assert!(
            p["interval"].is_array() || p["interval_statement"].is_string(),
            "{p}"
        );
    }
    the_answer_applies_to_a_run_as_set_does(d, &root, &result);
    let meas = root.join("data/spielberg_lap.csv");
    let track = root.join("data/spielberg_lap_track.csv");
    let args = args![
        "validate",
        "opt/result.json",
        meas,
        "--track",
        track,
        "--out",
        "val"
    ];
    let o = run_ok_in(d, args.iter().chain(&args!["--json"]));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 7, "{v}");
    for r in rows {
        let (a, b) = (r["e_fitted"].as_f64().unwrap(), r["e"].as_f64().unwrap());
        // The lap `lap` prepares is the bundled bench's lap: the same e to 1e-3.
        assert!((a - b).abs() < 1e-3, "{r}");
    }
    assert!(v["notes"].as_array().unwrap().is_empty(), "{v}");
    for f in [
        "validation.md",
        "validation.json",
        "validation_fz_sum.svg",
        "validation_fz_sum.png",
    ] {
        assert!(d.join("val").join(f).is_file(), "{f}");
    }
    let md = std::fs::read_to_string(d.join("val/validation.md")).unwrap();
    assert!(md.contains("| 2 | Fz_rl |"), "{md}");
    the_same_lap_in_a_loggers_names_validates_alike(d, &meas, &track, rows);
    a_result_file_never_decides_what_code_runs(d, &result, &meas, &track, rows);
    // Not a result: named, and what was expected.
    std::fs::write(d.join("bad.json"), "{\"study\": 1}").unwrap();
    let e = fails_in(d, args!["validate", "bad.json", meas, "--out", "val2"]);
    assert_contains(
        &e,
        &["bad.json: not a study result (the result.json `twinbench optimize` writes)"],
    );
}

/// `run SYSTEM --params result.json` gives the lap `run SYSTEM --set …` gives with the
/// answer's values typed out (bit for bit); a `--set` after it wins; a result naming a
/// parameter the system does not have is refused by name.
fn the_answer_applies_to_a_run_as_set_does(
    d: &std::path::Path,
    root: &std::path::Path,
    result: &serde_json::Value,
) {
    let system = root.join("systems/rls_v.toml");
    let system = system.to_str().unwrap();
    ok_in(
        d,
        [
            "run",
            system,
            "--params",
            "opt/result.json",
            "-o",
            "params.csv",
        ],
    );
    let mut args = vec!["run".to_string(), system.to_string()];
    for p in result["parameters_final"].as_array().unwrap() {
        let (name, value) = (p[0].as_str().unwrap(), p[1].as_f64().unwrap());
        args.push("--set".into());
        args.push(format!("{name}={value}"));
    }
    args.extend(["-o".to_string(), "set.csv".to_string()]);
    ok_in(d, &args);
    let (a, b) = (
        std::fs::read(d.join("params.csv")).unwrap(),
        std::fs::read(d.join("set.csv")).unwrap(),
    );
    assert!(a == b, "run --params and run --set differ");
    // A --set after --params wins: the lap changes.
    let params = ["run", system, "--params", "opt/result.json"];
    ok_in(
        d,
        params
            .iter()
            .chain(&["--set", "vehicle.l=3.0", "-o", "params_l.csv"]),
    );
    assert!(std::fs::read(d.join("params_l.csv")).unwrap() != a);
    // A parameter the system does not have: named, with the result file.
    let text = std::fs::read_to_string(d.join("opt/result.json"))
        .unwrap()
        .replace("\"vehicle.b_rear\"", "\"vehicle.b_rearr\"");
    std::fs::write(d.join("renamed.json"), text).unwrap();
    let e = fails_in(d, ["run", system, "--params", "renamed.json"]);
    assert_contains(&e, &["--params renamed.json: vehicle.b_rearr", "b_rear"]);
}

/// Red team P4: a result whose "system" names a hostile FMU's system and whose
/// "measurement" names a file that is not there: `validate` runs and reads neither (the
/// fitted lap's e is the answer's, from the result), and gives the table it gave before.
fn a_result_file_never_decides_what_code_runs(
    d: &std::path::Path,
    result: &serde_json::Value,
    meas: &std::path::Path,
    track: &std::path::Path,
    rows: &[serde_json::Value],
) {
    let (fmu, _) = common::hostile::fmu(d, "DOORS");
    let sys = common::hostile::system(d, &fmu);
    let mut hostile = result.clone();
    hostile["system"] = serde_json::json!(sys);
    hostile["measurement"] = serde_json::json!(d.join("no-such-lap.csv"));
    std::fs::write(d.join("hostile.json"), hostile.to_string()).unwrap();
    let args = args![
        "validate",
        "hostile.json",
        meas,
        "--track",
        track,
        "--out",
        "val3"
    ];
    let o = run_ok_in(d, args.iter().chain(&args!["--json"]));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!e.contains("hostile:"), "the result's system ran: {e}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["rows"].as_array().unwrap(), rows);
    // The fitted lap's e is the answer's as the study computed it.
    for r in rows {
        let answer = result["joint"]["e"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["signal"] == r["signal"])
            .unwrap();
        assert_eq!(r["e_fitted"], answer["after"]["e"], "{r}");
    }
}

/// The same lap with a logger's channel names and a channel map: every row (the fitted
/// lap's e, the answer's, and this lap's) as with the study's names, to the bit.
fn the_same_lap_in_a_loggers_names_validates_alike(
    d: &std::path::Path,
    meas: &std::path::Path,
    track: &std::path::Path,
    rows: &[serde_json::Value],
) {
    let names = [
        ("v", "GPS_Speed"),
        ("a_x", "AccLong"),
        ("a_y", "AccLat"),
        ("Fz_fl", "LoadFL"),
        ("Fz_fr", "LoadFR"),
        ("Fz_rl", "LoadRL"),
        ("Fz_rr", "LoadRR"),
    ];
    let text = std::fs::read_to_string(meas).unwrap();
    let (header, body) = text.split_once('\n').unwrap();
    let header: Vec<String> = header
        .split(',')
        .map(|h| {
            names
                .iter()
                .find(|(ours, _)| *ours == h)
                .map_or(h.to_string(), |(_, theirs)| theirs.to_string())
        })
        .collect();
    std::fs::write(
        d.join("logger.csv"),
        format!("{}\n{body}", header.join(",")),
    )
    .unwrap();
    let map: String = names
        .iter()
        .map(|(ours, theirs)| format!("{ours} = \"{theirs}\"\n"))
        .collect();
    std::fs::write(d.join("map.toml"), format!("[channels]\n{map}")).unwrap();
    let args = args![
        "validate",
        "opt/result.json",
        "logger.csv",
        "--channels",
        "map.toml"
    ];
    let o = run_ok_in(
        d,
        args.iter()
            .chain(&args!["--track", track, "--out", "val_logger", "--json"]),
    );
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["rows"].as_array().unwrap(), rows, "{v}");
    assert!(v["notes"].as_array().unwrap().is_empty(), "{v}");
}
