//! The compiled plan: exchange slots and their readers, the stepping order, the recording,
//! parameters (types, ranges, Enumerations, paths), port maps, the backends chosen, and the
//! checks after initialisation.

mod support;

use std::sync::Arc;
use support::kinds::invalid;
use support::{column, instances, last, texts, Bench};
use tb_cosim::plan::{Cadence, Plan};
use tb_cosim::{LoadOptions, ParamValue, Simulation, SystemError};
use tb_fmi::FmuError;
use tb_testkit::assert_contains;

/// integrator (u = 0.5) -> g1 -> g2, h = 1/8, four steps.
fn chain() -> String {
    let instances = support::chain_instances();
    format!(
        r#"connections = ["int.x -> g1.u", "g1.y -> g2.u"]

{instances}[parameters]
"int.u" = 0.5

[experiment]
step = 0.125
stop = "int.steps >= 4"

[record]
signals = ["g2.y", "int.x"]
"#
    )
}

#[test]
fn the_stepping_order_puts_sources_before_their_consumers() {
    let b = Bench::new();
    let plan = b.plan(&chain()).unwrap();
    let names: Vec<&str> = plan.order.iter().map(|&k| plan.unit_name(k)).collect();
    assert_eq!(names, ["int", "g1", "g2"]);
    // Declaration order breaks ties: unconnected units keep theirs.
    let plan = b
        .plan("[[instance]]\nname = \"b\"\nfmu = \"gain\"\n[[instance]]\nname = \"a\"\nfmu = \"gain\"\n[experiment]\nstep = 1.0\nstop = 1.0\n")
        .unwrap();
    assert_eq!(plan.order, [0, 1]);
}

#[test]
fn each_source_has_one_slot_whoever_reads_it() {
    let b = Bench::new();
    let plan = b.plan(&chain()).unwrap();
    // int.x (connection, record), g1.y (connection), g2.y (record), int.steps (stop).
    let names: Vec<&str> = plan
        .signals
        .signals
        .iter()
        .map(|s| s.name.as_str())
        .collect();
    assert_eq!(names, ["int.x", "g1.y", "g2.y", "int.steps"]);
    assert_eq!(plan.record, [2, 0]);
    assert_eq!(plan.signals.signals[0].unit, "m");
    assert_eq!(plan.connections[0].from_slot, 0);
    assert_eq!(plan.connections[1].from_slot, 1);
}

#[test]
fn readers_declare_what_they_read_and_when() {
    let b = Bench::new();
    let plan = b.plan(&chain()).unwrap();
    let readers: Vec<(&str, &[usize], Cadence)> = plan
        .readers
        .iter()
        .map(|r| (r.what, r.slots.as_slice(), r.cadence))
        .collect();
    assert_eq!(
        readers,
        [
            ("connections", &[0, 1][..], Cadence::EveryStep),
            ("stop condition", &[3][..], Cadence::EveryStep),
            ("replay distance basis", &[][..], Cadence::EveryStep),
            ("recording", &[2, 0][..], Cadence::Recorded),
        ]
    );
    // g2.y is read only for the recording: not after every step.
    assert_eq!(plan.read_every_step(), [true, true, false, true]);
}

#[test]
fn without_a_record_list_every_output_is_recorded() {
    let b = Bench::new();
    let text = chain().replace("[record]\nsignals = [\"g2.y\", \"int.x\"]\n", "");
    let plan = b.plan(&text).unwrap();
    assert_eq!(plan.record_names, ["g2.y", "g1.y", "int.x", "int.steps"]);
    let (names, units) = plan.record_columns();
    assert_eq!(names, ["time", "g2.y", "g1.y", "int.x", "int.steps"]);
    assert_eq!(units, ["s", "", "", "m", ""]);
}

#[test]
fn a_name_is_recorded_once() {
    let b = Bench::new();
    for signals in ["\"int.x\", \"int.x\"", "\"time\""] {
        let text = chain().replace("\"g2.y\", \"int.x\"", signals);
        assert_contains(
            &b.error(&text),
            &["is listed twice (a result file has one column per name)"],
        );
    }
}

