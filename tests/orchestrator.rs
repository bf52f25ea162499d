//! The master's time base, warnings, result files and the `run`/`info` commands.

mod common;

use common::kinds::invalid;

use std::path::PathBuf;
use std::sync::Arc;
use tb_cosim::{Plan, Simulation, SystemFile};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

/// The system text parsed as if read from `<scratch>/<name>.toml` (nothing is written).
fn faulty_system(body: &str, name: &str) -> (SystemFile, PathBuf) {
    let fmu = common::fmu("faulty");
    let text = format!("{body}\n[fmus]\nfaulty = \"{}\"\n", fmu.display());
    let path = PathBuf::from(format!("/nonexistent/tb-orch/{name}.toml"));
    (SystemFile::parse(&text, &path).unwrap(), path)
}

fn sim(file: SystemFile, path: &std::path::Path) -> Simulation {
    let s = Plan::from_file(file, path, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let mut sim = Simulation::new(s).unwrap();
    sim.echo_fmu_log = false;
    sim
}

const ONE: &str = "[[instance]]\nname = \"a\"\nfmu = \"faulty\"\n\n[parameters]\n\"a.u\" = 1.0\n\n[record]\nsignals = [\"a.y\", \"a.steps\"]\n\n[experiment]\nstep = 1e-3\n";

#[test]
fn the_last_step_is_clamped_to_the_stop_time() {
    let (f, p) = faulty_system(&format!("{ONE}stop = 1.0005\n"), "clamp");
    let mut s = sim(f, &p);
    let r = s.run().unwrap();
    // 1000 full steps and one of 0.5 ms: y = ∫1 dt ends at exactly the stop time.
    assert_eq!(r.steps, 1001);
    assert_eq!(r.simulated_time, 1.0005);
    let y = *s.recording().require("a.y").unwrap().last().unwrap();
    assert!((y - 1.0005).abs() < 1e-12, "{y}");
    assert_eq!(
        *s.recording().require("time").unwrap().last().unwrap(),
        1.0005
    );
}

#[test]
fn the_tick_time_base_does_not_drift() {
    let (f, p) = faulty_system(&format!("{ONE}stop = 100.0\n"), "drift");
    let mut f = f;
    f.record.decimation = 1000;
    let mut s = sim(f, &p);
    let r = s.run().unwrap();
    assert_eq!(r.steps, 100_000);
    let t = s.recording().require("time").unwrap();
    // Every recorded time is exactly k·h (k integer), no accumulated rounding.
    for (k, &x) in t.iter().enumerate() {
        assert_eq!(x, k as f64 * 1000.0 * 1e-3, "row {k}");
    }
    assert_eq!(
        *s.recording().require("a.steps").unwrap().last().unwrap(),
        100_000.0
    );
}

#[test]
fn results_are_csv_with_a_units_row_written_atomically() {
    let (f, p) = faulty_system(&format!("{ONE}stop = 0.1\n"), "csv");
    let mut s = sim(f, &p);
    s.run().unwrap();
    let scratch = tb_testkit::scratch("orch-csv");
    let out = scratch.path().join("lap.csv");
    s.recording().write_csv(&out).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time,a.y,a.steps"));
    assert_eq!(lines.next(), Some("s,s,"));
    let t = tb_compare::Table::read_path(&out).unwrap();
    assert_eq!(t.names(), &["time", "a.y", "a.steps"]);
    assert_eq!(t.column("a.steps").unwrap().unwrap().last(), Some(&100.0));
    // No temporary file is left beside it.
    let dir = out.parent().unwrap();
    let stem = out.file_name().unwrap().to_string_lossy().to_string();
    assert!(std::fs::read_dir(dir).unwrap().all(|e| !e
        .unwrap()
        .file_name()
        .to_string_lossy()
        .starts_with(&format!(".{stem}.tmp"))));
    std::fs::remove_file(out).unwrap();
}

#[test]
fn run_json_summary_and_info_table() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    let scratch = tb_testkit::scratch("orch-run");
    let out = scratch.path().join("lap.csv");
    let run = args!["run", "systems/rls_v.toml", "--json", "--out", out];
    let set = args!["--set", "vehicle.c_lift_front=0.9"];
    let o = common::run_ok_in(&root, run.iter().chain(&set));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in ["steps", "simulated_time", "wall_time", "lap_time"] {
        assert!(j[key].is_number(), "{key} missing in {j}");
    }
    assert!((j["lap_time"].as_f64().unwrap() - 98.0).abs() < 3.0);
    assert!(out.exists());
    std::fs::remove_file(&out).unwrap();
    // A bad --set names the variable.
    let o = common::twinbench_in(
        &root,
        [
            "run",
            "systems/rls_v.toml",
            "--set",
            "vehicle.c_lift_frnt=0.9",
        ],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_contains(
        &err,
        &["unknown variable 'vehicle.c_lift_frnt'", "c_lift_front"],
    );
    // info lists variables with units.
    let o = common::twinbench_in(&root, ["info", "target/fmu/vehicle.fmu"]);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success());
    assert!(
        text.contains("canGetAndSetFMUstate") || text.contains("get/set state true"),
        "{text}"
    );
    assert!(
        text.lines()
            .any(|l| l.starts_with("Fz_sum") && l.contains(" N ")),
        "{text}"
    );
}

