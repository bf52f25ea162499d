//! Cross-validation with an independent master: tools/fmpy_cosim.py runs the same system
//! file with FMPy's FMU2Slave and the same algorithm; every recorded signal must agree
//! (docs/cross_validation.md: max relative difference 1e-9; in practice bit for bit).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use tb_cosim::{Algorithm, Plan, Simulation, StopConfig, SystemFile};
use tb_fmi::FmuCache;

const TOLERANCE: f64 = 1e-9;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// Run twinbench on the system file with optional overrides; write its CSV to `out`.
fn twinbench_run(
    system: &Path,
    stop: Option<f64>,
    algorithm: Option<Algorithm>,
    out: &Path,
) -> (Vec<String>, u64) {
    common::fmu_dir();
    let mut file = SystemFile::load(system).unwrap();
    if let Some(t) = stop {
        file.experiment.stop = StopConfig::Time(t);
    }
    if let Some(a) = algorithm {
        file.experiment.algorithm = a;
    }
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let sys = Plan::from_file(file, system, cache).unwrap();
    let order = sys
        .order
        .iter()
        .map(|&k| sys.unit_name(k).to_string())
        .collect();
    let mut sim = Simulation::new(sys).unwrap();
    sim.echo_fmu_log = false;
    let summary = sim.run().unwrap();
    sim.recording().write_csv(out).unwrap();
    (order, summary.steps)
}

fn fmpy_run(system: &Path, args: &[&str], reference: &Path) -> serde_json::Value {
    let out = common::cli::output_ok(
        Command::new(common::python::python())
            .arg(root().join("tools/fmpy_cosim.py"))
            .arg(system)
            .args(args)
            .arg("--compare")
            .arg(reference)
            .arg("--json"),
    );
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "bad JSON from fmpy_cosim.py ({e}): {}",
            String::from_utf8_lossy(&out.stdout)
        )
    })
}

fn check(j: &serde_json::Value, order: &[String], steps: u64, what: &str) {
    let fmpy_order: Vec<String> = serde_json::from_value(j["order"].clone()).unwrap();
    assert_eq!(fmpy_order, order, "{what}: stepping order");
    assert_eq!(j["steps"].as_u64(), Some(steps), "{what}: steps");
    let cmp = j["compare"].as_object().expect("comparison");
    assert!(cmp.get("error").is_none(), "{what}: {}", cmp["error"]);
    assert!(
        cmp.len() > 20,
        "{what}: only {} signals compared",
        cmp.len()
    );
    let mut worst = ("", 0.0f64);
    for (name, c) in cmp {
        let r = c["max_rel"].as_f64().unwrap();
        if r > worst.1 {
            worst = (name, r);
        }
    }
    eprintln!(
        "{what}: {} signals, {} steps, max relative difference {:e} ({}), bitwise equal: {}, FMPy master {:.1} s",
        cmp.len(),
        steps,
        worst.1,
        worst.0,
        j["bitwise_equal"],
        j["wall_time"].as_f64().unwrap_or(0.0)
    );
    assert!(
        worst.1 <= TOLERANCE,
        "{what}: {} differs by {:e} (relative) between twinbench and the FMPy master",
        worst.0,
        worst.1
    );
}

/// The bench with `from` replaced by `to`, written as `name` in `dir`, run for `stop` seconds
/// by twinbench and by FMPy's master: they agree ([`check`], as `what`). Twinbench's order.
fn edited_bench_matches(
    dir: &Path,
    name: &str,
    (from, to): (&str, &str),
    stop: &str,
    what: &str,
) -> Vec<String> {
    let system = common::bench_file(&dir.join(name), |text| text.replace(from, to));
    let csv = dir.join("twinbench.csv");
    let (order, steps) = twinbench_run(&system, Some(stop.parse().unwrap()), None, &csv);
    let j = fmpy_run(&system, &["--stop", stop], &csv);
    check(&j, &order, steps, what);
    order
}

