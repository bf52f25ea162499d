//! `twinbench export-ssp`: the package validates against the SSP 1.0 schema FMPy ships, runs
//! in FMPy's simulate_ssp and in libcosim (libcosimpy), and their results agree with
//! twinbench's Jacobi run within the tolerances of docs/cross_validation.md; each tool's
//! own semantics are reproduced bit for bit by tools/fmpy_cosim.py.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use tb_cosim::{Algorithm, Plan, Simulation, StopConfig, SystemFile};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// rls_v in Jacobi mode, every step recorded, with a fixed stop (or the lap).
fn jacobi_system(dir: &Path, stop: Option<f64>) -> PathBuf {
    let fmu_dir = common::fmu_dir();
    let mut text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("algorithm = \"gauss-seidel\"", "algorithm = \"jacobi\"")
        .replace("decimation = 5", "decimation = 1")
        .replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()));
    if let Some(t) = stop {
        text = text.replace("stop = \"vehicle.lap >= 1\"", &format!("stop = {t:?}"));
    }
    let p = dir.join(format!("jacobi_{}.toml", stop.unwrap_or(0.0)));
    std::fs::write(&p, text).unwrap();
    p
}

fn twinbench_csv(system: &Path, out: &Path) -> u64 {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let mut sim = Simulation::new(Plan::load(system, cache).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    sim.recording().write_csv(out).unwrap();
    s.steps
}

fn export(system: &Path, out: &Path, stop: f64) -> serde_json::Value {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let sys = Plan::load(system, cache).unwrap();
    let s = tb_cosim::ssp::export(
        &sys,
        out,
        &tb_cosim::ssp::ExportOptions {
            stop_time: Some(stop),
        },
    )
    .unwrap();
    serde_json::to_value(s).unwrap()
}

fn python(args: &[&str]) -> serde_json::Value {
    let out = common::cli::output_ok(Command::new(common::python::python()).args(args));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("bad JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

fn tool(name: &str) -> String {
    root().join("tools").join(name).display().to_string()
}

fn max_abs(c: &serde_json::Value, signal: &str) -> f64 {
    c["signals"][signal]["max_abs"].as_f64().unwrap()
}

/// The tolerances of docs/cross_validation.md (SSP tools vs twinbench Jacobi): speed [m/s],
/// distance [m], dyno speed [rad/s].
fn assert_within_lap_tolerance(c: &serde_json::Value, what: &str, limits: [f64; 3]) {
    let v = max_abs(c, "vehicle.v");
    let d = max_abs(c, "vehicle.distance");
    let w = max_abs(c, "dyno_rl.omega");
    eprintln!("{what}: max |dv| {v:.2e} m/s, |ds| {d:.2e} m, |d omega| {w:.2e} rad/s");
    assert!(v <= limits[0], "{what}: vehicle.v differs by {v} m/s");
    assert!(d <= limits[1], "{what}: vehicle.distance differs by {d} m");
    assert!(w <= limits[2], "{what}: dyno_rl.omega differs by {w} rad/s");
}

#[test]
fn ssp_validates_and_runs_in_fmpy_exactly_as_its_semantics_predict() {
    let dir = tempfile::tempdir().unwrap();
    let stop = 4.0;
    let system = jacobi_system(dir.path(), Some(stop));
    let ssp = dir.path().join("bench.ssp");
    let summary = export(&system, &ssp, stop);
    assert_eq!(summary["components"], 5);
    assert_eq!(summary["connections"], 14);
    assert_eq!(summary["parameters"], 7);
    assert_eq!(summary["fmus"].as_array().unwrap().len(), 4);
    let tb = dir.path().join("twinbench.csv");
    twinbench_csv(&system, &tb);
    let ssp_s = ssp.display().to_string();
    let tb_s = tb.display().to_string();
    let saved = dir.path().join("simulate_ssp.csv").display().to_string();
    let j = python(&[
        &tool("ssp_check.py"),
        &ssp_s,
        "--fmpy",
        "--compare",
        &tb_s,
        "--save",
        &saved,
        "--skip-until",
        "1.0",
        "--json",
    ]);
    assert_eq!(
        j["validation"]["valid"], true,
        "schema problems: {}",
        j["validation"]["problems"]
    );
    assert!(j["validation"]["schema"]
        .as_str()
        .unwrap()
        .ends_with("SystemStructureDescription.xsd"));
    // simulate_ssp = FMPy master without initialisation exchange and with t += h: the
    // independent master with those semantics gives the same numbers bit for bit.
    let sys_s = system.display().to_string();
    let explained = python(&[
        &tool("fmpy_cosim.py"),
        &sys_s,
        "--init",
        "zero",
        "--time-base",
        "sum",
        "--compare",
        &saved,
        "--json",
    ]);
    // (The time column differs: the saved simulate_ssp rows are labelled k*h, the
    // accumulated t += h drifts by ~1e-13 s; the signals are equal bit for bit.)
    let cmp = explained["compare"].as_object().unwrap();
    assert!(cmp.len() > 20);
    for (name, c) in cmp.iter().filter(|(n, _)| *n != "time") {
        assert_eq!(c["bitwise_equal"], true, "{name}: {c}");
    }
    // Against twinbench's Jacobi run: the speed and distance everywhere, the wheel speed
    // after the start transient of the zero inputs (first second).
    let c = &j["fmpy"]["compare"];
    assert!(c["points"].as_u64().unwrap() >= 3990);
    assert!(max_abs(c, "vehicle.v") <= 0.3 && max_abs(c, "vehicle.distance") <= 1.0);
    // simulate_ssp's own semantics (zero start, summed time) differ from twinbench's.
    assert_within_lap_tolerance(
        &j["fmpy"]["compare_after"],
        "simulate_ssp, 1-4 s",
        [0.02, 0.05, 0.1],
    );
}

#[test]
fn ssp_runs_in_libcosim_over_a_lap() {
    let dir = tempfile::tempdir().unwrap();
    let system = jacobi_system(dir.path(), None);
    let tb = dir.path().join("twinbench.csv");
    let steps = twinbench_csv(&system, &tb);
    assert!(steps > 90_000);
    let stop = (steps / 1000) as f64; // whole seconds inside the lap
    let ssp = dir.path().join("bench.ssp");
    export(&system, &ssp, stop);
    let ssp_s = ssp.display().to_string();
    let tb_s = tb.display().to_string();
    let j = python(&[
        &tool("ssp_check.py"),
        &ssp_s,
        "--libcosim",
        "--compare",
        &tb_s,
        "--json",
    ]);
    assert!(j["libcosim"]["error"].is_null(), "{}", j["libcosim"]);
    let c = &j["libcosim"]["compare"];
    assert!(c["points"].as_u64().unwrap() as f64 >= stop * 1000.0 - 1.0);
    // Only libcosim's nanosecond clock differs (measured 1.4e-11 m/s over the lap).
    assert_within_lap_tolerance(c, "libcosim, one lap", [1e-8, 1e-8, 1e-8]);
}

#[test]
fn libcosim_is_reproduced_bitwise_with_its_nanosecond_clock() {
    // libcosim differs from twinbench only by its time base (integer nanoseconds converted
    // per step, so the step size jitters by an ulp and the models' substep counts change);
    // the independent master on that clock gives libcosim's numbers bit for bit.
    let dir = tempfile::tempdir().unwrap();
    let stop = 2.0;
    let system = jacobi_system(dir.path(), Some(stop));
    let ssp = dir.path().join("bench.ssp");
    export(&system, &ssp, stop);
    let ns = dir.path().join("ns.csv");
    let sys_s = system.display().to_string();
    let ns_s = ns.display().to_string();
    python(&[
        &tool("fmpy_cosim.py"),
        &sys_s,
        "--time-base",
        "ns",
        "--out",
        &ns_s,
        "--json",
    ]);
    // fmpy_cosim's CSV has no units row; ssp_check reads twinbench's format: add one.
    let text = std::fs::read_to_string(&ns).unwrap();
    let (head, rest) = text.split_once('\n').unwrap();
    let units = vec![""; head.split(',').count()].join(",");
    std::fs::write(&ns, format!("{head}\n{units}\n{rest}")).unwrap();
    let ssp_s = ssp.display().to_string();
    let j = python(&[
        &tool("ssp_check.py"),
        &ssp_s,
        "--libcosim",
        "--compare",
        &ns_s,
        "--json",
    ]);
    let c = &j["libcosim"]["compare"];
    assert!(c["points"].as_u64().unwrap() >= 1999);
    assert_eq!(c["worst_rel"].as_f64(), Some(0.0), "{c}");
}

#[test]
fn replays_are_refused_with_a_clear_error() {
    common::fmu_dir();
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let path = root().join("systems/rls_alpha.toml");
    let sys = Plan::load(&path, cache).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x.ssp");
    let e = tb_cosim::ssp::export(&sys, &out, &Default::default()).unwrap_err();
    assert!(matches!(e, tb_cosim::ssp::SspError::Unsupported(_)), "{e}");
    let e = e.to_string();
    assert_contains(&e, &["replay", "SSP 1.0"]);
    assert!(!out.exists());
    // The file itself stays usable in SSP-free form: a system without replays exports.
    let mut file = SystemFile::load(&root().join("systems/rls_v.toml")).unwrap();
    file.experiment.stop = StopConfig::Time(1.0);
    file.experiment.algorithm = Algorithm::Jacobi;
    let sys = Plan::from_file(
        file,
        &root().join("systems/rls_v.toml"),
        Arc::new(FmuCache::temporary(false).unwrap()),
    )
    .unwrap();
    tb_cosim::ssp::export(&sys, &out, &Default::default()).unwrap();
    assert!(out.exists());
}
