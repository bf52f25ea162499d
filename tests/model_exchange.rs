//! Model Exchange, FMI 2.0 and FMI 3.0: every Reference FMU run through its Model Exchange
//! interface (integrated by twinbench with CVODE) and compared with FMPy's Model Exchange
//! loop with its CVode solver (`simulate_fmu(..., fmi_type='ModelExchange',
//! solver='CVode')`, record_events off, output interval = the system's step): every output
//! sample, and the event times (BouncingBall's bounces, Stair's steps). Each model runs
//! twice in twinbench, both ways of choosing Model Exchange: the Reference FMU (which
//! declares both interfaces) with `interface = "model-exchange"`, and an archive stripped of
//! its `<CoSimulation>` element (Model Exchange only: the default). FMI 3.0 adds StateSpace,
//! whose states are an array. Then an isolated instance against the in-process one (bit
//! for bit), Model Exchange and Co-Simulation instances connected in one system, and the
//! refusals and errors.

mod common;

use common::kinds::invalid;

use common::reference;
use std::path::{Path, PathBuf};
use tb_cosim::{Simulation, SystemError, SystemFile, Table};
use tb_fmi::{FmuCache, FmuError};
use tb_testkit::assert_contains;

/// The largest difference from FMPy's CVode result allowed, relative to the larger of 1
/// and the column's largest magnitude. Both integrate with CVODE set up alike (BDF,
/// Newton, dense, rtol 1e-5 and atol = rtol·nominal, maxStep (stop − start)/50, 500 steps
/// per call, restart after every event), FMPy with SUNDIALS 7 and twinbench with Debian's
/// 6.4.1; the measured differences are printed (`--nocapture`) and in docs/design.md.
const TOLERANCE: f64 = 1e-11;

/// The experiments: the models' default ones (Feedthrough and Resource have no step).
fn experiment(model: &str) -> (f64, f64) {
    match model {
        "BouncingBall" => (3.0, 1e-2),
        "Dahlquist" => (10.0, 0.1),
        "Feedthrough" => (2.0, 0.1),
        "Resource" => (1.0, 0.1),
        "Stair" => (10.0, 0.2),
        "VanDerPol" => (20.0, 1e-2),
        "StateSpace" => (10.0, 0.1),
        "Roberts" => (1.0, 0.01),
        m => panic!("no experiment for {m}"),
    }
}

/// `xml` without its `<element>` (written `<element .../>` or `<element>...</element>`).
fn without(xml: &str, element: &str) -> String {
    let a = xml.find(&format!("<{element}")).unwrap();
    let close = a + xml[a..].find('>').unwrap();
    let b = if xml[..close].ends_with('/') {
        close + 1
    } else {
        let end = format!("</{element}>");
        xml.find(&end).unwrap() + end.len()
    };
    format!("{}{}", &xml[..a], &xml[b..])
}

/// `<Model>.fmu` (both interfaces) and `<Model>_me.fmu` (Model Exchange only, in `dir`),
/// of FMI `version`.
fn fmus(model: &str, version: u8, dir: &Path) -> (PathBuf, PathBuf) {
    let both = reference::fmu(model, version);
    let me_only = reference::with_description(&both, dir, &format!("{model}_me"), |xml| {
        without(xml, "CoSimulation")
    });
    (both, me_only)
}

/// FMPy's Model Exchange result: a row per output point (`record_events`: and the two rows
/// FMPy records at each event, before and after it).
fn fmpy(fmu: &Path, out: &Path, stop: f64, step: f64, record_events: bool) -> Table {
    let script = twinbench::pack::workspace_root().join("tools/fmpy_simulate.py");
    let mut cmd = std::process::Command::new(common::python::python());
    cmd.arg(&script)
        .arg(fmu)
        .arg(out)
        .args(["--stop", &stop.to_string(), "--step", &step.to_string()])
        .arg("--model-exchange");
    if record_events {
        cmd.arg("--record-events");
    }
    let r = cmd.output().unwrap();
    assert!(
        r.status.success(),
        "FMPy on {}: {}",
        fmu.display(),
        String::from_utf8_lossy(&r.stderr)
    );
    Table::read_any(out).unwrap()
}