/// A sink with the given parameters, recording what it makes of them.
fn sink(parameters: &str) -> String {
    format!(
        r#"
[[instance]]
name = "snk"
fmu = "sink"

[parameters]
{parameters}

[experiment]
step = 0.5
stop = 0.5

[record]
signals = ["snk.limit_out", "snk.level_out", "snk.mode_out", "snk.on_out", "snk.text_out", "snk.file_lines"]
"#
    )
}

#[test]
fn parameters_are_typed_once_and_reach_the_model() {
    let b = Bench::new();
    let text = sink(
        "\"snk.limit\" = 4\n\"snk.level\" = 5\n\"snk.mode\" = 3\n\"snk.invert\" = true\n\"snk.name\" = \"tag\"",
    );
    let plan = b.plan(&text).unwrap();
    let values: Vec<(&str, &ParamValue)> = plan
        .parameters
        .iter()
        .map(|(s, v)| (s.name.as_str(), v))
        .collect();
    // In the system file's (sorted) order; an integer literal for a Real is a Real.
    assert_eq!(
        values,
        [
            ("snk.invert", &ParamValue::Boolean(true)),
            ("snk.level", &ParamValue::Integer(5)),
            ("snk.limit", &ParamValue::Real(4.0)),
            ("snk.mode", &ParamValue::Integer(3)),
            ("snk.name", &ParamValue::String("tag".into())),
        ]
    );
    let mode = plan.parameter("snk.mode").unwrap();
    assert_eq!(
        mode.items.unwrap(),
        [
            ("eco".to_string(), 1),
            ("normal".to_string(), 2),
            ("sport".to_string(), 3)
        ]
    );
    let (sim, _) = b.run(&text);
    assert_eq!(last(&sim, "snk.limit_out"), 4.0);
    assert_eq!(last(&sim, "snk.level_out"), 5.0);
    assert_eq!(last(&sim, "snk.mode_out"), 3.0);
    assert_eq!(last(&sim, "snk.on_out"), 1.0);
    assert_eq!(texts(&sim, "snk.text_out").last().unwrap(), "tag:");
}

#[test]
fn parameter_values_are_checked_against_type_range_and_items() {
    let cases = [
        (
            "\"snk.limit\" = 10.5",
            "10.5 is outside the declared range [0, 10] of 'snk.limit'",
        ),
        (
            "\"snk.limit\" = -1",
            "-1 is outside the declared range [0, 10] of 'snk.limit'",
        ),
        (
            "\"snk.level\" = 6",
            "6 is outside the declared range [0, 5] of 'snk.level'",
        ),
        (
            "\"snk.level\" = 1.5",
            "'snk.level' is Integer, the value 1.5 is not",
        ),
        (
            "\"snk.level\" = 3000000000",
            "3000000000 does not fit the 32-bit Integer 'snk.level'",
        ),
        (
            "\"snk.mode\" = 4",
            "4 is not an item of the Enumeration 'snk.mode' (1 'eco', 2 'normal', 3 'sport')",
        ),
        (
            "\"snk.invert\" = 1",
            "'snk.invert' is Boolean, the value 1 is not",
        ),
        (
            "\"snk.name\" = 1.0",
            "'snk.name' is String, the value 1.0 is not",
        ),
        (
            "\"snk.limit\" = \"fast\"",
            "'snk.limit' is Real, the value \"fast\" is not",
        ),
        (
            "\"snk.limit\" = 9007199254740993",
            "9007199254740993 cannot be carried exactly as a double",
        ),
    ];
    Bench::new().refuses(&cases, &["parameter \"snk."], sink);
}

#[test]
fn only_parameters_and_inputs_of_known_variables_can_be_set() {
    let cases = [
        (
            "\"snk.v_out\" = 1.0",
            "'snk.v_out' is continuous output; only parameters and inputs can be set",
        ),
        ("\"snk.limt\" = 1.0", "unknown variable 'snk.limt' (FMU"),
        (
            "\"nope.limit\" = 1.0",
            "unknown instance 'nope'; instances: snk",
        ),
        ("\"limit\" = 1.0", "expected \"instance.variable\""),
    ];
    let b = Bench::new();
    b.refuses(&cases, &[], sink);
    // The closest names are offered.
    assert_contains(
        &b.error(&sink("\"snk.limt\" = 1.0")),
        &["closest names: limit"],
    );
}