#[test]
fn strings_are_set_connected_recorded_and_quoted_in_the_csv() {
    let body = "connections = [\"a.tag_out -> b.tag\"]\n[[instance]]\nname = \"a\"\nfmu = \"faulty\"\n\n[[instance]]\nname = \"b\"\nfmu = \"faulty\"\n\n[parameters]\n\"a.tag\" = \"lap, one\"\n\n[record]\nsignals = [\"a.tag_out\", \"b.tag_out\", \"b.steps\"]\n\n[experiment]\nstep = 1e-3\nstop = 0.003\n";
    let (f, p) = faulty_system(body, "strings");
    let mut s = sim(f, &p);
    s.run().unwrap();
    let rec = s.recording();
    assert_eq!(
        rec.text_at(1).unwrap(),
        ["lap, one 0", "lap, one 1", "lap, one 2", "lap, one 3"]
    );
    assert_eq!(rec.text_at(2).unwrap()[3], "lap, one 3 3");
    let scratch = tb_testkit::scratch("orch-strings");
    let out = scratch.path().join("s.csv");
    rec.write_csv(&out).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("\"lap, one 3\",\"lap, one 3 3\",3"), "{text}");
    let back = tb_table::Table::read_path(&out).unwrap();
    assert_eq!(back.text_at(2).unwrap()[3], "lap, one 3 3");
    // The same through isolated workers (strings on the worker protocol).
    let (f, p) = faulty_system(body, "strings-isolated");
    let options = tb_cosim::LoadOptions {
        isolate: true,
        ..Default::default()
    };
    let plan = Plan::compile(
        f,
        &p,
        Arc::new(FmuCache::temporary(false).unwrap()),
        &options,
    )
    .unwrap();
    let mut iso = Simulation::new(plan).unwrap();
    iso.run().unwrap();
    assert_eq!(iso.recording().text_at(2), rec.text_at(2));
    // A String parameter of the wrong type is refused by the plan, naming it.
    let bad = body.replace("\"a.tag\" = \"lap, one\"", "\"a.tag\" = 3");
    let (f, p) = faulty_system(&bad, "strings-bad");
    let e = Plan::from_file(f, &p, Arc::new(FmuCache::temporary(false).unwrap()))
        .err()
        .unwrap();
    assert!(invalid(&e, "parameter \"a.tag\""), "{e}");
    assert!(
        e.to_string()
            .contains("'a.tag' is String, the value 3 is not"),
        "{e}"
    );
}