/// A system file's text: the top-level keys `top`, `instances` as (name, fmu, extra
/// keys), then the tables `rest`.
fn system_text(top: &str, instances: &[(&str, &Path, &str)], rest: &str) -> String {
    let mut text = format!("{top}\n[fmus]\n");
    for (name, fmu, _) in instances {
        text.push_str(&format!("{name} = \"{}\"\n", fmu.display()));
    }
    for (name, _, extra) in instances {
        text.push_str(&format!(
            "\n[[instance]]\nname = \"{name}\"\nfmu = \"{name}\"\n{extra}\n"
        ));
    }
    text.push('\n');
    text.push_str(rest);
    text
}

/// Run a system file's text in `dir`: the recording, or the error.
fn run(text: &str, dir: &Path, name: &str) -> Result<Table, SystemError> {
    let path = dir.join(format!("{name}.toml"));
    let file = SystemFile::parse(text, &path)?;
    let plan = common::compile(file, &path)?;
    let mut sim = Simulation::new(plan)?;
    sim.echo_fmu_log = false;
    sim.run()?;
    Ok(sim.recording().clone())
}

/// One Model Exchange instance `m` of `fmu`, every output recorded.
fn run_one(fmu: &Path, extra: &str, stop: f64, step: f64, dir: &Path) -> Table {
    let text = system_text(
        "",
        &[("m", fmu, extra)],
        &format!("[experiment]\nstep = {step}\nstop = {stop}\n"),
    );
    run(&text, dir, "m").unwrap_or_else(|e| panic!("{}: {e}", fmu.display()))
}

/// [`run_one`] in `model`'s experiment.
fn run_model(model: &str, fmu: &Path, extra: &str, dir: &Path) -> Table {
    let (stop, step) = experiment(model);
    run_one(fmu, extra, stop, step, dir)
}

/// Per column FMPy recorded: the largest difference, relative to max(1, |largest value|).
fn differences(model: &str, ours: &Table, theirs: &Table) -> Vec<(String, f64)> {
    reference::worst_differences(model, ours, theirs)
        .into_iter()
        .map(|(name, worst, largest)| (name, worst / largest.max(1.0)))
        .collect()
}

/// Whether two recordings are equal bit for bit.
fn same_bits(a: &Table, b: &Table) -> bool {
    a.names() == b.names()
        && a.len() == b.len()
        && (0..a.names().len()).all(|k| {
            a.is_text(k) && b.is_text(k)
                || a.column_at(k)
                    .iter()
                    .zip(b.column_at(k))
                    .all(|(x, y)| x.to_bits() == y.to_bits())
        })
}

fn check(model: &str, version: u8) {
    let dir = tb_testkit::scratch(&format!("me-{model}-fmi{version}"));
    let (stop, step) = experiment(model);
    let (both, me_only) = fmus(model, version, dir.path());
    let forced = run_model(model, &both, "interface = \"model-exchange\"", dir.path());
    let only = run_model(model, &me_only, "", dir.path());
    assert!(
        same_bits(&forced, &only),
        "{model}: the Model Exchange only archive gives another result"
    );
    // The same through `twinbench run model.fmu`.
    let csv = dir.path().join("cli.csv");
    let (to, by) = (stop.to_string(), step.to_string());
    common::run_ok(args![
        "run", me_only, "--start", "0", "--stop", to, "--step", by, "--out", csv
    ]);
    let cli = Table::read_path(&csv).unwrap();
    assert!(cli.names().len() > 1 && cli.len() == only.len());
    for name in cli.names().iter().filter(|n| *n != "time") {
        assert_eq!(
            cli.require(name).unwrap(),
            only.require(&format!("m.{name}")).unwrap(),
            "{model} (FMI {version}): {name} from `twinbench run`"
        );
    }
    let theirs = fmpy(&me_only, &dir.path().join("fmpy.csv"), stop, step, false);
    let mut ours = forced.clone();
    if model == "Stair" {
        // Stair ends the simulation at t = 9 (terminateSimulation when its counter reaches
        // 10). twinbench records that last time as after a Co-Simulation FMU's end (FMPy's
        // Co-Simulation loop does too); FMPy's Model Exchange loop stops without it.
        assert_eq!(forced.len(), theirs.len() + 1);
        assert_eq!(forced.require("time").unwrap().last(), Some(&9.0));
        assert_eq!(forced.require("m.counter").unwrap().last(), Some(&10.0));
        ours.truncate(theirs.len());
    }
    let diffs = differences(model, &ours, &theirs);
    eprintln!("{model} (FMI {version}, Model Exchange) vs FMPy CVode: {diffs:?}");
    for (name, d) in diffs {
        assert!(
            d <= TOLERANCE,
            "{model} (FMI {version}): {name} differs from FMPy's Model Exchange result by {d:e} (relative)"
        );
    }
}