#[test]
fn a_file_parameter_is_relative_to_the_system_file_that_sets_it() {
    let b = Bench::new();
    b.write("lap/data/lines.txt", "a\nb\nc\n");
    let path = b.system_named(
        "lap/system.toml",
        &sink("\"snk.data_file\" = \"data/lines.txt\""),
    );
    let plan = b.load(&path).unwrap();
    let file = b.path("lap/data/lines.txt");
    assert_eq!(
        plan.parameters[0].1,
        ParamValue::String(file.display().to_string())
    );
    assert!(plan.parameters[0].0.is_path);
    assert!(
        plan.input_files().contains(&file),
        "{:?}",
        plan.input_files()
    );
    let mut sim = support::quiet(Simulation::new(plan).unwrap());
    sim.run().unwrap();
    assert_eq!(last(&sim, "snk.file_lines"), 3.0);
    // A String that is not a `_file` is passed as it is.
    let plan = b.plan(&sink("\"snk.name\" = \"data/lines.txt\"")).unwrap();
    assert_eq!(
        plan.parameters[0].1,
        ParamValue::String("data/lines.txt".into())
    );
    assert!(!plan.parameters[0].0.is_path);
}

#[test]
fn a_parameter_set_between_runs_is_checked_and_used() {
    let b = Bench::new();
    let mut sim = b.sim(&sink(""));
    assert_eq!(sim.parameter("snk.limit"), Some(1.0));
    sim.set_parameter("snk.limit", toml::Value::Float(2.5))
        .unwrap();
    sim.set_parameter("snk.mode", toml::Value::Integer(2))
        .unwrap();
    assert_eq!(sim.parameter("snk.limit"), Some(2.5));
    let e = sim
        .set_parameter("snk.limit", toml::Value::Float(11.0))
        .unwrap_err();
    assert!(invalid(&e, "parameter \"snk.limit\""), "{e}");
    assert_contains(&e.to_string(), &["outside the declared range"]);
    let e = sim
        .set_parameter("snk.mode", toml::Value::Integer(9))
        .unwrap_err();
    assert!(invalid(&e, "parameter \"snk.mode\""), "{e}");
    assert_contains(
        &e.to_string(),
        &["9 is not an item of the Enumeration 'snk.mode'"],
    );
    sim.run().unwrap();
    assert_eq!(last(&sim, "snk.limit_out"), 2.5);
    assert_eq!(last(&sim, "snk.mode_out"), 2.0);
    // A connected input would be overwritten at once: the plan names its connection.
    let plan = b.plan(&chain()).unwrap();
    let slot = plan.parameter("g1.u").unwrap();
    assert_eq!(
        plan.driving_connection(&slot).unwrap().text,
        "int.x -> g1.u"
    );
    assert!(plan
        .driving_connection(&plan.parameter("g1.k").unwrap())
        .is_none());
}

#[test]
fn a_port_map_renames_an_fmus_variables_for_the_system() {
    let b = Bench::new();
    let text = r#"connections = ["int.position -> g.input"]

[[instance]]
name = "int"
fmu = "integrator"
ports = { position = "x", rate = "u" }

[[instance]]
name = "g"
fmu = "gain"
ports = { input = "u" }

[parameters]
"int.rate" = 2.0

[experiment]
step = 0.25
stop = 1.0

[record]
signals = ["int.position", "g.y"]
"#;
    let (sim, _) = b.run(text);
    assert_eq!(column(&sim, "int.position"), [0.0, 0.5, 1.0, 1.5, 2.0]);
    assert_eq!(last(&sim, "g.y"), 4.0);
    // A port map naming no variable of the FMU is refused where it is written.
    let e = b.error(&text.replace("rate = \"u\"", "rate = \"uu\""));
    assert_contains(
        &e,
        &[
            "port map of 'int'",
            "unknown variable 'int.uu'",
            "closest names: u",
        ],
    );
}

