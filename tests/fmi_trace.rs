//! `twinbench run --trace-fmi FILE`: every FMI call of the traced instances with its
//! arguments, values and status, FMI 2.0 and 3.0, in a run that ends normally and in one
//! the FMU ends; the chosen instances only; a path that is an input is refused.

mod common;

use common::reference;
use std::ffi::OsStr;
use std::path::Path;

fn system(dir: &Path) -> std::path::PathBuf {
    let text = format!(
        "[fmus]\nm = \"{}\"\nf = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"m\"\n\n[[instance]]\nname = \"f\"\nfmu = \"f\"\n\n[parameters]\n\"f.String_input\" = \"hello\"\n\"f.Int8_input\" = -3\n\n[experiment]\nstep = 0.2\nstop = 10.0\n",
        reference::fmu("Stair", 2).display(),
        reference::fmu("Feedthrough", 3).display()
    );
    let path = dir.join("s.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn the_trace_has_every_call_with_names_values_and_status() {
    let dir = tb_testkit::scratch("trace");
    let s = system(dir.path());
    let trace = dir.path().join("trace.txt");
    let out_traced = dir.path().join("traced.csv");
    common::run_ok(args!["run", s, "--trace-fmi", trace, "-o", out_traced]);
    let text = std::fs::read_to_string(&trace).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let has = |needle: &str| lines.iter().any(|l| l.contains(needle));
    for needle in [
        "m: fmi2Instantiate(instanceName=\"m\"",
        "t=0 m: fmi2SetupExperiment(startTime=0.0, stopTime=10.0) -> fmi2OK",
        "f: fmi3InstantiateCoSimulation(instanceName=\"f\"",
        "t=0 f: fmi3Set*(vr=[11 Int8_input:Int8=-3]) -> fmi3OK",
        "t=0 f: fmi3Set*(vr=[29 String_input:String=\"hello\"]) -> fmi3OK",
        "t=0 f: fmi3Get*(vr=[30 String_output:String=\"hello\", 32 Binary_output:Binary=\"666f6f\"]) -> fmi3OK",
        "t=0 m: fmi2GetInteger(vr=[1 counter=1]) -> fmi2OK",
        // Stair asks to end the run at 9 s: the refused step, the question, the end.
        "m: fmi2DoStep(currentCommunicationPoint=8.8, communicationStepSize=0.2) -> fmi2Discard",
        "m: fmi2GetBooleanStatus(fmi2Terminated), fmi2GetRealStatus(fmi2LastSuccessfulTime) -> terminated at 9.0",
        "m: fmi2Terminate() -> fmi2OK",
        "m: fmi2FreeInstance()",
        "f: fmi3Terminate() -> fmi3OK",
        "f: fmi3FreeInstance()",
    ] {
        assert!(has(needle), "no line with `{needle}` in:\n{}", &text[..text.len().min(3000)]);
    }
    // One DoStep line per step: 44 accepted and the refused one for m.
    let steps = |who: &str| {
        lines
            .iter()
            .filter(|l| l.contains(&format!(" {who}: fmi")) && l.contains("DoStep("))
            .count()
    };
    assert_eq!(steps("m"), 45);
    assert_eq!(steps("f"), 44);
    // Tracing changes nothing in the results.
    let out_plain = dir.path().join("plain.csv");
    let r = common::twinbench(args!["run", s, "-o", out_plain]);
    assert!(r.status.success());
    assert_eq!(
        std::fs::read(&out_traced).unwrap(),
        std::fs::read(&out_plain).unwrap()
    );
}

#[test]
fn only_the_chosen_instances_are_traced_and_unknown_ones_are_named() {
    let dir = tb_testkit::scratch("trace-some");
    let s = system(dir.path());
    let trace = dir.path().join("trace.txt");
    let traced = args!["run", s, "--trace-fmi", trace];
    common::run_ok(traced.iter().chain(&args!["--trace-instances", "f"]));
    let text = std::fs::read_to_string(&trace).unwrap();
    assert!(text.lines().count() > 100);
    assert!(
        text.lines()
            .all(|l| l.contains(" f: ") || l.starts_with("f: ")),
        "{text}"
    );
    let r = common::twinbench(traced.iter().chain(&args!["--trace-instances", "f,edu"]));
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(
        !r.status.success()
            && err.contains("no instance named 'edu'")
            && err.contains("instances: m, f"),
        "{err}"
    );
}

#[test]
fn a_trace_path_that_is_an_input_is_refused_and_the_input_kept() {
    let dir = tb_testkit::scratch("trace-input");
    let s = system(dir.path());
    let before = std::fs::read(&s).unwrap();
    let r = common::twinbench(args!["run", s, "--trace-fmi", s]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success() && err.contains("--trace-fmi"), "{err}");
    assert_eq!(std::fs::read(&s).unwrap(), before);
}

/// A Model Exchange instance's trace has the calls the FMU receives while twinbench
/// integrates it (time, states, derivatives, event indicators, event mode and the event
/// iteration, CVODE's callbacks among them), not an `fmi2DoStep` it never gets; and the
/// trace changes nothing in the result.
#[test]
fn a_model_exchange_trace_has_the_calls_the_fmu_receives() {
    let dir = tb_testkit::scratch("trace-me");
    let fmu = reference::fmu("BouncingBall", 2);
    let trace = dir.path().join("trace.txt");
    let (traced, plain) = (dir.path().join("traced.csv"), dir.path().join("plain.csv"));
    // `twinbench run FMU --interface model-exchange EXTRA`, which must succeed.
    let run_me = |extra: &[&OsStr]| {
        let me = args!["run", fmu, "--interface", "model-exchange"];
        common::run_ok(me.iter().chain(extra));
    };
    run_me(&args!["--trace-fmi", trace, "-o", traced]);
    run_me(&args!["-o", plain]);
    assert_eq!(
        std::fs::read(&traced).unwrap(),
        std::fs::read(&plain).unwrap()
    );
    let text = std::fs::read_to_string(&trace).unwrap();
    for call in [
        "fmi2Instantiate(",
        // As FMPy's Model Exchange loop: no tolerance unless the run gives one.
        "fmi2SetupExperiment(toleranceDefined=false, startTime=0.0",
        "fmi2ExitInitializationMode(",
        "fmi2SetTime(time=",
        "fmi2SetContinuousStates([",
        "fmi2GetDerivatives([",
        "fmi2GetEventIndicators([",
        "fmi2GetContinuousStates([",
        "fmi2GetNominalsOfContinuousStates([",
        "fmi2CompletedIntegratorStep(noSetFMUStatePriorToCurrentPoint=true",
        "fmi2EnterEventMode()",
        "fmi2NewDiscreteStates(newDiscreteStatesNeeded=false",
        "fmi2EnterContinuousTimeMode()",
        "fmi2GetReal(",
    ] {
        assert!(
            text.contains(call),
            "no {call} in the trace:\n{}",
            &text[..text.len().min(3000)]
        );
    }
    assert!(
        !text.contains("fmi2DoStep"),
        "an fmi2DoStep in a Model Exchange trace"
    );
    // BouncingBall's eleven bounces (and none more): event mode entered once for each.
    let bounces = text.matches("fmi2EnterEventMode()").count();
    assert!((11..=12).contains(&bounces), "{bounces} events");
    // A line: the instance's time, its name, the call, its status.
    let line = text
        .lines()
        .find(|l| l.contains("fmi2GetDerivatives("))
        .unwrap();
    assert!(
        line.starts_with("t=") && line.contains(" BouncingBall: "),
        "{line}"
    );
    assert!(line.ends_with(") -> fmi2OK"), "{line}");
    // With a tolerance the FMU is told it.
    run_me(&args!["--tolerance", "1e-7", "--trace-fmi", trace]);
    let text = std::fs::read_to_string(&trace).unwrap();
    assert!(
        text.contains("fmi2SetupExperiment(toleranceDefined=true, tolerance=1e-7, startTime=0.0"),
        "{}",
        &text[..text.len().min(2000)]
    );
}