#[test]
fn bouncing_ball() {
    check("BouncingBall", 2);
}

#[test]
fn dahlquist() {
    check("Dahlquist", 2);
}

#[test]
fn feedthrough() {
    check("Feedthrough", 2);
}

#[test]
fn resource() {
    check("Resource", 2);
}

#[test]
fn stair() {
    check("Stair", 2);
}

#[test]
fn van_der_pol() {
    check("VanDerPol", 2);
}

#[test]
fn bouncing_ball_fmi3() {
    check("BouncingBall", 3);
}

#[test]
fn dahlquist_fmi3() {
    check("Dahlquist", 3);
}

#[test]
fn feedthrough_fmi3() {
    check("Feedthrough", 3);
}

#[test]
fn resource_fmi3() {
    check("Resource", 3);
}

#[test]
fn stair_fmi3() {
    check("Stair", 3);
}

#[test]
fn van_der_pol_fmi3() {
    check("VanDerPol", 3);
}

/// Robertson's stiff chemical kinetics (FMI 3.0 only): CVODE's BDF as FMPy's, two event
/// indicators.
#[test]
fn roberts_fmi3() {
    check("Roberts", 3);
}

/// The states are one array (`der(x)` has the dimension `n`): three states, integrated as
/// FMPy integrates them.
#[test]
fn state_space_fmi3_array_states() {
    check("StateSpace", 3);
}

/// The event times of one in-process Model Exchange instance over `stop` in steps of
/// `step` (the backend the master drives, without the master), and the time at which the
/// FMU asked to end the simulation, if it did.
fn our_events(fmu: &Path, stop: f64, step: f64) -> (Vec<f64>, Option<f64>) {
    let cache = FmuCache::temporary(false).unwrap();
    let loaded = cache.load(fmu).unwrap();
    let mut m = tb_cosim::backend::model_exchange(&loaded, "m", false, Default::default()).unwrap();
    m.setup_experiment(0.0, Some(stop)).unwrap();
    m.enter_initialization_mode().unwrap();
    m.exit_initialization_mode().unwrap();
    let n = (stop / step).round() as usize;
    for k in 0..n {
        if let Err(e) = m.do_step(k as f64 * step, step) {
            let end = m.terminated_by_fmu();
            assert!(end.is_some(), "{e}");
            return (m.events().to_vec(), end);
        }
    }
    (m.events().to_vec(), None)
}

/// FMPy's event times (the times it recorded twice, before and after each event), and the
/// last time it recorded.
fn fmpy_events(fmu: &Path, dir: &Path, stop: f64, step: f64) -> (Vec<f64>, f64) {
    let t = fmpy(fmu, &dir.join("events.csv"), stop, step, true);
    let time = t.require("time").unwrap();
    let events = time
        .windows(2)
        .filter(|w| w[0] == w[1])
        .map(|w| w[0])
        .collect();
    (events, *time.last().unwrap())
}