#[test]
fn an_unlinked_model_runs_as_an_fmu_and_a_description_only_fmu_cannot() {
    let b = Bench::new();
    let options = LoadOptions {
        native: true,
        native_models: vec![tb_cosim::native::NativeModel::of::<support::models::Gain>()],
        ..Default::default()
    };
    let plan = Plan::load_with(&b.system(&chain()), b.cache.clone(), &options).unwrap();
    assert_contains(
        &plan.warnings.join("\n"),
        &[
            "instance 'int' runs as an FMU: ",
            "model 'integrator' is not linked into twinbench (native models: gain)",
        ],
    );
    let kinds: Vec<&str> = plan.instances.iter().map(|i| i.factory.kind()).collect();
    assert_eq!(kinds, ["native", "native", "fmu"]);
    let mut sim = support::quiet(Simulation::new(plan).unwrap());
    let e = sim.run().unwrap_err();
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Load { path, .. }) if path.ends_with("integrator.fmu")),
        "{e:?}"
    );
    assert_contains(&e.to_string(), &["binaries/linux64/integrator.so"]);
}

#[test]
fn a_native_model_must_have_the_fmus_guid() {
    let b = Bench::new();
    let xml = support::description::<support::models::Gain>();
    let guid = fmu_export::description::guid::<support::models::Gain>();
    support::write_fmu(
        &b.path("fmu/gain.fmu"),
        &xml.replace(&guid, "{0-other}"),
        &[],
    );
    let plan = b.plan(&chain()).unwrap();
    assert_contains(
        &plan.warnings.join("\n"),
        &[
            "instance 'g2' runs as an FMU",
            "GUID {0-other} differs from the linked 'gain' model's",
        ],
    );
}

#[test]
fn an_ordinary_cache_refuses_fmus_without_a_binary() {
    let b = Bench::new();
    let cache = Arc::new(tb_fmi::FmuCache::persistent(&b.path("plain-cache")).unwrap());
    let e = Plan::load_with(&b.system(&chain()), cache, &support::options())
        .err()
        .expect("refused");
    assert!(
        matches!(e, SystemError::Fmu(FmuError::Archive { .. })),
        "{e:?}"
    );
    assert_contains(
        &e.to_string(),
        &[
            "no binaries/linux64/",
            "the FMU has no binary for this platform; it has no binaries at all",
        ],
    );
}

/// Two sources whose speeds differ by 0.1 in 36, and a check of them.
fn checked(check: &str) -> String {
    let instances = instances(&[("a", "source"), ("b", "source")]);
    format!(
        r#"{instances}[parameters]
"b.speed" = 36.1

[experiment]
step = 0.5
stop = 1.0

[[check]]
{check}
"#
    )
}

#[test]
fn checks_after_initialisation_pass_within_their_tolerance() {
    let b = Bench::new();
    // |36.1 − 36| / 36.1 = 0.277 %, within the default 0.5 %.
    let (_, summary) = b.run(&checked("equal = [\"a.y_kmh\", \"b.y_kmh\"]"));
    assert_eq!(summary.steps, 2);
    // An Integer and an Enumeration are numbers too.
    b.run(&checked(
        "equal = [\"a.count\", \"b.gear\"]\nrelative_tolerance = 1.0",
    ));
}

#[test]
fn a_failed_check_stops_the_run_before_the_first_step() {
    let b = Bench::new();
    let mut sim = b.sim(&checked(
        "equal = [\"a.y_kmh\", \"b.y_kmh\"]\nrelative_tolerance = 0.001\nwhy = \"the two laps differ\"",
    ));
    let e = sim.run().unwrap_err();
    assert!(matches!(e, SystemError::Stop(_)), "{e:?}");
    assert_contains(
        &e.to_string(),
        &[
            "check failed after initialisation: a.y_kmh = 36 and b.y_kmh = 36.1 differ by 0.277 % (at most 0.1 % allowed): the two laps differ",
        ],
    );
    assert!(sim.recording().is_empty());
}

#[test]
fn checks_that_cannot_be_evaluated_are_refused() {
    let cases = [
        ("equal = [\"a.y_kmh\"]", "`equal` needs two or more signals"),
        (
            "equal = [\"a.y_kmh\", \"a.label\"]",
            "'a.label' is not a numeric FMU variable",
        ),
        (
            "equal = [\"a.y_kmh\", \"b.y_kmh\"]\nrelative_tolerance = -0.1",
            "relative_tolerance must be a non-negative number, got -0.1",
        ),
        (
            "equal = [\"a.y_kmh\", \"c.y_kmh\"]",
            "unknown instance 'c'; instances: a, b",
        ),
    ];
    Bench::new().refuses(&cases, &["check 1"], checked);
}
