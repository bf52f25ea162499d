//! Replayed measurement channels: by time (linear, hold, the automatic choice per input, a
//! repeated time as a step, the ends held) and by a distance signal of the system; and the
//! replays refused.

mod support;

use support::{column, instances, Bench};
use tb_testkit::assert_contains;

/// A time replay `r` of `file` (with `extra` lines), `r.a -> g.u` (k = 2), h = 1/4.
fn by_time(extra: &str, start: f64, stop: f64) -> String {
    let instances = instances(&[("g", "gain")]);
    format!(
        r#"connections = ["r.a -> g.u"]

{instances}[[replay]]
name = "r"
file = "a.csv"
basis = "time"
{extra}

[experiment]
start = {start:?}
step = 0.25
stop = {stop:?}

[record]
signals = ["r.a", "g.y"]
"#
    )
}

/// a(t): 8·t up to 1, then 8 + 16·(t − 1) up to 2.
fn a(t: f64) -> f64 {
    if t <= 1.0 {
        8.0 * t
    } else {
        8.0 + 16.0 * (t - 1.0)
    }
}

#[test]
fn a_time_replay_interpolates_and_each_step_sees_the_value_at_its_start() {
    let b = Bench::new();
    b.write("a.csv", "time,a\n0,0\n1,8\n2,24\n");
    let (sim, _) = b.run(&by_time("", 0.0, 2.0));
    let (r, y) = (column(&sim, "r.a"), column(&sim, "g.y"));
    // Rows at t = k/4: the column at t (exact), the gain's output from the step that
    // started one row earlier (FMPy applies an input file so).
    assert_eq!(y[0], 0.0);
    for k in 0..=8 {
        let t = k as f64 * 0.25;
        assert_eq!(r[k], a(t), "row {k}");
        if k > 0 {
            assert_eq!(y[k], 2.0 * a(t - 0.25), "row {k}");
        }
    }
}

#[test]
fn a_held_replay_keeps_the_last_row_at_or_before() {
    let b = Bench::new();
    b.write("a.csv", "time,a\n0,0\n1,8\n2,24\n");
    let (sim, _) = b.run(&by_time("interpolation = \"hold\"", 0.0, 2.0));
    assert_eq!(
        column(&sim, "r.a"),
        [0.0, 0.0, 0.0, 0.0, 8.0, 8.0, 8.0, 8.0, 24.0]
    );
}

#[test]
fn a_repeated_time_is_a_step_and_the_ends_are_held() {
    let b = Bench::new();
    b.write("a.csv", "time,a\n0,1\n1,1\n1,5\n2,5\n");
    let (sim, _) = b.run(&by_time("", -0.5, 2.5));
    let r = column(&sim, "r.a");
    // Before the first row: the first value; from t = 1 on: the value after the step; past
    // the last row: the last value. Exact.
    let expected: Vec<f64> = (0..=12)
        .map(|k| {
            if -0.5 + k as f64 * 0.25 < 1.0 {
                1.0
            } else {
                5.0
            }
        })
        .collect();
    assert_eq!(r, expected.as_slice());
}

#[test]
fn auto_holds_the_inputs_that_are_not_continuous_reals() {
    let b = Bench::new();
    b.write("m.csv", "time,a,n,on\n0,0,0,0\n1,8,3,1\n");
    let text = r#"connections = ["m.a -> g.u", "m.n -> snk.n", "m.on -> snk.on"]

[[instance]]
name = "g"
fmu = "gain"

[[instance]]
name = "snk"
fmu = "sink"

[[replay]]
name = "m"
file = "m.csv"
basis = "time"

[experiment]
step = 0.25
stop = 1.0

[record]
signals = ["m.a", "m.n", "m.on", "snk.n_out", "snk.on_out"]
"#;
    let (sim, _) = b.run(text);
    // The Real input interpolated, the Integer and Boolean ones held (FMPy's rule).
    assert_eq!(column(&sim, "m.a"), [0.0, 2.0, 4.0, 6.0, 8.0]);
    assert_eq!(column(&sim, "m.n"), [0.0, 0.0, 0.0, 0.0, 3.0]);
    assert_eq!(column(&sim, "m.on"), [0.0, 0.0, 0.0, 0.0, 1.0]);
    let plan = sim.plan();
    assert_eq!(plan.replays[0].hold, [false, true, true]);
    // Without [record] every output and every replayed column is recorded.
    let plan = b
        .plan(&text.replace(
            "[record]\nsignals = [\"m.a\", \"m.n\", \"m.on\", \"snk.n_out\", \"snk.on_out\"]",
            "",
        ))
        .unwrap();
    let names = plan.record_names.clone();
    assert_eq!(&names[..2], ["g.y", "snk.v_out"]);
    assert_eq!(&names[names.len() - 3..], ["m.a", "m.n", "m.on"]);
}