#[test]
fn events_land_where_fmpy_puts_them() {
    // BouncingBall: state events (the bounces); Stair: time events (its steps), the last
    // of which ends the simulation (terminateSimulation at counter 10). A step of
    // twinbench's ends at t + h (the master's t and h), FMPy's output point at
    // start + (n + 1)·interval: the two may be an ulp apart (3.0000000000000004 and 3.0),
    // and a time event on the grid lands on that point.
    for (model, version, tolerance) in [
        ("BouncingBall", 2, 1e-12),
        ("Stair", 2, 1e-15),
        ("BouncingBall", 3, 1e-12),
        ("Stair", 3, 1e-15),
    ] {
        let dir = tb_testkit::scratch("me-events");
        let (stop, step) = experiment(model);
        let (_, me_only) = fmus(model, version, dir.path());
        let (mut ours, end) = our_events(&me_only, stop, step);
        let (theirs, their_last) = fmpy_events(&me_only, dir.path(), stop, step);
        eprintln!("{model} (FMI {version}): events at {ours:?} (end {end:?}); FMPy: {theirs:?}");
        if let Some(end) = end {
            // FMPy stops at the terminating event: its last row, recorded once.
            assert_eq!(ours.pop(), Some(end));
            assert_eq!(end, their_last, "{model}: the end");
        }
        assert_eq!(ours.len(), theirs.len(), "{model}: {ours:?} vs {theirs:?}");
        assert!(!ours.is_empty(), "{model}: no event");
        let worst = ours
            .iter()
            .zip(&theirs)
            .map(|(a, b)| (a - b).abs() / a.abs().max(1.0))
            .fold(0.0f64, f64::max);
        eprintln!("{model}: event times differ from FMPy's by at most {worst:e} (relative)");
        assert!(worst <= tolerance, "{model}: {worst:e}");
    }
}

#[test]
fn an_isolated_instance_equals_the_in_process_one_bit_for_bit() {
    let dir = tb_testkit::scratch("me-isolated");
    for (model, version) in [
        ("BouncingBall", 2),
        ("VanDerPol", 2),
        ("BouncingBall", 3),
        ("StateSpace", 3),
    ] {
        let (both, _) = fmus(model, version, dir.path());
        let inside = run_model(model, &both, "interface = \"model-exchange\"", dir.path());
        let me_isolated = "interface = \"model-exchange\"\nisolate = true";
        let isolated = run_model(model, &both, me_isolated, dir.path());
        assert!(same_bits(&inside, &isolated), "{model} (FMI {version})");
    }
}

#[test]
fn model_exchange_and_co_simulation_instances_connect() {
    // VanDerPol through Model Exchange feeds a Co-Simulation Feedthrough (a continuous
    // Real input) and a Model Exchange Feedthrough; Stair (Co-Simulation) drives the Model
    // Exchange Feedthrough's Integer input, a discrete input set in event mode.
    let dir = tb_testkit::scratch("me-mixed");
    let vdp = reference::fmu("VanDerPol", 2);
    let stair = reference::fmu("Stair", 2);
    let ft = reference::fmu("Feedthrough", 2);
    let me = "interface = \"model-exchange\"";
    let text = system_text(
        "connections = [\"vdp.x0 -> cs.Float64_continuous_input\", \"vdp.x0 -> me.Float64_continuous_input\", \"stair.counter -> me.Int32_input\"]",
        &[
            ("vdp", &vdp, me),
            ("stair", &stair, ""),
            ("cs", &ft, "interface = \"co-simulation\""),
            ("me", &ft, me),
        ],
        "[experiment]\nstep = 0.05\nstop = 5\n[record]\nsignals = [\"vdp.x0\", \"cs.Float64_continuous_output\", \"me.Float64_continuous_output\", \"stair.counter\", \"me.Int32_output\"]\n",
    );
    let t = run(&text, dir.path(), "mixed").unwrap();
    let col = |n: &str| t.require(n).unwrap().to_vec();
    let x0 = col("vdp.x0");
    // Gauss-Seidel in connection order: both Feedthroughs see vdp's output of this step.
    assert_eq!(col("cs.Float64_continuous_output"), x0);
    assert_eq!(col("me.Float64_continuous_output"), x0);
    assert_eq!(col("me.Int32_output"), col("stair.counter"));
    assert!(col("stair.counter").iter().any(|c| *c >= 4.0));
    // The Model Exchange VanDerPol alone gives the same x0.
    let alone = run_one(&vdp, me, 5.0, 0.05, dir.path());
    assert_eq!(alone.require("m.x0").unwrap(), x0.as_slice());
}

