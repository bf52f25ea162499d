//! What is refused before the first step (names with suggestions, causality, types, double
//! connections, feed-through cycles, experiment values, files) and the errors of a run
//! (a model's error, a value that is not finite), each with where it is.

mod support;

use support::kinds::{algebraic_loop, invalid};
use support::{instances, Bench};
use tb_cosim::plan::OrderError;
use tb_cosim::{SystemError, SystemFile};
use tb_testkit::assert_contains;

/// A gain `g`, an integrator `int` and a sink `snk`, with `connections`.
fn wired(connections: &str) -> String {
    let instances = instances(&[("g", "gain"), ("int", "integrator"), ("snk", "sink")]);
    format!("connections = [{connections}]\n\n{instances}[experiment]\nstep = 0.5\nstop = 1.0\n")
}

/// The error of `wired(connections)` holds every one of `parts`.
#[track_caller]
fn assert_wiring_refused(b: &Bench, connections: &str, parts: &[&str]) {
    assert_contains(&b.error(&wired(connections)), parts);
}

#[test]
fn an_unknown_instance_is_named_with_the_instances_closest_first() {
    let b = Bench::new();
    assert_wiring_refused(
        &b,
        "\"itn.x -> g.u\"",
        &[
            "connection \"itn.x -> g.u\"",
            "unknown instance 'itn'; instances: int, g, snk",
        ],
    );
    assert_wiring_refused(
        &b,
        "\"int.x -> sink.v\"",
        &["unknown instance 'sink'; instances: snk,"],
    );
}

#[test]
fn an_unknown_variable_is_named_with_the_closest_names() {
    let b = Bench::new();
    assert_wiring_refused(
        &b,
        "\"int.x -> snk.vv\"",
        &[
            "unknown variable 'snk.vv' (FMU",
            "sink.fmu); closest names: v, n, on",
        ],
    );
    // A swap of two letters is one edit.
    assert_wiring_refused(&b, "\"int.x -> snk.v_uot\"", &["closest names: v_out"]);
}

#[test]
fn a_connection_runs_from_an_output_to_an_input() {
    let cases = [
        (
            "\"int.x -> snk.v_out\"",
            "'snk.v_out' is continuous output, not an input: it cannot be connected to",
        ),
        (
            "\"int.x -> snk.limit\"",
            "'snk.limit' is fixed parameter, not an input",
        ),
        (
            "\"int.u -> g.u\"",
            "'int.u' is continuous input, not an output",
        ),
        (
            "\"int.x0 -> g.u\"",
            "'int.x0' is fixed parameter, not an output",
        ),
        (
            "\"int.x g.u\"",
            "expected \"instance.output -> instance.input\"",
        ),
        (
            "\"int.x -> gu\"",
            "'gu' is not of the form instance.variable",
        ),
    ];
    Bench::new().refuses(&cases, &[], wired);
}

#[test]
fn an_input_is_connected_once() {
    assert_wiring_refused(
        &Bench::new(),
        "\"int.x -> g.u\", \"snk.x_out -> g.u\"",
        &[
            "connection \"snk.x_out -> g.u\"",
            "'g.u' is already connected",
        ],
    );
}

#[test]
fn types_must_match_or_widen_to_real() {
    let cases = [
        (
            "\"snk.text_out -> g.u\"",
            "type mismatch: 'snk.text_out' is String, 'g.u' is Real",
        ),
        (
            "\"int.x -> snk.n\"",
            "type mismatch: 'int.x' is Real, 'snk.n' is Integer",
        ),
        (
            "\"int.x -> snk.text\"",
            "type mismatch: 'int.x' is Real, 'snk.text' is String",
        ),
        (
            "\"snk.on_out -> snk.n\"",
            "type mismatch: 'snk.on_out' is Boolean, 'snk.n' is Integer",
        ),
        (
            "\"int.steps -> snk.on\"",
            "type mismatch: 'int.steps' is Integer, 'snk.on' is Boolean",
        ),
    ];
    let b = Bench::new();
    b.refuses(&cases, &[], wired);
    // Integer into an Enumeration and back, and any number into a Real, pass.
    b.plan(&wired(
        "\"int.steps -> snk.gear_in\", \"snk.gear_out -> snk.n\", \"snk.on_out -> g.u\"",
    ))
    .unwrap();
}

