//! The newcomer's fourth hour (`lap` and `info` messages): a logger's `Time` column, a
//! wrong key in a channel map, a speed in km/h without its unit, a refused lap's folder, the
//! default experiment as `info` prints it, and messages without an `invalid settings:`
//! prefix. Each message names the file and says what to write instead.

mod common;

use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use tb_testkit::assert_contains;

/// The bundled lap's rows, the header replaced by `header` (same columns), the columns
/// mapped by `row`.
fn lap_with(dir: &Path, name: &str, header: &str, row: impl Fn(&mut Vec<String>)) -> PathBuf {
    let text =
        std::fs::read_to_string(twinbench::pack::workspace_root().join("data/spielberg_lap.csv"))
            .unwrap();
    let mut out = String::from(header);
    out.push('\n');
    for line in text.lines().skip(1) {
        let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
        row(&mut cells);
        out.push_str(&cells.join(","));
        out.push('\n');
    }
    let p = dir.join(name);
    std::fs::write(&p, out).unwrap();
    p
}

const HEADER: &str =
    "time,distance,v,a_x,a_y,Fz_fl,Fz_fr,Fz_rl,Fz_rr,accel_pedal,brake_pedal,omega_rl,omega_rr";

/// The bundled lap as `logger.csv` in `dir`, the header's first `column` named `name`.
fn renamed_column(dir: &Path, column: &str, name: &str) -> PathBuf {
    lap_with(dir, "logger.csv", &HEADER.replacen(column, name, 1), |_| {})
}

/// `lap MEASUREMENT --out OUT --fmus <the packed FMUs>`, then `extra`.
fn lap_args(measurement: &Path, out: &Path, extra: &[&OsStr]) -> Vec<OsString> {
    let fmus = common::fmu_dir();
    let args = args!["lap", measurement, "--out", out, "--fmus", fmus];
    args.iter().chain(extra).map(|a| a.to_os_string()).collect()
}

#[test]
fn a_loggers_time_column_is_named_with_the_map_entry_that_takes_it() {
    let dir = tb_testkit::scratch("first-hour-4-time");
    let m = renamed_column(dir.path(), "time", "Time");
    let out = dir.path().join("lap");
    let e = common::fails(lap_args(&m, &out, &[]));
    assert!(e.contains("missing required column `time`"), "{e}");
    assert_contains(
        &e,
        &["the column `Time` differs only in case: map it with `time = \"Time\"`"],
    );
    assert!(!out.exists(), "a refused lap left {}", out.display());
    // The map entry the message suggests works.
    let map = dir.path().join("map.toml");
    std::fs::write(&map, "[channels]\ntime = \"Time\"\n").unwrap();
    common::ok(lap_args(&m, &out, &args!["--channels", map]));
    assert!(out.join("study.toml").is_file());
}

#[test]
fn an_unknown_key_in_a_channel_map_is_refused_with_the_keys_a_map_has() {
    let dir = tb_testkit::scratch("first-hour-4-map");
    let m = renamed_column(dir.path(), ",v,", ",GPS_Speed,");
    let map = dir.path().join("map.toml");
    std::fs::write(&map, "[channels]\nspeed = \"GPS_Speed\"\n").unwrap();
    let out = dir.path().join("lap");
    let args = lap_args(&m, &out, &args!["--channels", map]);
    let e = common::fails(&args);
    assert_contains(
        &e,
        &[&format!(
            "{}: channel map: unknown signal `speed`",
            map.display()
        )],
    );
    assert!(
        e.contains("(the signals a map names: time, distance, v, a_x"),
        "{e}"
    );
    assert!(!e.contains("invalid settings"), "{e}");
    assert!(!out.exists(), "a refused lap left {}", out.display());
    // A near miss is named.
    std::fs::write(&map, "[channels]\nFz_lf = \"LoadFL\"\n").unwrap();
    let e = common::fails(&args);
    assert_contains(&e, &["unknown signal `Fz_lf` (did you mean `Fz_fl`?)"]);
}

/// The speed column times `factor` (3.6: km/h, 2.237: mph), without a units row.
fn scaled_speed(dir: &Path, name: &str, factor: f64, header: &str) -> PathBuf {
    lap_with(dir, name, header, |cells| {
        let v: f64 = cells[2].parse().unwrap();
        cells[2] = format!("{}", v * factor);
    })
}