#[test]
fn interfaces_an_fmu_lacks_are_refused_with_the_reason() {
    let dir = tb_testkit::scratch("me-refused");
    let (both, me_only) = fmus("Dahlquist", 2, dir.path());
    let cs_only = reference::with_description(&both, dir.path(), "Dahlquist_cs", |xml| {
        without(xml, "ModelExchange")
    });
    let exp = "[experiment]\nstep = 0.1\nstop = 1\n";
    // Instance `m` of `fmu` with `interface` in a system of its own (`tag`): refused, why.
    let refused = |fmu: &Path, interface: &str, tag: &str| {
        run(
            &system_text("", &[("m", fmu, interface)], exp),
            dir.path(),
            tag,
        )
        .unwrap_err()
        .to_string()
    };
    let e = refused(&cs_only, "interface = \"model-exchange\"", "a");
    assert_contains(&e, &["instance 'm'", "interface = \"model-exchange\"", "Dahlquist_cs.fmu: the FMU has no <ModelExchange> element (it supports co-simulation only)"]);
    let e = refused(&me_only, "interface = \"co-simulation\"", "b");
    assert_contains(&e, &["Dahlquist_me.fmu: the FMU has no <CoSimulation> element (it supports model-exchange only)"]);
    let e = refused(&both, "interface = \"me\"", "c");
    assert_contains(
        &e,
        &["unknown interface \"me\" (co-simulation, model-exchange)"],
    );
    // FMI 3.0 declares no counts: a description whose state vector (its
    // ContinuousStateDerivative elements) is not the FMU's is refused before the first
    // step, with both counts.
    let v3 = reference::with_description(
        &reference::fmu("Dahlquist", 3),
        dir.path(),
        "Dahlquist3_two_states",
        |xml| {
            xml.replace(
                "<ContinuousStateDerivative valueReference=\"2\"",
                "<ContinuousStateDerivative valueReference=\"1\"/>\n    <ContinuousStateDerivative valueReference=\"2\"",
            )
        },
    );
    let e = run(
        &system_text("", &[("m", &v3, "interface = \"model-exchange\"")], exp),
        dir.path(),
        "d",
    )
    .unwrap_err();
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Instantiate { instance, .. }) if instance == "m"),
        "{e}"
    );
    assert_contains(&e.to_string(), &["Dahlquist3_two_states.fmu: the model description declares 2 continuous states (the elements of its <ContinuousStateDerivative> variables), but fmi3GetNumberOfContinuousStates returns 1"]);
    // A tolerance out of range.
    let e = run(
        &system_text(
            "",
            &[("m", &me_only, "")],
            "[experiment]\nstep = 0.1\nstop = 1\ntolerance = 0\n",
        ),
        dir.path(),
        "e",
    )
    .unwrap_err();
    assert!(invalid(&e, "experiment.tolerance"), "{e}");
    assert_contains(&e.to_string(), &["experiment.tolerance: 0 is not a relative tolerance: expected a number between 0 and 1"]);
}

#[test]
fn a_solver_failure_names_the_fmu_instance_time_and_cvode_flag() {
    // Far more accuracy than a double holds: CVODE gives up with CV_TOO_MUCH_ACC.
    let dir = tb_testkit::scratch("me-solver");
    let (_, me_only) = fmus("VanDerPol", 2, dir.path());
    let text = system_text(
        "",
        &[("vdp", &me_only, "")],
        "[experiment]\nstep = 0.1\nstop = 2\ntolerance = 1e-300\n",
    );
    let e = run(&text, dir.path(), "acc").unwrap_err();
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::ModelExchange { fmu, instance, call, .. })
            if fmu.ends_with("VanDerPol_me.fmu") && instance == "vdp" && &**call == "CVode"),
        "{e}"
    );
    // The solver's flag, by its name and number.
    assert_contains(
        &e.to_string(),
        &["s: CVode returned CV_TOO_MUCH_ACC (-2): "],
    );
}