#[test]
fn a_distance_replay_follows_a_signal_of_the_system() {
    let b = Bench::new();
    b.write(
        "lap.csv",
        "time,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr,distance,accel_pedal\n\
         0,1,1,1,1,1,0,0\n1,1,1,1,1,1,1,0.5\n2,1,1,1,1,1,2,1\n3,1,1,1,1,1,4,0\n",
    );
    let instances = instances(&[("g", "gain"), ("int", "integrator")]);
    let text = format!(
        r#"connections = ["lap.accel_pedal -> g.u"]

{instances}[[replay]]
name = "lap"
file = "lap.csv"
basis = "distance"
by = "int.x"
columns = ["accel_pedal"]

[parameters]
"int.u" = 1.0
"g.k" = 1.0

[experiment]
step = 0.25
stop = 4.5

[record]
signals = ["int.x", "lap.accel_pedal", "g.y"]
"#
    );
    let (sim, _) = b.run(&text);
    let plan = sim.plan();
    let order: Vec<&str> = plan.order.iter().map(|&k| plan.unit_name(k)).collect();
    assert_eq!(order, ["int", "lap", "g"]);
    let pedal = |x: f64| match x {
        x if x <= 1.0 => 0.5 * x,
        x if x <= 2.0 => 0.5 + 0.5 * (x - 1.0),
        x if x <= 4.0 => 1.0 - 0.5 * (x - 2.0),
        _ => 0.0,
    };
    let (x, p, y) = (
        column(&sim, "int.x"),
        column(&sim, "lap.accel_pedal"),
        column(&sim, "g.y"),
    );
    // The pedal at this step's distance, passed on within the step (Gauss-Seidel). Exact.
    for k in 0..x.len() {
        assert_eq!(x[k], k as f64 * 0.25);
        assert_eq!(p[k], pedal(x[k]), "row {k}");
        assert_eq!(y[k], p[k], "row {k}");
    }
    assert_eq!(plan.replay_basis[0], Some(plan.connections.len()));
    assert_eq!(plan.replays[0].units, ["1"]);
}

/// A system with a gain `g`, a sink `snk`, the replay table `replay` and `connection`.
fn with(replay: &str, connection: &str) -> String {
    format!(
        "connections = [{connection}]\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[[instance]]\nname = \"snk\"\nfmu = \"sink\"\n[[replay]]\n{replay}\n[experiment]\nstep = 0.5\nstop = 1.0\n"
    )
}

/// The files the refusals read.
fn files(b: &Bench) {
    b.write("a.csv", "time,a,label\n0,0.5,x\n1,2,y\n");
    b.write("back.csv", "time,a\n0,0\n2,1\n1,2\n");
    b.write("gears.csv", "time,gear\n0,1\n1,7\n");
    b.write(
        "lap.csv",
        "time,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr,distance,accel_pedal\n0,1,1,1,1,1,0,0\n1,1,1,1,1,1,1,0.5\n",
    );
}

