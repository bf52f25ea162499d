//! `twinbench run model.fmu`: one FMU on its own as `fmpy simulate` runs it (default
//! experiment, every output in FMPy's column order, an input file by column names, start
//! values), checked against `fmpy simulate` itself on the Reference FMUs; and FMI 3.0
//! arrays recorded and connected by their names in a system.

mod common;

use common::cli::succeeded;
use common::reference;
use std::path::Path;
use std::process::Command;
use tb_testkit::assert_contains;

/// `fmpy simulate FMU --output-file OUT [extra]`.
fn fmpy_simulate(dir: &Path, fmu: &Path, out: &str, extra: &[&str]) {
    let o = Command::new(common::python::python())
        .current_dir(dir)
        .args(["-m", "fmpy.cli", "simulate"])
        .arg(fmu)
        .args(["--output-file", out])
        .args(extra)
        .output()
        .unwrap();
    succeeded(&o, "fmpy simulate");
}

/// FMPy's CSV: the header, then rows of numbers; True/False as 1/0; an array's values in
/// one field separated by spaces, spread here into one number per element.
fn read_fmpy(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(|h| h.trim_matches('"').to_string())
        .collect();
    let rows: Vec<Vec<Vec<f64>>> = lines
        .map(|l| {
            l.split(',')
                .map(|f| {
                    f.split(' ')
                        .map(|x| match x {
                            "True" => 1.0,
                            "False" => 0.0,
                            x => x.parse().unwrap(),
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    // An array column `y` of n values is y[1] … y[n] in twinbench.
    let mut names = Vec::new();
    for (k, h) in header.iter().enumerate() {
        match rows[0][k].len() {
            1 => names.push(h.clone()),
            n => names.extend((1..=n).map(|i| format!("{h}[{i}]"))),
        }
    }
    let rows = rows.into_iter().map(|r| r.concat()).collect();
    (names, rows)
}

/// twinbench's result: the header and the numbers (the units row skipped).
fn read_ours(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let t = tb_table::Table::read_path(path).unwrap();
    let names = t.names().to_vec();
    let rows = (0..t.len())
        .map(|r| t.columns().iter().map(|c| c[r]).collect())
        .collect();
    (names, rows)
}

/// Our CSV `ours` against FMPy's `theirs` of `model`: the same columns and rows, each value
/// within `tol(column)` relative (to a magnitude of at least 1). Our rows and the largest
/// relative difference.
fn compare(
    model: &str,
    ours: &Path,
    theirs: &Path,
    tol: impl Fn(&str) -> f64,
) -> (Vec<Vec<f64>>, f64) {
    let (n1, r1) = read_ours(ours);
    let (n2, r2) = read_fmpy(theirs);
    assert_eq!(n1, n2, "{model}: columns");
    assert_eq!(r1.len(), r2.len(), "{model}: rows");
    let mut worst: f64 = 0.0;
    for (k, (a, b)) in r1.iter().zip(&r2).enumerate() {
        for (c, (x, y)) in a.iter().zip(b).enumerate() {
            let d = (x - y).abs() / y.abs().max(1.0);
            worst = worst.max(d);
            assert!(
                d <= tol(&n1[c]),
                "{model}: row {k}, {}: twinbench {x}, FMPy {y}",
                n1[c]
            );
        }
    }
    (r1, worst)
}

/// The same columns, rows and values (Float32 values to a float's precision: FMPy writes
/// them as float32, twinbench as the double they widen to).
fn assert_same(model: &str, ours: &Path, theirs: &Path) -> f64 {
    let tol = |column: &str| {
        if column.starts_with("Float32") {
            1e-7
        } else {
            1e-13
        }
    };
    compare(model, ours, theirs, tol).1
}

fn models(version: u8) -> Vec<&'static str> {
    let mut m = reference::FMI2_MODELS.to_vec();
    if version == 3 {
        m.extend(["Roberts", "StateSpace"]);
    }
    m
}

#[test]
fn each_reference_fmu_alone_gives_fmpy_simulates_columns_and_values() {
    let dir = tb_testkit::scratch("run-fmu");
    for version in [2u8, 3] {
        for model in models(version) {
            let fmu = reference::fmu(model, version);
            let ours = format!("{model}{version}.csv");
            let theirs = format!("{model}{version}.fmpy.csv");
            // Roberts' default experiment runs to 1e8 s at an internal step of 1e-3 s (days,
            // in any host): both stop at 1 s. Its variable-step solver sees the step sizes
            // FMPy passes (t[n+1] - t[n]) with the grid convention (docs/cross_validation.md).
            let (stop, fmpy_stop): (&[&str], &[&str]) = match model {
                "Roberts" => (
                    &["--stop", "1", "--step-convention", "grid"],
                    &["--stop-time", "1"],
                ),
                _ => (&[], &[]),
            };
            let mut args = vec!["run", fmu.to_str().unwrap(), "--out", &ours];
            args.extend(stop);
            let o = common::twinbench_in(dir.path(), &args);
            succeeded(&o, model);
            // The same summary as a system's run.
            let summary = String::from_utf8_lossy(&o.stdout);
            assert!(summary.contains("stopped by      "), "{summary}");
            fmpy_simulate(dir.path(), &fmu, &theirs, fmpy_stop);
            let worst = assert_same(
                &format!("{model} (FMI {version})"),
                &dir.path().join(&ours),
                &dir.path().join(&theirs),
            );
            println!("{model} (FMI {version}): largest relative difference from FMPy {worst:e}");
        }
    }
}

/// Through Model Exchange with event rows (`--interface model-exchange --record-events`),
/// each FMI 2.0 Reference FMU gives `fmpy simulate --interface-type ModelExchange`'s rows: the
/// output points and, at each event, a row before and after it (FMPy's `record_events`,
/// its default), with the values of FMPy's CVode to round-off (1e-11 relative).
#[test]
fn each_reference_fmu_as_model_exchange_with_event_rows_gives_fmpy_simulates_rows() {
    let dir = tb_testkit::scratch("run-fmu-me");
    let mut rows_with_events = 0;
    for model in reference::FMI2_MODELS {
        let fmu = reference::fmu(model, 2);
        let ours = format!("{model}.me.csv");
        let theirs = format!("{model}.me.fmpy.csv");
        // `twinbench run FMU --interface model-exchange [--record-events] --out OUT`.
        let run_me = |record_events: &[&str], out: &str| {
            let fmu = fmu.to_str().unwrap();
            let mut args = vec!["run", fmu, "--interface", "model-exchange"];
            args.extend(record_events);
            args.extend(["--out", out]);
            common::ok_in(dir.path(), args);
        };
        run_me(&["--record-events"], &ours);
        fmpy_simulate(
            dir.path(),
            &fmu,
            &theirs,
            &["--interface-type", "ModelExchange"],
        );
        let (r1, worst) = compare(
            model,
            &dir.path().join(&ours),
            &dir.path().join(&theirs),
            |_| 1e-11,
        );
        // Rows at one time twice: an event's left and right limits.
        let times: Vec<f64> = r1.iter().map(|r| r[0]).collect();
        let events = times.windows(2).filter(|w| w[0] == w[1]).count();
        rows_with_events += events;
        println!("{model} (Model Exchange, event rows): {} rows, {events} at events, largest relative difference from FMPy {worst:e}", r1.len());
        // Without --record-events: the output points only.
        let plain = format!("{model}.me.plain.csv");
        run_me(&[], &plain);
        let (_, r3) = read_ours(&dir.path().join(&plain));
        assert!(
            r3.windows(2).all(|w| w[1][0] > w[0][0]),
            "{model}: a time twice without event rows"
        );
    }
    // BouncingBall's bounces and Stair's steps are there.
    assert!(
        rows_with_events >= 10,
        "{rows_with_events} event rows in all"
    );
}

/// Feedthrough's inputs from a file in FMPy's format (a time column, one column per input,
/// no units; a repeated time is a step) and a start value, with an output interval of
/// their own (FMPy's communication step, as alone it is twinbench's).
#[test]
fn an_input_file_start_values_and_intervals_as_in_fmpy() {
    let input = "time,Float64_continuous_input,Int32_input,Boolean_input\n0,0,1,0\n0.5,1,1,0\n0.5,1,3,1\n1,-2,3,1\n";
    let dir = common::scratch_with("run-fmu-input", &[("in.csv", input)]);
    let fmu = reference::fmu("Feedthrough", 2);
    let f = fmu.to_str().unwrap();
    let o = common::twinbench_in(
        dir.path(),
        [
            "run",
            f,
            "--input",
            "in.csv",
            "--set",
            "Float64_fixed_parameter=2.5",
            "--stop",
            "1",
            "--output-interval",
            "0.05",
            "--out",
            "ours.csv",
        ],
    );
    succeeded(&o, "run with --input");
    fmpy_simulate(
        dir.path(),
        &fmu,
        "theirs.csv",
        &[
            "--input-file",
            "in.csv",
            "--start-values",
            "Float64_fixed_parameter",
            "2.5",
            "--stop-time",
            "1",
            "--output-interval",
            "0.05",
        ],
    );
    let (n, rows) = read_ours(&dir.path().join("ours.csv"));
    assert_eq!(rows.len(), 21, "every 0.05 s over 1 s");
    assert_same(
        "Feedthrough with inputs",
        &dir.path().join("ours.csv"),
        &dir.path().join("theirs.csv"),
    );
    // The inputs reached the outputs: the Int32 steps from 1 to 3 at 0.5 s.
    let k = n.iter().position(|c| c == "Int32_output").unwrap();
    assert_eq!((rows[9][k], rows[11][k]), (1.0, 3.0));
}

#[test]
fn what_does_not_fit_is_refused_with_the_reason() {
    let dir = tb_testkit::scratch("run-fmu-refused");
    let fmu = reference::fmu("Feedthrough", 2);
    let f = fmu.to_str().unwrap();
    let refused = |args: &[&str]| common::fails_in(dir.path(), args);
    // A column that is no input: the closest inputs named.
    std::fs::write(
        dir.path().join("bad.csv"),
        "time,Float64_continous_input\n0,1\n1,1\n",
    )
    .unwrap();
    let e = refused(&["run", f, "--input", "bad.csv"]);
    assert_contains(&e, &["column 'Float64_continous_input' is no variable of the FMU; its inputs: Float64_continuous_input"]);
    std::fs::write(
        dir.path().join("out.csv"),
        "time,Float64_continuous_output\n0,1\n1,1\n",
    )
    .unwrap();
    let e = refused(&["run", f, "--input", "out.csv"]);
    assert_contains(
        &e,
        &["column 'Float64_continuous_output' is continuous output, not an input"],
    );
    // A stop before the start; an output interval that is not whole steps.
    let e = refused(&["run", f, "--start", "2", "--stop", "1"]);
    assert_contains(&e, &["would end at 1 s, not after its start at 2 s"]);
    let e = refused(&["run", f, "--step", "0.3", "--output-interval", "0.5"]);
    assert_contains(
        &e,
        &["--output-interval 0.5 is not a whole number of steps of 0.3 s"],
    );
    // FMU options with a system file.
    let sys = dir.path().join("s.toml");
    std::fs::write(&sys, "").unwrap();
    let e = refused(&["run", sys.to_str().unwrap(), "--stop", "1"]);
    assert!(e.contains("--stop is for running one FMU"), "{e}");
}

/// FMI 3.0 arrays in a system: StateSpace's output vector y into another StateSpace's
/// input vector u by their names, recorded by name; an element where an array is meant
/// gets a message naming the elements.
#[test]
fn arrays_are_recorded_and_connected_by_their_names() {
    let dir = tb_testkit::scratch("arrays");
    let fmu = reference::fmu("StateSpace", 3);
    let system = |connection: &str| {
        common::system_file(
            &dir.path().join("ss.toml"),
            &format!("connections = [{connection:?}]\n"),
            &[("ss", &fmu)],
            "[[instance]]\nname = \"a\"\nfmu = \"ss\"\n\n[[instance]]\nname = \"b\"\nfmu = \"ss\"\n\n[experiment]\nstep = 0.1\nstop = 1\n\n[record]\nsignals = [\"a.y\", \"b.y\"]\n",
        )
    };
    let sys = system("a.y -> b.u");
    common::ok_in(dir.path(), args!["run", sys, "--out", "arrays.csv"]);
    let (names, rows) = read_ours(&dir.path().join("arrays.csv"));
    assert_eq!(
        names,
        ["time", "a.y[1]", "a.y[2]", "a.y[3]", "b.y[1]", "b.y[2]", "b.y[3]"]
    );
    // y = C x + D u with C = D = I and x(0) = 0: a's y starts at its u = (1, 2, 3), and b,
    // driven by a's y, starts at the same.
    assert_eq!(&rows[0][1..], &[1.0, 2.0, 3.0, 1.0, 2.0, 3.0]);
    // b's input follows a's output, so b grows faster than a (its u grows too).
    let last = rows.last().unwrap();
    for i in 1..=3 {
        assert!(
            last[3 + i] > last[i],
            "b.y[{i}] {} vs a.y[{i}] {}",
            last[3 + i],
            last[i]
        );
    }
    let sys = system("a.y[1] -> b.u");
    let e = common::fails_in(dir.path(), args!["run", sys]);
    assert_contains(
        &e,
        &["'b.u' is an array of 3 elements", "'b.u[1]' … 'b.u[3]'"],
    );
}
