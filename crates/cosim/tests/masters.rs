//! The master algorithms over the test models: what each unit sees within a macro step
//! (Gauss-Seidel this step's values, Jacobi the last step's), the time base, initialisation
//! and reuse. Binary fractions make every value exact.

mod support;

use support::{assert_close, column, instances, last, texts, Bench};
use tb_cosim::master::{algorithm, Jacobi, MasterAlgorithm};
use tb_cosim::Algorithm;

/// integrator (u = 0.5, x0 = 1) -> g1 (k = 2) -> g2 (k = 3), h = 1/8, 16 steps.
fn chain(algorithm: &str) -> String {
    let instances = support::chain_instances();
    format!(
        r#"connections = ["int.x -> g1.u", "g1.y -> g2.u"]

{instances}[parameters]
"int.x0" = 1.0
"int.u" = 0.5
"g1.k" = 2.0
"g2.k" = 3.0

[experiment]
step = 0.125
stop = 2.0
algorithm = "{algorithm}"

[record]
signals = ["int.x", "g1.y", "g2.y"]
"#
    )
}

#[test]
fn an_integrator_of_a_constant_is_exact_over_n_steps() {
    let b = Bench::new();
    for algorithm in ["gauss-seidel", "jacobi"] {
        let (sim, summary) = b.run(&chain(algorithm));
        assert_eq!(summary.steps, 16);
        let x = column(&sim, "int.x");
        assert_eq!(x.len(), 17);
        for (k, &xk) in x.iter().enumerate() {
            // x_k = x0 + k·u·h, exactly (tolerance 0).
            assert_eq!(xk, 1.0 + k as f64 * 0.5 * 0.125, "{algorithm}, row {k}");
        }
    }
}

/// The chain run under `algorithm`: the columns int.x, g1.y and g2.y.
fn chain_columns(algorithm: &str) -> [Vec<f64>; 3] {
    let (sim, _) = Bench::new().run(&chain(algorithm));
    ["int.x", "g1.y", "g2.y"].map(|name| column(&sim, name).to_vec())
}

#[test]
fn gauss_seidel_feeds_this_steps_outputs_down_the_chain() {
    // Stepping order int, g1, g2 (the connections', not the declaration's): each gain
    // sees its source's value at the end of this step. Exact.
    let [x, y1, y2] = chain_columns("gauss-seidel");
    for k in 0..x.len() {
        assert_eq!(y1[k], 2.0 * x[k], "row {k}");
        assert_eq!(y2[k], 6.0 * x[k], "row {k}");
    }
}

#[test]
fn jacobi_feeds_every_unit_the_last_steps_outputs() {
    let [x, y1, y2] = chain_columns("jacobi");
    // Initialisation reaches the fixed point: the first row is consistent.
    assert_eq!((y1[0], y2[0]), (2.0, 6.0));
    // Then each gain lags its source by one step: g1 one, g2 two. Exact.
    assert_eq!(y1[1], 2.0 * x[0]);
    assert_eq!(y2[1], 6.0 * x[0]);
    for k in 2..x.len() {
        assert_eq!(y1[k], 2.0 * x[k - 1], "row {k}");
        assert_eq!(y2[k], 6.0 * x[k - 2], "row {k}");
    }
}

#[test]
fn an_explicit_order_makes_gauss_seidel_see_the_last_steps_values() {
    let b = Bench::new();
    let text = chain("gauss-seidel").replace(
        "algorithm = \"gauss-seidel\"",
        "algorithm = \"gauss-seidel\"\norder = [\"g2\", \"g1\", \"int\"]",
    );
    let (sim, _) = b.run(&text);
    let names: Vec<&str> = sim
        .plan()
        .order
        .iter()
        .map(|&k| sim.plan().unit_name(k))
        .collect();
    assert_eq!(names, ["g2", "g1", "int"]);
    // Consumers before their sources: each gain lags as under Jacobi. Exact.
    let (x, y2) = (column(&sim, "int.x"), column(&sim, "g2.y"));
    for k in 2..x.len() {
        assert_eq!(y2[k], 6.0 * x[k - 2], "row {k}");
    }
}

/// int.x -> g.u, g.y -> int.u with k = -1: x' = -x, h = 1/2.
fn decay(algorithm: &str) -> String {
    let instances = instances(&[("int", "integrator"), ("g", "gain")]);
    format!(
        r#"connections = ["int.x -> g.u", {{ from = "g.y", to = "int.u", scale = 1.0 }}]

{instances}[parameters]
"int.x0" = 1.0
"g.k" = -1.0

[experiment]
step = 0.5
stop = 5.0
algorithm = "{algorithm}"

[record]
signals = ["int.x", "g.y"]
"#
    )
}