#[test]
fn fmpy_master_gauss_seidel_whole_lap_matches() {
    let dir = tempfile::tempdir().unwrap();
    let system = root().join("systems/rls_v.toml");
    let csv = dir.path().join("twinbench.csv");
    let (order, steps) = twinbench_run(&system, None, None, &csv);
    assert!(steps > 90_000, "a whole lap: {steps} steps");
    let j = fmpy_run(&system, &[], &csv);
    check(&j, &order, steps, "Gauss-Seidel, one lap");
}

#[test]
fn fmpy_master_jacobi_matches() {
    let dir = tempfile::tempdir().unwrap();
    let system = root().join("systems/rls_v.toml");
    let csv = dir.path().join("twinbench.csv");
    let (order, steps) = twinbench_run(&system, Some(8.0), Some(Algorithm::Jacobi), &csv);
    let j = fmpy_run(&system, &["--stop", "8.0", "--algorithm", "jacobi"], &csv);
    check(&j, &order, steps, "Jacobi, 8 s");
}

#[test]
fn fmpy_master_explicit_order_and_fractional_stop_match() {
    // A non-default stepping order and a stop time that is not a whole number of steps
    // (the last step is shortened) exercise the same rules on both sides.
    let dir = tempfile::tempdir().unwrap();
    let order = edited_bench_matches(
        dir.path(),
        "reordered.toml",
        (
            "algorithm = \"gauss-seidel\"",
            "algorithm = \"gauss-seidel\"\norder = [\"edu\", \"dyno_rr\", \"dyno_rl\", \"driver\", \"vehicle\"]",
        ),
        "3.0005",
        "explicit order, stop 3.0005 s",
    );
    assert_eq!(order[0], "edu");
}

/// The second-order chassis (named by its item in the system file, as FMPy's master is told
/// it too): 8 s of the lap with sprung pitch and roll agree as the first-order lap does.
#[test]
fn fmpy_master_second_order_chassis_matches() {
    let dir = tempfile::tempdir().unwrap();
    let src = root().join("systems/rls_v.toml");
    edited_bench_matches(
        dir.path(),
        "second_order.toml",
        (
            "\"vehicle.v_start\" = 52.43",
            "\"vehicle.v_start\" = 52.43\n\"vehicle.chassis_model\" = \"second_order\"\n\"vehicle.pitch_damping\" = 0.3",
        ),
        "8.0",
        "second-order chassis, 8 s",
    );
    let csv = dir.path().join("twinbench.csv");
    // The chassis was in force: a_x differs from the first-order lap's.
    let first = dir.path().join("first.csv");
    twinbench_run(&src, Some(8.0), None, &first);
    let column = |path: &Path| -> Vec<String> {
        let text = std::fs::read_to_string(path).unwrap();
        let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
        let k = header.iter().position(|h| *h == "vehicle.a_x").unwrap();
        text.lines()
            .skip(2)
            .map(|l| l.split(',').nth(k).unwrap().to_string())
            .collect()
    };
    assert_ne!(column(&csv), column(&first));
}

/// Issue #35: FMPy's master (FMU3Slave) over the models' FMI 3.0 FMUs agrees with
/// twinbench's over the same FMUs, a whole lap, as the FMI 2.0 cross-check does.
#[test]
fn fmpy_master_over_the_fmi3_fmus_matches() {
    let dir = tempfile::tempdir().unwrap();
    let fmu_dir = common::fmu_dir();
    let mut text = std::fs::read_to_string(root().join("systems/rls_v.toml")).unwrap();
    for m in ["vehicle", "driver", "dyno", "edu"] {
        text = text.replace(
            &format!("\"../target/fmu/{m}.fmu\""),
            &format!(
                "{:?}",
                fmu_dir.join(format!("{m}-fmi3.fmu")).display().to_string()
            ),
        );
    }
    let system = dir.path().join("fmi3.toml");
    std::fs::write(&system, text).unwrap();
    let csv = dir.path().join("twinbench.csv");
    let (order, steps) = twinbench_run(&system, None, None, &csv);
    assert!(steps > 90_000, "a whole lap: {steps} steps");
    let j = fmpy_run(&system, &[], &csv);
    check(&j, &order, steps, "FMI 3.0 FMUs, one lap");
}