/// `a.y -> b.u`, `b.y -> a.u`: `a` of the FMU `a_fmu`, `b` a gain.
fn gain_loop(a_fmu: &str) -> String {
    let instances = instances(&[("a", a_fmu), ("b", "gain")]);
    format!("connections = [\"a.y -> b.u\", \"b.y -> a.u\"]\n{instances}[experiment]\nstep = 0.5\nstop = 1.0\n")
}

#[test]
fn a_loop_of_declared_feedthrough_is_an_algebraic_loop() {
    let b = Bench::new();
    let e = b.plan(&gain_loop("gain")).err().expect("refused");
    assert!(algebraic_loop(&e), "{e}");
    let e = e.to_string();
    assert_contains(
        &e,
        &["direct feed-through cycle (an algebraic loop): a.u -> a.y -> b.u -> b.y -> a.u"],
    );
    assert!(e.ends_with("b.y -> a.u"), "{e}");
    // Through an integrator (no feed-through) the loop is fine, without a warning.
    let plan = b
        .plan(&wired("\"int.x -> g.u\", \"g.y -> int.u\""))
        .unwrap();
    assert!(
        plan.warnings.iter().all(|w| !w.contains("cycle")),
        "{:?}",
        plan.warnings
    );
}

#[test]
fn a_loop_through_outputs_without_declared_dependencies_is_a_warning() {
    let b = Bench::new();
    let plan = b.plan(&gain_loop("gain_nodeps")).unwrap();
    assert_contains(
        &plan.warnings.join("\n"),
        &[
            "possible feed-through cycle through outputs that declare no dependencies: a.u -> a.y -> b.u -> b.y -> a.u",
        ],
    );
    assert!(
        plan.warnings.iter().any(|w| w.ends_with("b.y -> a.u")),
        "{:?}",
        plan.warnings
    );
}

/// Red team N18: an output the ModelStructure leaves out may depend on every input; a
/// self-loop through it ran with no word.
#[test]
fn a_loop_through_an_output_missing_from_the_model_structure_is_a_warning() {
    let b = Bench::new();
    let plan = b
        .plan("connections = [\"g.y -> g.u\"]\n[[instance]]\nname = \"g\"\nfmu = \"gain_unlisted\"\n[experiment]\nstep = 0.5\nstop = 1.0\n")
        .unwrap();
    assert_contains(
        &plan.warnings.join("\n"),
        &["possible feed-through cycle through outputs that declare no dependencies: g.u -> g.y -> g.u"],
    );
}

#[test]
fn instances_and_fmus_are_named_once_and_must_exist() {
    let cases = [
        (
            "[[instance]]\nname = \"g\"\nfmu = \"gian\"\n",
            "instance 'g': fmu 'gian' is not in [fmus] (known: gain, gain_nodeps, gain_unlisted, integrator, sink, source)",
        ),
        (
            "[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n",
            "instance name 'g' is repeated",
        ),
        ("[[instance]]\nname = \"g.1\"\nfmu = \"gain\"\n", "instance name 'g.1' is repeated, empty, or contains a '.'"),
        ("[[instance]]\nname = \"\"\nfmu = \"gain\"\n", "instance name '' is repeated, empty"),
    ];
    let b = Bench::new();
    b.refuses(&cases, &[], |instances| {
        format!("{instances}[experiment]\nstep = 0.5\nstop = 1.0\n")
    });
    // An FMU file that is not there: the system file, the entry, and how to make it.
    let path = b.write(
        "lap/system.toml",
        "[fmus]\ngain = \"fmu/gain.fmu\"\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[experiment]\nstep = 0.5\nstop = 1.0\n",
    );
    let e = b.load(&path).err().expect("refused");
    assert!(invalid(&e, "lap/system.toml"), "{e}");
    assert_contains(
        &e.to_string(),
        &[
            "lap/system.toml: [fmus] gain: ",
            "lap/fmu/gain.fmu does not exist (paths in a system file are relative to its folder)",
            "twinbench pack -o ",
        ],
    );
}

