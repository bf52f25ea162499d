//! The stop condition: a time, or a signal crossing a threshold with each operator, the
//! older `stop = "lap"`, `max_time`, the reported values; and the condition refused when it
//! cannot be evaluated.

mod support;

use support::{column, instances, last, Bench};
use tb_cosim::plan::{Cadence, Op};
use tb_cosim::{Stop, SystemError};
use tb_testkit::assert_contains;

/// One integrator with rate `u` from 0, h = 1/8, and the given experiment lines.
fn integrator(u: f64, experiment: &str) -> String {
    let instances = instances(&[("int", "integrator")]);
    format!(
        r#"{instances}[parameters]
"int.u" = {u:?}

[experiment]
step = 0.125
{experiment}

[record]
signals = ["int.x", "int.steps"]
"#
    )
}

#[test]
fn a_stop_time_ends_the_run_there() {
    let b = Bench::new();
    let (sim, summary) = b.run(&integrator(1.0, "stop = 1.0"));
    assert_eq!(summary.steps, 8);
    assert_eq!(summary.simulated_time, 1.0);
    assert_eq!(summary.stopped_by, "stop time 1 s");
    assert_eq!(last(&sim, "int.x"), 1.0);
    assert!(matches!(sim.plan().stop, Stop::Time(t) if t == 1.0));
}

#[test]
fn each_operator_stops_at_the_first_step_where_it_holds() {
    let b = Bench::new();
    // x_k = ±k/8 exactly: ">=" and "<=" hold at the threshold (step 8), ">" and "<" one
    // step later.
    for (u, condition, steps) in [
        (1.0, "int.x >= 1", 8u64),
        (1.0, "int.x > 1", 9),
        (-1.0, "int.x <= -1", 8),
        (-1.0, "int.x < -1", 9),
    ] {
        let (sim, summary) = b.run(&integrator(u, &format!("stop = \"{condition}\"")));
        assert_eq!(summary.steps, steps, "{condition}");
        assert_eq!(summary.stopped_by, condition);
        assert_eq!(summary.simulated_time, steps as f64 / 8.0, "{condition}");
        assert_eq!(last(&sim, "int.x"), u * steps as f64 / 8.0, "{condition}");
    }
    // Every operator of the one list is covered above.
    assert_eq!(Op::symbols(), ">=, <=, >, <");
}

#[test]
fn a_condition_on_an_integer_output_is_compared_as_a_number() {
    let b = Bench::new();
    let (sim, summary) = b.run(&integrator(0.5, "stop = \"int.steps >= 5\""));
    assert_eq!(summary.steps, 5);
    assert_eq!(last(&sim, "int.steps"), 5.0);
}

#[test]
fn rows_stay_on_the_decimation_grid_when_a_condition_stops_the_run() {
    let b = Bench::new();
    let text =
        integrator(1.0, "stop = \"int.x >= 1\"").replace("[record]", "[record]\ndecimation = 3");
    let (sim, summary) = b.run(&text);
    assert_eq!(summary.steps, 8);
    // Rows at steps 0, 3, 6: the step that met the condition is not on the grid.
    assert_eq!(column(&sim, "time"), [0.0, 0.375, 0.75]);
}

#[test]
fn the_older_lap_spelling_is_a_condition() {
    let b = Bench::new();
    let text = integrator(
        1.0,
        "stop = \"lap\"\nlap_signal = \"int.steps\"\nlap_count = 3",
    );
    let (_, summary) = b.run(&text);
    assert_eq!(summary.steps, 3);
    assert_eq!(summary.stopped_by, "int.steps >= 3");
    let e = b.error(&integrator(1.0, "stop = \"lap\""));
    assert_contains(&e, &["stop = \"lap\" needs lap_signal"]);
}

#[test]
fn a_condition_that_never_holds_is_an_error_after_max_time() {
    let b = Bench::new();
    let mut sim = b.sim(&integrator(1.0, "stop = \"int.x < 0\"\nmax_time = 0.5"));
    let e = sim.run().unwrap_err();
    assert!(matches!(e, SystemError::Stop(_)), "{e:?}");
    assert_contains(
        &e.to_string(),
        &[
            "system.toml",
            "did not complete within max_time = 0.5 s",
            "the stop condition int.x < 0 never held (int.x = 0.5 at the end)",
        ],
    );
    // The steps up to max_time were recorded.
    assert_eq!(last(&sim, "time"), 0.5);
}

#[test]
fn the_stop_signal_is_read_every_step_even_when_not_recorded() {
    let b = Bench::new();
    let text = integrator(1.0, "stop = \"int.x >= 1\"").replace(
        "signals = [\"int.x\", \"int.steps\"]",
        "signals = [\"int.steps\"]\ndecimation = 100",
    );
    let (sim, summary) = b.run(&text);
    assert_eq!(summary.steps, 8);
    let plan = sim.plan();
    let Stop::When {
        condition,
        max_time,
    } = &plan.stop
    else {
        panic!("a condition")
    };
    assert_eq!(*max_time, 600.0);
    assert!(plan.read_every_step()[condition.slot]);
    let reader = plan
        .readers
        .iter()
        .find(|r| r.what == "stop condition")
        .unwrap();
    assert_eq!(
        (reader.slots.as_slice(), reader.cadence),
        (&[condition.slot][..], Cadence::EveryStep)
    );
}

#[test]
fn reported_signals_are_read_at_the_end_of_the_run() {
    let b = Bench::new();
    let text = integrator(
        0.5,
        "stop = \"int.steps >= 4\"\nreport = [\"int.x\", \"int.steps\"]",
    );
    let (_, summary) = b.run(&text);
    assert_eq!(
        summary.reported,
        [("int.x".to_string(), 0.25), ("int.steps".to_string(), 4.0)]
    );
    assert_eq!(summary.value("int.x"), Some(0.25));
    assert_eq!(summary.value("int.u"), None);
}

#[test]
fn conditions_that_cannot_be_evaluated_are_refused() {
    let cases = [
        (
            "stop = \"int.x = 1\"",
            "experiment.stop must be a time in s or a condition such as \"vehicle.lap >= 1\" (operators >=, <=, >, <), got \"int.x = 1\"",
        ),
        ("stop = \"int.x >= nan\"", "operators >=, <=, >, <"),
        ("stop = \"int.xx >= 1\"", "unknown variable 'int.xx'"),
        ("stop = \"nope.x >= 1\"", "unknown instance 'nope'; instances: int"),
        (
            "stop = \"int.x >= 1\"\nmax_time = 0.0",
            "experiment.max_time must be a positive number of seconds, got 0",
        ),
        (
            "stop = \"int.x >= 1\"\nmax_time = inf",
            "experiment.max_time must be a positive number of seconds, got inf",
        ),
    ];
    let b = Bench::new();
    b.refuses(&cases, &[], |experiment| integrator(1.0, experiment));
    // A String cannot be compared with a number.
    let e = b.error(
        "[[instance]]\nname = \"src\"\nfmu = \"source\"\n[experiment]\nstep = 0.5\nstop = \"src.label >= 1\"\n",
    );
    assert_contains(
        &e,
        &["'src.label' is a String; a stop condition compares a number"],
    );
}