#[test]
fn a_loop_through_an_integrator_halves_x_each_step_under_gauss_seidel() {
    let b = Bench::new();
    let (sim, _) = b.run(&decay("gauss-seidel"));
    // x_{k+1} = x_k + h·(−x_k) = x_k / 2: exactly 2^-k.
    for (k, &x) in column(&sim, "int.x").iter().enumerate() {
        assert_eq!(x, 0.5f64.powi(k as i32), "row {k}");
    }
}

#[test]
fn a_loop_through_an_integrator_under_jacobi_uses_the_delayed_feedback() {
    let b = Bench::new();
    let (sim, _) = b.run(&decay("jacobi"));
    // x_{k+1} = x_k − h·x_{k−1} (the gain's output is one step old), x_{−1} = x_0 from the
    // initialisation's fixed point. Exact in binary fractions.
    let mut expected = vec![1.0, 0.5];
    for k in 1..10 {
        let next = expected[k] - 0.5 * expected[k - 1];
        expected.push(next);
    }
    assert_eq!(column(&sim, "int.x"), expected.as_slice());
    assert_eq!(expected[3], -0.25);
}

#[test]
fn the_algorithm_can_be_changed_on_a_simulation() {
    let b = Bench::new();
    let mut sim = b.sim(&chain("gauss-seidel"));
    sim.set_algorithm(Box::new(Jacobi));
    sim.run().unwrap();
    let (x, y1) = (column(&sim, "int.x"), column(&sim, "g1.y"));
    assert_eq!(y1[5], 2.0 * x[4]);
    // The names are one list: the system file's, the master's.
    for a in Algorithm::ALL {
        assert_eq!(algorithm(a).name(), a.name());
        assert_eq!(Algorithm::from_name(a.name()), Ok(a));
    }
    assert_eq!(Jacobi.kind(), Algorithm::Jacobi);
    let e = Algorithm::from_name("newton").unwrap_err();
    assert!(matches!(&e, tb_cosim::config::UnknownName::Algorithm { name } if name == "newton"));
    assert_eq!(
        e.to_string(),
        "unknown algorithm \"newton\" (gauss-seidel, jacobi)"
    );
}

#[test]
fn the_last_step_is_clamped_to_the_stop_time() {
    let b = Bench::new();
    let text = chain("gauss-seidel").replace("stop = 2.0", "stop = 1.1");
    let (sim, summary) = b.run(&text);
    // Eight steps of 1/8 and one of 0.1 s.
    assert_eq!(summary.steps, 9);
    assert_eq!(summary.simulated_time, 1.1);
    assert_eq!(summary.stopped_by, "stop time 1.1 s");
    assert_eq!(last(&sim, "time"), 1.1);
    // x = 1 + 0.5·1.1, to rounding (tolerance 1e-15).
    assert_close(last(&sim, "int.x"), 1.55, 1e-15);
}

#[test]
fn the_tick_time_base_does_not_drift_from_a_nonzero_start() {
    let b = Bench::new();
    let text = r#"
[[instance]]
name = "src"
fmu = "source"

[experiment]
start = 0.5
step = 0.001
stop = 1.5

[record]
signals = ["src.t", "src.count"]
"#;
    let (sim, summary) = b.run(text);
    assert_eq!(summary.steps, 1000);
    let t = column(&sim, "time");
    // Every row is exactly start + k·h (no summed steps); the model's own time t + h agrees
    // to rounding (tolerance 1e-12).
    for (k, &tk) in t.iter().enumerate() {
        assert_eq!(tk, 0.5 + k as f64 * 0.001, "row {k}");
        assert_close(column(&sim, "src.t")[k], tk, 1e-12);
    }
    assert_eq!(last(&sim, "src.count"), 1000.0);
}

#[test]
fn integer_boolean_and_enumeration_outputs_feed_real_inputs() {
    let b = Bench::new();
    let instances = instances(&[
        ("src", "source"),
        ("gc", "gain"),
        ("gb", "gain"),
        ("ge", "gain"),
    ]);
    let text = format!(
        r#"connections = [
    "src.count -> gc.u",
    "src.odd -> gb.u",
    "src.gear -> ge.u",
]

{instances}[parameters]
"gc.k" = 0.5
"gb.k" = 3.0
"ge.k" = 1.0

[experiment]
step = 0.25
stop = 2.0

[record]
signals = ["src.count", "src.odd", "src.gear", "gc.y", "gb.y", "ge.y"]
"#
    );
    let (sim, _) = b.run(&text);
    for k in 0..=8 {
        let n = k as f64;
        assert_eq!(column(&sim, "src.count")[k], n);
        assert_eq!(column(&sim, "gc.y")[k], 0.5 * n, "row {k}");
        let odd = (k % 2) as f64;
        assert_eq!(column(&sim, "src.odd")[k], odd);
        assert_eq!(column(&sim, "gb.y")[k], 3.0 * odd, "row {k}");
        let gear = (1 + k % 3) as f64;
        assert_eq!(column(&sim, "ge.y")[k], gear, "row {k}");
    }
}