#[test]
fn replayed_files_that_cannot_be_read_are_refused_with_the_line() {
    let b = Bench::new();
    files(&b);
    let cases = [
        (
            "name = \"r\"\nfile = \"lap.csv\"\nbasis = \"distance\"\ncolumns = [\"accel_pedal\"]",
            "basis = \"distance\" needs `by`",
        ),
        (
            "name = \"r\"\nfile = \"a.csv\"\nbasis = \"time\"\ncolumns = [\"zz\"]",
            "no column 'zz' in the file (columns: time, a, label)",
        ),
        (
            "name = \"r\"\nfile = \"a.csv\"\nbasis = \"time\"\ncolumns = [\"label\"]",
            "column 'label' is not numeric",
        ),
        (
            "name = \"r\"\nfile = \"back.csv\"\nbasis = \"time\"",
            "line 4: time 1 after 2: the time of an input file must not decrease",
        ),
        (
            "name = \"r\"\nfile = \"missing.csv\"\nbasis = \"time\"",
            "missing.csv",
        ),
    ];
    for (replay, expected) in cases {
        assert_contains(&b.error(&with(replay, "")), &["replay 'r'", expected]);
    }
}

#[test]
fn replay_names_must_be_distinct_column_heads() {
    let b = Bench::new();
    files(&b);
    let cases = [
        ("g", "replay name 'g' is also an instance name"),
        ("r.1", "replay name 'r.1' is empty, or contains a '.'"),
        (
            "r,1",
            "replay name 'r,1' is empty, or contains a '.', a quote, a separator",
        ),
    ];
    for (name, expected) in cases {
        let replay =
            format!("name = \"{name}\"\nfile = \"a.csv\"\nbasis = \"time\"\ncolumns = [\"a\"]");
        assert_contains(&b.error(&with(&replay, "")), &[expected]);
    }
}

#[test]
fn replayed_values_must_fit_the_inputs_they_drive() {
    let b = Bench::new();
    files(&b);
    let replay = "name = \"r\"\nfile = \"a.csv\"\nbasis = \"time\"\ncolumns = [\"a\"]";
    let cases = [
        (
            "\"r.a -> snk.n\"",
            "a.csv, row 1: value 0.5 is not a 32-bit integer for Integer 'snk.n'",
        ),
        (
            "\"r.a -> snk.on\"",
            "a.csv, row 1: value 0.5 is not 0 or 1 for the Boolean 'snk.on'",
        ),
        (
            "\"r.a -> snk.text\"",
            "type mismatch: 'r.a' is Real, 'snk.text' is String",
        ),
        (
            "\"g.y -> r.a\"",
            "'r.a' is a replayed channel; it cannot be an input",
        ),
    ];
    for (connection, expected) in cases {
        assert_contains(&b.error(&with(replay, connection)), &[expected]);
    }
    // A value that is no item of the Enumeration it drives.
    let e = b.error(&with(
        "name = \"r\"\nfile = \"gears.csv\"\nbasis = \"time\"",
        "\"r.gear -> snk.gear_in\"",
    ));
    assert_contains(
        &e,
        &["gears.csv, row 2: value 7 is not an item of the Enumeration 'snk.gear_in'"],
    );
}

#[test]
fn a_distance_must_be_a_number_of_an_fmu() {
    let b = Bench::new();
    files(&b);
    let distance = |by: &str| {
        format!(
            "{}[[instance]]\nname = \"src\"\nfmu = \"source\"\n[[replay]]\nname = \"r2\"\nfile = \"a.csv\"\nbasis = \"time\"\n",
            with(
                &format!("name = \"r\"\nfile = \"lap.csv\"\nbasis = \"distance\"\nby = \"{by}\"\ncolumns = [\"accel_pedal\"]"),
                ""
            )
        )
    };
    let e = b.error(&distance("src.label"));
    assert_contains(
        &e,
        &["replay 'r'", "'src.label' is a String, not a distance"],
    );
    let e = b.error(&distance("r2.a"));
    assert_contains(
        &e,
        &["replay 'r'", "a replay cannot be driven by another replay"],
    );
    let e = b.error(&distance("src.nope"));
    assert_contains(&e, &["unknown variable 'src.nope'"]);
}