/// One integrator with the given `[experiment]` lines.
fn experiment(lines: &str) -> String {
    format!("[[instance]]\nname = \"int\"\nfmu = \"integrator\"\n[experiment]\n{lines}\n")
}

#[test]
fn experiment_values_that_cannot_be_run_are_refused() {
    let cases = [
        (
            "step = 0.0\nstop = 1.0",
            "experiment.step must be positive, got 0",
        ),
        (
            "step = -0.1\nstop = 1.0",
            "experiment.step must be positive, got -0.1",
        ),
        (
            "step = nan\nstop = 1.0",
            "experiment.step must be positive, got NaN",
        ),
        (
            "step = inf\nstop = 1.0",
            "experiment.step must be positive, got inf",
        ),
        (
            "step = 0.1\nstart = inf\nstop = 1.0",
            "experiment.start must be a finite time, got inf",
        ),
        (
            "step = 0.1\nstop = inf",
            "experiment.stop must be a finite time, got inf",
        ),
        (
            "step = 0.1\nstart = 2.0\nstop = 1.0",
            "experiment.stop 1 is not after start 2",
        ),
        (
            "step = 0.1\nstop = 0.0",
            "experiment.stop 0 is not after start 0",
        ),
        (
            "step = 1e-300\nstop = 1.0",
            "s over 1 s is 1.000e300 macro steps, more than 1e12: a larger step",
        ),
        (
            "step = 1e308\nstop = 1.0",
            "experiment.step = 1e308 s is longer than the whole run (1 s): not one step would be taken",
        ),
        (
            "step = 1e-9\nstop = \"int.x >= 1\"\nmax_time = 1e4",
            "is 1.000e13 macro steps, more than 1e12",
        ),
        (
            "step = 0.1\nstop = 1.0\nalgorithm = \"newton\"",
            "unknown algorithm \"newton\" (gauss-seidel, jacobi)",
        ),
        (
            "step = 0.1\nstop = 1.0\norder = [\"int\", \"int\"]",
            "experiment.order: 'int' appears twice",
        ),
        (
            "step = 0.1\nstop = 1.0\norder = [\"nope\"]",
            "experiment.order: unknown instance 'nope'",
        ),
        (
            "step = 0.1\nstop = 1.0\nstep_size = 0.1",
            "unknown field `step_size`",
        ),
    ];
    let b = Bench::new();
    b.refuses(&cases, &["system.toml"], experiment);
    let e = b
        .plan(&format!(
            "{}[[instance]]\nname = \"g\"\nfmu = \"gain\"\n",
            experiment("step = 0.1\nstop = 1.0\norder = [\"int\"]")
        ))
        .err()
        .expect("refused");
    assert!(
        matches!(&e, SystemError::Order { error: OrderError::Missing { name }, .. } if name == "g"),
        "{e}"
    );
    let order_error = |order: &str| {
        let lines = format!("step = 0.1\nstop = 1.0\norder = {order}");
        match b.plan(&experiment(&lines)).err().expect("refused") {
            SystemError::Order { error, .. } => error,
            other => panic!("{other}"),
        }
    };
    assert!(matches!(
        order_error("[\"int\", \"int\"]"),
        OrderError::Twice { .. }
    ));
    assert!(matches!(
        order_error("[\"nope\"]"),
        OrderError::UnknownInstance { .. }
    ));
    let e = b.error(&format!(
        "{}[record]\ndecimation = 0\n",
        experiment("step = 0.1\nstop = 1.0")
    ));
    assert_contains(&e, &["record.decimation must be at least 1"]);
}