#[test]
fn strings_and_enumerations_are_exchanged_and_recorded() {
    let b = Bench::new();
    let instances = instances(&[("src", "source"), ("snk", "sink")]);
    let text = format!(
        r#"connections = ["src.label -> snk.text", "src.gear -> snk.gear_in"]

{instances}[parameters]
"src.prefix" = "lap "
"snk.name" = "got"

[experiment]
step = 0.5
stop = 2.0

[record]
signals = ["src.label", "snk.text_out", "snk.gear_out"]
"#
    );
    let (sim, _) = b.run(&text);
    assert_eq!(
        texts(&sim, "src.label"),
        ["lap 0", "lap 1", "lap 2", "lap 3", "lap 4"]
    );
    assert_eq!(
        texts(&sim, "snk.text_out"),
        [
            "got:lap 0",
            "got:lap 1",
            "got:lap 2",
            "got:lap 3",
            "got:lap 4"
        ]
    );
    assert_eq!(column(&sim, "snk.gear_out"), [1.0, 2.0, 3.0, 1.0, 2.0]);
    // In CSV, text is quoted.
    let csv = String::from_utf8(sim.recording().to_csv()).unwrap();
    assert!(csv.contains("\"lap 3\",\"got:lap 3\",1"), "{csv}");
}

#[test]
fn a_simulation_is_reused_bit_for_bit_and_takes_new_parameters() {
    let b = Bench::new();
    let mut sim = b.sim(&chain("jacobi"));
    sim.run().unwrap();
    let first = sim.recording().clone();
    sim.run().unwrap();
    assert_eq!(sim.recording().columns(), first.columns());
    sim.free_instances();
    sim.run().unwrap();
    assert_eq!(sim.recording().columns(), first.columns());
    // A parameter changed between runs is applied at the next initialisation.
    sim.set_parameter("g1.k", toml::Value::Float(4.0)).unwrap();
    assert_eq!(sim.parameter("g1.k"), Some(4.0));
    sim.run().unwrap();
    let (x, y1) = (column(&sim, "int.x"), column(&sim, "g1.y"));
    assert_eq!(y1[0], 4.0 * x[0]);
    assert_eq!(y1[16], 4.0 * x[15]);
}

#[test]
fn decimation_records_every_nth_step_and_the_stop_time() {
    let b = Bench::new();
    let text = chain("gauss-seidel").replace("[record]", "[record]\ndecimation = 4");
    let (sim, _) = b.run(&text);
    assert_eq!(column(&sim, "time"), [0.0, 0.5, 1.0, 1.5, 2.0]);
    // g2.y is read for the recording only (no connection reads it): at a recorded row it is
    // the value at that row's time, 6·x under Gauss-Seidel. Exact.
    let (x, y2) = (column(&sim, "int.x"), column(&sim, "g2.y"));
    for k in 0..x.len() {
        assert_eq!(y2[k], 6.0 * x[k], "row {k}");
    }
    assert_eq!(x, [1.0, 1.25, 1.5, 1.75, 2.0]);
    // A stop time off the grid adds its final row.
    let text = text.replace("stop = 2.0", "stop = 2.0625");
    let (sim, _) = b.run(&text);
    assert_eq!(column(&sim, "time"), [0.0, 0.5, 1.0, 1.5, 2.0, 2.0625]);
    assert_eq!(last(&sim, "int.x"), 1.0 + 2.0625 * 0.5);
}

#[test]
fn the_recording_has_a_units_row_from_the_descriptions() {
    let b = Bench::new();
    let (sim, _) = b.run(&chain("gauss-seidel"));
    assert_eq!(sim.recording().names(), ["time", "int.x", "g1.y", "g2.y"]);
    assert_eq!(sim.recording().units().unwrap(), ["s", "m", "", ""]);
    let csv = String::from_utf8(sim.recording().to_csv()).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("time,int.x,g1.y,g2.y"));
    assert_eq!(lines.next(), Some("s,m,,"));
    assert_eq!(lines.next(), Some("0,1,2,6"));
}