#[test]
fn a_speed_in_kmh_or_mph_without_a_units_row_is_named_as_such() {
    let dir = tb_testkit::scratch("first-hour-4-kmh");
    let out = dir.path().join("lap");
    // With the distance column: ∫v dt is 3.6 times the distance.
    let m = scaled_speed(dir.path(), "kmh.csv", 3.6, HEADER);
    let e = common::fails(lap_args(&m, &out, &[]));
    assert_contains(
        &e,
        &[&format!(
            "{}: v has no unit and looks like km/h, not m/s",
            m.display()
        )],
    );
    assert!(e.contains("the distance column"), "{e}");
    assert!(!out.exists());
    // Without it, from a_x: dv/dt is 2.24 times a_x. The distance column's name is
    // changed so that the measurement has none.
    let m = scaled_speed(
        dir.path(),
        "mph.csv",
        3600.0 / 1609.344,
        &HEADER.replacen("distance", "odometer", 1),
    );
    let e = common::fails(lap_args(&m, &out, &[]));
    assert_contains(&e, &["v has no unit and looks like mph, not m/s"]);
    assert!(e.contains("implies (mph: 2.24)"), "{e}");
    assert!(!out.exists());
    // The same speed in m/s is a lap (no false alarm from a_x's noise).
    let m = scaled_speed(
        dir.path(),
        "ms.csv",
        1.0,
        &HEADER.replacen("distance", "odometer", 1),
    );
    common::ok(lap_args(&m, &out, &[]));
    // A speed 2.7 times its own distance's (no unit it could be in): refused all the same,
    // declared unit or not.
    let m = scaled_speed(dir.path(), "scaled.csv", 2.7, HEADER);
    let out = dir.path().join("scaled");
    let e = common::fails(lap_args(&m, &out, &[]));
    assert_contains(
        &e,
        &[
            "v is 2.70 times the speed the distance column implies",
            "a wrong channel for v",
        ],
    );
    assert!(!out.exists());
}

#[test]
fn a_refused_lap_keeps_a_folder_the_user_made_and_what_is_in_it() {
    let dir = tb_testkit::scratch("first-hour-4-keep");
    let out = dir.path().join("mine");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let m = scaled_speed(dir.path(), "kmh.csv", 3.6, HEADER);
    common::fails(lap_args(&m, &out, &[]));
    assert_eq!(
        std::fs::read_to_string(out.join("notes.txt")).unwrap(),
        "mine"
    );
}

#[test]
fn an_unknown_unit_is_said_without_a_settings_prefix() {
    let dir = tb_testkit::scratch("first-hour-4-unit");
    let text =
        std::fs::read_to_string(twinbench::pack::workspace_root().join("data/spielberg_lap.csv"))
            .unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let units = "s,m,kph,m/s2,m/s2,N,N,N,N,1,1,rad/s,rad/s";
    let m = dir.path().join("bad_unit.csv");
    let body: Vec<&str> = lines.collect();
    std::fs::write(&m, format!("{header}\n{units}\n{}\n", body.join("\n"))).unwrap();
    let out = dir.path().join("lap");
    let e = common::fails(lap_args(&m, &out, &[]));
    assert_contains(
        &e,
        &[&format!("{}: channel `v`: unknown unit 'kph'", m.display())],
    );
    assert!(!e.contains("invalid settings"), "{e}");
}

#[test]
fn info_says_the_default_experiment_in_seconds() {
    let text = common::ok(args!["info", common::fmu("vehicle")]);
    let line = text
        .lines()
        .find(|l| l.starts_with("default experiment: "))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(
        line.starts_with("default experiment: start 0 s, stop "),
        "{line}"
    );
    assert!(!text.contains("Some("), "{text}");
}

/// Ctrl-C during `demo` keeps the checkpoint and says how to go on, as `optimize` does; the
/// command it prints finishes the demo.
#[test]
fn an_interrupted_demo_says_how_to_go_on() {
    let dir = tb_testkit::scratch("first-hour-4-demo");
    let d = dir.path();
    let checkpoint = d.join("dem/spielberg.checkpoint.json");
    let o = common::cli::interrupted_in(d, ["demo", "--out", "dem"], &checkpoint);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{e}");
    assert_contains(&e, &["interrupted: checkpoint kept (dem/spielberg.checkpoint.json); resume with `twinbench demo --resume --out dem`"]);
    let text = common::ok_in(d, ["demo", "--resume", "--out", "dem"]);
    assert!(text.contains("| Fz_rl |"), "{text}");
    assert!(d.join("dem/table1.md").is_file());
}