#[test]
fn a_file_that_is_not_a_system_file_says_what_it_is() {
    let b = Bench::new();
    let e = SystemFile::load(&b.path("fmu/gain.fmu")).unwrap_err();
    assert!(
        matches!(&e, SystemError::File { path, .. } if path.ends_with("fmu/gain.fmu")),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["gain.fmu: is a ZIP archive (an FMU?), not a system file: `run` takes a system file (TOML), an SSP 1.0 package (.ssp) or an FMU named .fmu"],
    );
    let bin = b.path("bin.toml");
    std::fs::write(&bin, [b'a', 0xff, b'b']).unwrap();
    let e = SystemFile::load(&bin).unwrap_err();
    assert!(
        matches!(&e, SystemError::File { path, .. } if *path == bin),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["is not a text file (byte 1 is not UTF-8): a system file is TOML"],
    );
    let e = SystemFile::load(&b.path("none.toml")).unwrap_err();
    assert!(
        matches!(&e, SystemError::File { path, .. } if path.ends_with("none.toml")),
        "{e}"
    );
    assert_contains(&e.to_string(), &["none.toml: cannot read:"]);
    // The path is said once, not once by the reader and again by the system file.
    assert_eq!(e.to_string().matches("none.toml").count(), 1, "{e}");
    let e = b.error(
        "[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[experiment]\nstep = 0.5\nstop = true\n",
    );
    assert_contains(&e, &["system.toml", "stop"]);
    let e = b.error(&wired("[\"int.x\", \"g.u\"]"));
    assert_contains(&e, &["a connection is \"a.x -> b.y\" or { from = \"a.x\", to = \"b.y\", ... }, got a TOML array"]);
}

#[test]
fn a_models_error_in_a_step_names_the_instance_the_call_and_the_time() {
    let b = Bench::new();
    let text = "[[instance]]\nname = \"int\"\nfmu = \"integrator\"\n[parameters]\n\"int.u\" = 1.0\n\"int.x_max\" = 0.6\n[experiment]\nstep = 0.25\nstop = 2.0\n";
    let mut sim = b.sim(text);
    let e = sim.run().unwrap_err();
    let SystemError::Fmu(fmu) = &e else {
        panic!("{e:?}")
    };
    assert_contains(
        &fmu.to_string(),
        &[
            "int",
            "fmi2DoStep",
            "0.5",
            "x = 0.75 exceeds x_max = 0.6 in the step from t = 0.5",
        ],
    );
    // The rows up to the failed step are kept.
    assert_eq!(support::column(&sim, "time"), [0.0, 0.25, 0.5]);
}

#[test]
fn a_value_that_is_not_finite_stops_the_run_naming_the_signal() {
    let b = Bench::new();
    let text = "connections = [\"int.x -> g.u\"]\n[[instance]]\nname = \"int\"\nfmu = \"integrator\"\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[parameters]\n\"int.x0\" = 1e308\n\"int.u\" = 1e308\n\"g.k\" = 1.0\n[experiment]\nstep = 1.0\nstop = 3.0\n";
    let e = b.sim(text).run().unwrap_err();
    let SystemError::NotFinite {
        instance,
        signal,
        value,
        time,
    } = &e
    else {
        panic!("{e:?}")
    };
    // 1e308 + 1e308·1 overflows in the first step.
    assert_eq!((instance.as_str(), signal.as_str()), ("int", "int.x"));
    assert_eq!((*value, *time), (f64::INFINITY, 1.0));
    assert_eq!(
        e.to_string(),
        "int.x is not finite (inf) at t = 1 s after the step of instance 'int'"
    );
}

#[test]
fn a_record_only_output_that_is_not_finite_is_caught_at_its_recorded_row() {
    let b = Bench::new();
    // g.y = 2·1e308 overflows at initialisation; only the recording reads it.
    let text = "connections = [\"int.x -> g.u\"]\n[[instance]]\nname = \"int\"\nfmu = \"integrator\"\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[parameters]\n\"int.x0\" = 1e308\n[experiment]\nstep = 1.0\nstop = 3.0\n[record]\nsignals = [\"g.y\"]\n";
    let e = b.sim(text).run().unwrap_err();
    assert_eq!(
        e.to_string(),
        "g.y is not finite (inf) at t = 0 s after the step of instance 'g'"
    );
}
