//! A lap of one's own, and what goes wrong with it: a malformed track file, a track and a
//! target of different laps, a missing channel, an unknown unit, a measurement of another
//! circuit; each refused with a message naming what disagrees. And FMPy sets the same
//! String parameters as twinbench.

mod common;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// The bundled bench with some parameters added, written beside `dir`'s files.
fn bench_with(dir: &Path, extra: &str) -> PathBuf {
    common::bench_file(&dir.join("bench.toml"), |text| {
        text.replace("[parameters]\n", &format!("[parameters]\n{extra}\n"))
    })
}

/// `dir/name`: the CSV header `header`, then `row(s)` for each `s` of `metres`.
fn by_metre(
    dir: &Path,
    name: &str,
    header: &str,
    metres: impl Iterator<Item = u32>,
    row: impl Fn(u32) -> String,
) -> PathBuf {
    let mut text = format!("{header}\n");
    for s in metres {
        text.push_str(&row(s));
        text.push('\n');
    }
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_malformed_track_file_fails_initialisation_naming_the_users_path_row_and_column() {
    let track = "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n1,0.01,x,0,0\n2,0,0,0,0\n";
    let dir = common::scratch_with("bad-track", &[("my_track.csv", track)]);
    // A relative path in the system file is relative to the system file.
    let sys = bench_with(dir.path(), "\"vehicle.track_file\" = \"my_track.csv\"");
    let e = common::fails(args!["run", sys]);
    let user_path = dir.path().join("my_track.csv").display().to_string();
    assert!(e.contains("fmi2ExitInitializationMode"), "{e}");
    assert_contains(
        &e,
        &[&format!(
            "{user_path}: row 3: column 'grade': 'x' is not a number"
        )],
    );
    // Printed once (the FMU's message with the failed call, not echoed before it too).
    assert_eq!(e.matches("is not a number").count(), 1, "{e}");
    // No temporary folder of the unpacked FMU in the message.
    assert!(!e.contains("twinbench-fmu-"), "{e}");
}

#[test]
fn a_track_and_a_target_of_different_laps_are_refused_before_the_first_step() {
    let dir = tb_testkit::scratch("other-target");
    by_metre(dir.path(), "short.csv", "s,v", 0..=3000, |s| {
        format!("{s},40")
    });
    let sys = bench_with(dir.path(), "\"driver.target_speed_file\" = \"short.csv\"");
    let e = common::fails(args!["run", sys]);
    assert!(e.contains("check failed after initialisation"), "{e}");
    assert_contains(&e, &["vehicle.lap_length", "driver.lap_length"]);
    assert!(e.contains("not the same lap"), "{e}");
}

#[test]
fn a_missing_channel_and_an_unknown_unit_name_the_file_and_the_channel() {
    let dir = tb_testkit::scratch("bad-channels");
    let map = dir.path().join("map.toml");
    std::fs::write(&map, "[channels]\nv = \"GPS_Speed\"\n").unwrap();
    let meas = root().join("data/spielberg_lap.csv");
    let out = dir.path().join("lap");
    let e = common::fails(args!["lap", meas, "--channels", map, "--out", out]);
    assert!(e.contains("spielberg_lap.csv"), "{e}");
    assert_contains(
        &e,
        &["no channel `GPS_Speed` (the channel map's name for signal `v`)"],
    );
    // A units row with a unit twinbench does not know.
    let text = std::fs::read_to_string(&meas).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    let units: Vec<&str> = header
        .split(',')
        .map(|c| if c == "v" { "furlong/fortnight" } else { "" })
        .collect();
    let odd = dir.path().join("odd_units.csv");
    std::fs::write(
        &odd,
        format!(
            "{header}\n{}\n{}\n",
            units.join(","),
            lines.collect::<Vec<_>>().join("\n")
        ),
    )
    .unwrap();
    let e = common::fails(args!["lap", odd, "--out", out]);
    assert_contains(&e, &["odd_units.csv", "channel `v`"]);
    assert!(e.contains("unknown unit 'furlong/fortnight'"), "{e}");
}

/// The bundled lap with the wheel loads renamed as a logger names them (`LoadFL`, …), one
/// row's `LoadFR` set to `nan` if `nan_row` is given, and `LoadRR` absent if `drop_rr`.
fn logger_named_lap(dir: &Path, name: &str, drop_rr: bool, nan_row: Option<usize>) -> PathBuf {
    let text = std::fs::read_to_string(root().join("data/spielberg_lap.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let header: Vec<String> = lines[0]
        .split(',')
        .map(|c| match c {
            "Fz_fl" => "LoadFL".into(),
            "Fz_fr" => "LoadFR".into(),
            "Fz_rl" => "LoadRL".into(),
            "Fz_rr" if drop_rr => "Other".into(),
            "Fz_rr" => "LoadRR".into(),
            c => c.into(),
        })
        .collect();
    if let Some(row) = nan_row {
        let k = header.iter().position(|c| c == "LoadFR").unwrap();
        let mut cells: Vec<String> = lines[row].split(',').map(str::to_string).collect();
        cells[k] = "nan".into();
        lines[row] = cells.join(",");
    }
    lines[0] = header.join(",");
    let path = dir.join(name);
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    path
}

#[test]
fn errors_about_mapped_channels_name_the_files_own_channels() {
    let channels =
        "[channels]\nFz_fl = \"LoadFL\"\nFz_fr = \"LoadFR\"\nFz_rl = \"LoadRL\"\nFz_rr = \"LoadRR\"\n";
    let dir = common::scratch_with("mapped-channels", &[("map.toml", channels)]);
    let map = dir.path().join("map.toml");
    let track = root().join("data/spielberg_lap_track.csv");
    let out = dir.path().join("lap");
    let lap = |meas: &Path| {
        common::fails(args![
            "lap",
            meas,
            "--channels",
            map,
            "--track",
            track,
            "--out",
            out
        ])
    };
    // A missing channel: the closest and the list are the file's channels, not the
    // signals the map renamed them to.
    let e = lap(&logger_named_lap(dir.path(), "no_rr.csv", true, None));
    assert!(e.contains("no channel `LoadRR`"), "{e}");
    assert_contains(&e, &["closest channels: LoadFR, LoadRL, LoadFL"]);
    assert_contains(
        &e,
        &["channels in the file: time, distance, v, a_x, a_y, LoadFL, LoadFR, LoadRL, Other"],
    );
    // A NaN in a mapped channel is told under the file's channel.
    let e = lap(&logger_named_lap(dir.path(), "nan.csv", false, Some(50)));
    assert_contains(&e, &["line 51, column `LoadFR`", "not finite"]);
    // Two signals given one channel are refused, both named.
    std::fs::write(&map, "[channels]\nFz_fl = \"LoadFL\"\nFz_fr = \"LoadFL\"\n").unwrap();
    let e = lap(&logger_named_lap(dir.path(), "ok.csv", false, None));
    assert!(e.contains("gives channel `LoadFL` to two signals"), "{e}");
}

#[test]
fn a_measurement_of_another_circuit_is_refused_before_optimising() {
    common::fmu_dir();
    let dir = tb_testkit::scratch("other-circuit");
    // The bundled lap stretched in time and distance by 1.3: another circuit.
    let t = tb_table::Table::read_path(root().join("data/spielberg_lap.csv")).unwrap();
    let cols: Vec<Vec<f64>> = t
        .names()
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let c = t.column_at(i);
            if n == "time" || n == "distance" {
                c.iter().map(|x| 1.3 * x).collect()
            } else {
                c.to_vec()
            }
        })
        .collect();
    let other = dir.path().join("other_circuit.csv");
    tb_table::Table::from_columns("other", t.names().to_vec(), cols)
        .unwrap()
        .write_csv(&other)
        .unwrap();
    let study = std::fs::read_to_string(root().join("studies/spielberg.toml"))
        .unwrap()
        .replace(
            "system = \"../systems/rls_v.toml\"",
            &format!(
                "system = {:?}",
                root().join("systems/rls_v.toml").display().to_string()
            ),
        )
        .replace(
            "measurement = \"../data/spielberg_lap.csv\"",
            &format!("measurement = {:?}", other.display().to_string()),
        );
    let study_p = dir.path().join("study.toml");
    std::fs::write(&study_p, study).unwrap();
    let out = dir.path().join("out");
    let e = common::fails(args![
        "optimize",
        study_p,
        "--out",
        out,
        "--generations",
        "1",
        "--no-report"
    ]);
    assert!(e.contains("do not belong together"), "{e}");
    assert_contains(&e, &["lap length", "(measured)"]);
    assert!(e.contains("--force"), "{e}");
}

#[test]
fn fmpy_sets_the_track_file_and_reads_the_same_lap_length_as_twinbench() {
    let dir = tb_testkit::scratch("fmpy-track");
    let header = "s,curvature,grade,z_road_left,z_road_right";
    let track_p = by_metre(dir.path(), "oval.csv", header, 0..1234, |s| {
        format!("{s},0.002,0,0,0")
    });
    // twinbench: the vehicle alone, track_file set.
    let fmu = common::fmu("vehicle");
    let sys = common::system_file(
        &dir.path().join("vehicle.toml"),
        "",
        &[("vehicle", &fmu)],
        "[[instance]]\nname = \"vehicle\"\nfmu = \"vehicle\"\n\n[parameters]\n\"vehicle.track_file\" = \"oval.csv\"\n\"vehicle.v_start\" = 20.0\n\"vehicle.omega_rl\" = 57.97\n\"vehicle.omega_rr\" = 57.97\n\n[experiment]\nstep = 1e-3\nstop = 0.01\n\n[record]\nsignals = [\"vehicle.lap_length\"]\n",
    );
    let csv = dir.path().join("tb.csv");
    common::ok(args!["run", sys, "--out", csv]);
    let tb = tb_table::Table::read_path(&csv).unwrap();
    let ours = *tb.require("vehicle.lap_length").unwrap().last().unwrap();
    assert_eq!(ours, 1234.0);
    // FMPy, with the same String parameter.
    let script = r#"
import sys
from fmpy import simulate_fmu
r = simulate_fmu(sys.argv[1], start_values={"track_file": sys.argv[2], "v_start": 20.0},
                 stop_time=0.01, step_size=1e-3, output=["lap_length"])
print(repr(float(r["lap_length"][-1])))
"#;
    let o = Command::new(common::python::python())
        .args([
            "-c",
            script,
            fmu.to_str().unwrap(),
            track_p.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fmpy: f64 = String::from_utf8_lossy(&o.stdout).trim().parse().unwrap();
    assert_eq!(fmpy, ours);
}

/// Wheel loads logged in kN, daN or lbf without a units row: `lap` refuses the lap naming
/// the likely unit and the file's own channel (mapped: the signal too), before any file is
/// written; the same file in N passes; a declared unit is converted and passes.
#[test]
fn wheel_loads_in_kn_dan_or_lbf_without_their_unit_are_refused_naming_it() {
    let dir = tb_testkit::scratch("load-units");
    let d = dir.path();
    let text = std::fs::read_to_string(root().join("data/spielberg_lap.csv")).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    let loads: Vec<usize> = (0..header.len())
        .filter(|&i| header[i].starts_with("Fz_"))
        .collect();
    assert_eq!(loads.len(), 4);
    // Every other row (a lighter file), the loads divided by `factor`; `names` renames the
    // header, `units` adds a units row.
    let write = |name: &str, factor: f64, names: &[(&str, &str)], units: Option<&str>| {
        let mut h: Vec<String> = header.iter().map(|s| s.to_string()).collect();
        for (from, to) in names {
            let i = h.iter().position(|x| x == from).unwrap();
            h[i] = to.to_string();
        }
        let mut out = format!("{}\n", h.join(","));
        if let Some(u) = units {
            let row: Vec<&str> = header
                .iter()
                .map(|n| match *n {
                    "time" => "s",
                    "distance" => "m",
                    "v" => "m/s",
                    "a_x" | "a_y" => "m/s2",
                    "omega_rl" | "omega_rr" => "rad/s",
                    n if n.starts_with("Fz_") => u,
                    _ => "",
                })
                .collect();
            out.push_str(&format!("{}\n", row.join(",")));
        }
        for r in rows.iter().step_by(2) {
            let cells: Vec<String> = r
                .iter()
                .enumerate()
                .map(|(i, x)| {
                    if loads.contains(&i) {
                        format!("{}", x / factor)
                    } else {
                        format!("{x}")
                    }
                })
                .collect();
            out.push_str(&format!("{}\n", cells.join(",")));
        }
        let p = d.join(name);
        std::fs::write(&p, out).unwrap();
        p
    };
    let track = root().join("data/spielberg_lap_track.csv");
    let lap = |meas: &Path, out: &str, extra: &[&OsStr]| {
        let out = d.join(out);
        let args = args!["lap", meas, "--track", track, "--out", out];
        (common::twinbench(args.iter().chain(extra)), out)
    };
    for (unit, factor) in [("kN", 1000.0), ("daN", 10.0), ("lbf", 4.448_221_615_260_5)] {
        let meas = write(&format!("lap_{unit}.csv"), factor, &[], None);
        let (o, out) = lap(&meas, unit, &[]);
        assert!(!o.status.success(), "{unit}: accepted");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            e.contains(&format!("looks like {unit}, not N"))
                && e.contains("lap_")
                && e.contains("Fz_"),
            "{unit}: {e}"
        );
        assert!(!out.exists(), "{unit}: a refused lap left its folder");
    }
    // Logger names through a channel map: the file's channel and the signal both named.
    let meas = write(
        "logger_kn.csv",
        1000.0,
        &[
            ("Fz_fl", "LoadFL"),
            ("Fz_fr", "LoadFR"),
            ("Fz_rl", "LoadRL"),
            ("Fz_rr", "LoadRR"),
        ],
        None,
    );
    let map = d.join("map.toml");
    std::fs::write(
        &map,
        "[channels]\nFz_fl = \"LoadFL\"\nFz_fr = \"LoadFR\"\nFz_rl = \"LoadRL\"\nFz_rr = \"LoadRR\"\n",
    )
    .unwrap();
    let (o, _) = lap(&meas, "logger", &args!["--channels", map]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert_contains(
        &e,
        &["looks like kN", "channel `LoadFL` (the study's Fz_fl)"],
    );
    // In N, and in kN with its unit declared: accepted.
    let (o, _) = lap(&write("lap_n.csv", 1.0, &[], None), "n", &[]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, _) = lap(
        &write("lap_kn_declared.csv", 1000.0, &[], Some("kN")),
        "kn",
        &[],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}
