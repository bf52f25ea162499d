//! The relative tolerance of an FMU with an internal variable-step solver
//! (`tests/cfmus/adaptive.c`: Van der Pol by an embedded Runge-Kutta pair with step control,
//! DefaultExperiment tolerance 1e-7, its own default 1e-2 when given none): passed as FMPy
//! passes it (the DefaultExperiment's, `toleranceDefined = true`), set by the system file
//! per experiment and per instance and by `run --tolerance`, kept through SSP, and checked.

mod common;

use common::ok_in;
use std::path::Path;
use std::process::Command;
use tb_cosim::Table;
use tb_testkit::assert_contains;

/// The FMU alone: 10 s at 0.1 s, its outputs recorded; `extra` goes into `[experiment]`,
/// `instance` into `[[instance]]`.
fn system(dir: &Path, name: &str, extra: &str, instance: &str) {
    let text = format!(
        "[fmus]\nadaptive = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"adaptive\"\n{instance}\n\n[experiment]\nstep = 0.1\nstop = 10.0\n{extra}\n\n[record]\nsignals = [\"m.x1\", \"m.x2\", \"m.steps_taken\"]\n",
        common::cfmu::fmu("adaptive").display()
    );
    std::fs::write(dir.join(name), text).unwrap();
}

fn fmpy(dir: &Path, out: &str, tolerance: Option<&str>) -> Table {
    let mut cmd = Command::new(common::python::python());
    cmd.arg(twinbench::pack::workspace_root().join("tools/fmpy_simulate.py"))
        .arg(common::cfmu::fmu("adaptive"))
        .arg(dir.join(out))
        .args(["--stop", "10", "--step", "0.1"]);
    if let Some(t) = tolerance {
        cmd.args(["--tolerance", t]);
    }
    let r = cmd.output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    Table::read_any(&dir.join(out)).unwrap()
}

fn worst(ours: &Table, theirs: &Table) -> f64 {
    assert_eq!(ours.len(), theirs.len());
    ["x1", "x2", "steps_taken"]
        .iter()
        .flat_map(|n| {
            let a = ours.require(&format!("m.{n}")).unwrap();
            let b = theirs.require(n).unwrap();
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .collect::<Vec<_>>()
        })
        .fold(0.0, f64::max)
}

fn read(dir: &Path, name: &str) -> Table {
    Table::read_any(&dir.join(name)).unwrap()
}

#[test]
fn the_default_experiment_tolerance_reaches_the_fmu_as_in_fmpy() {
    let dir = tb_testkit::scratch("tolerance");
    let d = dir.path();
    system(d, "sys.toml", "", "");
    ok_in(
        d,
        [
            "run",
            "sys.toml",
            "--out",
            "default.csv",
            "--trace-fmi",
            "trace.txt",
        ],
    );
    let ours = read(d, "default.csv");
    let theirs = fmpy(d, "fmpy.csv", None);
    let w = worst(&ours, &theirs);
    eprintln!("DefaultExperiment tolerance 1e-7: largest difference to FMPy {w:e}");
    assert!(w <= 1e-12, "differs from FMPy by {w:e}");
    let trace = std::fs::read_to_string(d.join("trace.txt")).unwrap();
    assert_contains(
        &trace,
        &["fmi2SetupExperiment(tolerance=1e-7, startTime=0.0, stopTime=10.0) -> fmi2OK"],
    );

    // Another tolerance: another solution (fewer internal steps), again equal to FMPy's.
    ok_in(
        d,
        [
            "run",
            "sys.toml",
            "--tolerance",
            "1e-3",
            "--out",
            "coarse.csv",
        ],
    );
    let coarse = read(d, "coarse.csv");
    let w = worst(&coarse, &fmpy(d, "fmpy-coarse.csv", Some("1e-3")));
    assert!(w <= 1e-12, "--tolerance 1e-3 differs from FMPy by {w:e}");
    let steps = |t: &Table| *t.require("m.steps_taken").unwrap().last().unwrap();
    assert!(
        steps(&coarse) < 0.5 * steps(&ours),
        "1e-3: {} internal steps, 1e-7: {}",
        steps(&coarse),
        steps(&ours)
    );
    let x1_gap = worst(&coarse, &theirs);
    assert!(
        x1_gap > 1e-6,
        "1e-3 and 1e-7 agree to {x1_gap:e}: the tolerance is not used"
    );
}

#[test]
fn the_system_file_sets_the_tolerance_per_experiment_and_per_instance_and_ssp_keeps_it() {
    let dir = tb_testkit::scratch("tolerance-file");
    let d = dir.path();
    ok_pair(d);
    // [experiment] tolerance applies to every instance; an instance's own wins.
    system(d, "exp.toml", "tolerance = 1e-3", "");
    system(d, "inst.toml", "tolerance = 1e-9", "tolerance = 1e-3");
    ok_in(d, ["run", "exp.toml", "--out", "exp.csv"]);
    ok_in(d, ["run", "inst.toml", "--out", "inst.csv"]);
    ok_in(
        d,
        ["run", "exp.toml", "--tolerance", "1e-3", "--out", "cli.csv"],
    );
    let exp = std::fs::read(d.join("exp.csv")).unwrap();
    assert_eq!(exp, std::fs::read(d.join("inst.csv")).unwrap());
    assert_eq!(exp, std::fs::read(d.join("cli.csv")).unwrap());
    // Through SSP: the experiment's and an instance's tolerance come back.
    for name in ["exp", "inst"] {
        let (toml, ssp, csv) = (
            format!("{name}.toml"),
            format!("{name}.ssp"),
            format!("{name}-ssp.csv"),
        );
        ok_in(d, ["export-ssp", &toml, "--out", &ssp]);
        ok_in(d, ["run", &ssp, "--out", &csv]);
        assert_eq!(
            exp,
            std::fs::read(d.join(format!("{name}-ssp.csv"))).unwrap(),
            "{name} through SSP"
        );
    }
}

/// The default run, for the comparisons above (1e-7 against 1e-3 must differ).
fn ok_pair(d: &Path) {
    system(d, "default.toml", "", "");
    ok_in(d, ["run", "default.toml", "--out", "default.csv"]);
}

#[test]
fn a_tolerance_that_is_not_one_is_refused_before_the_run() {
    let dir = tb_testkit::scratch("tolerance-bad");
    let d = dir.path();
    for (extra, instance, expected) in [
        (
            "tolerance = 0.0",
            "",
            "experiment.tolerance: 0 is not a relative tolerance",
        ),
        (
            "tolerance = 2.0",
            "",
            "experiment.tolerance: 2 is not a relative tolerance",
        ),
        (
            "",
            "tolerance = -1e-6",
            "instance 'm': tolerance: -1e-6 is not a relative tolerance",
        ),
    ] {
        system(d, "bad.toml", extra, instance);
        let o = common::twinbench_in(d, ["run", "bad.toml"]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert!(e.contains(expected), "{expected}: {e}");
    }
    system(d, "sys.toml", "", "");
    for bad in ["nan", "0", "1"] {
        let o = common::twinbench_in(d, ["run", "sys.toml", "--tolerance", bad]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{e}");
        assert_contains(&e, &["--tolerance", "between 0 and 1"]);
    }
}