#[test]
fn the_system_tolerance_reaches_the_solver() {
    // A tighter tolerance changes the result, a little.
    let dir = tb_testkit::scratch("me-tolerance");
    let (_, me_only) = fmus("VanDerPol", 2, dir.path());
    let loose = run_one(&me_only, "", 20.0, 0.01, dir.path());
    let text = system_text(
        "",
        &[("m", &me_only, "")],
        "[experiment]\nstep = 0.01\nstop = 20\ntolerance = 1e-8\n",
    );
    let tight = run(&text, dir.path(), "tight").unwrap();
    let (a, b) = (
        loose.require("m.x0").unwrap(),
        tight.require("m.x0").unwrap(),
    );
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0f64, f64::max);
    assert!(worst > 1e-9 && worst < 1e-2, "{worst:e}");
}

/// An ME instance through the paths a Co-Simulation one takes: exported to SSP and run from
/// the package (`implementation="ModelExchange"` keeps the interface), traced, and run a
/// second time after a reset, each bit for bit the same as the plain run.
#[test]
fn ssp_trace_and_reset_keep_a_model_exchange_instance() {
    paths_of_a_model_exchange_instance(2);
}

#[test]
fn ssp_trace_and_reset_keep_an_fmi3_model_exchange_instance() {
    paths_of_a_model_exchange_instance(3);
}

fn paths_of_a_model_exchange_instance(version: u8) {
    let dir = tb_testkit::scratch("me-paths");
    let bb = reference::fmu("BouncingBall", version);
    let text = system_text(
        "",
        &[("m", &bb, "interface = \"model-exchange\"")],
        "[experiment]\nstep = 0.01\nstop = 3\n[record]\nsignals = [\"m.h\", \"m.v\"]\n",
    );
    let sys = dir.path().join("bb.toml");
    std::fs::write(&sys, &text).unwrap();
    let plain = run(&text, dir.path(), "plain").unwrap();
    let d = dir.path();
    common::ok_in(d, ["export-ssp", "bb.toml", "--out", "bb.ssp"]);
    common::ok_in(
        d,
        [
            "run",
            "bb.ssp",
            "--out",
            "from_ssp.csv",
            "--trace-fmi",
            "trace.txt",
        ],
    );
    let from_ssp = Table::read_path(dir.path().join("from_ssp.csv")).unwrap();
    for c in ["m.h", "m.v"] {
        assert_eq!(
            from_ssp.require(c).unwrap(),
            plain.require(c).unwrap(),
            "{c} from the SSP"
        );
    }
    let trace = std::fs::read_to_string(dir.path().join("trace.txt")).unwrap();
    // The calls the FMU receives while twinbench integrates it, not a DoStep, by their
    // names in the FMU's version.
    let (set_time, derivatives, update) = match version {
        2 => (
            " m: fmi2SetTime(",
            " m: fmi2GetDerivatives(",
            " m: fmi2NewDiscreteStates(newDiscreteStatesNeeded=",
        ),
        _ => (
            " m: fmi3SetTime(",
            " m: fmi3GetContinuousStateDerivatives(",
            " m: fmi3UpdateDiscreteStates(discreteStatesNeedUpdate=",
        ),
    };
    assert!(
        trace.matches(set_time).count() >= 300
            && trace.contains(derivatives)
            && trace.contains(update)
            && !trace.contains("DoStep")
            && !trace.contains(if version == 2 { "fmi3" } else { "fmi2" }),
        "{}",
        &trace[..trace.len().min(2000)]
    );
    // A second run of the same Simulation (the instance reset, as an optimisation's
    // candidates reuse it).
    let path = dir.path().join("again.toml");
    let file = SystemFile::parse(&text, &path).unwrap();
    let plan = common::compile(file, &path).unwrap();
    let mut sim = Simulation::new(plan).unwrap();
    sim.echo_fmu_log = false;
    sim.run().unwrap();
    sim.run().unwrap();
    assert!(same_bits(sim.recording(), &plain), "the second run");
}
