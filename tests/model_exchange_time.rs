//! Red team, fourth pass (`docs/robustness.md`, "Red team findings"): the Model Exchange
//! integrator's time handling (M5–M7), each with an FMU of the suite's own
//! (`tests/cfmus/me_time.c`: x' = −x, x(0) = 1, and a time event chosen by `mode`).

mod common;

use common::cli::{failed, succeeded};
use std::ffi::OsStr;
use std::path::Path;
use std::process::{Command, Output};
use tb_testkit::assert_contains;

/// `twinbench run me_time.fmu --set mode=<mode> --start <start> --stop <stop>`: its output
/// and the last row (time, y, events) of the CSV when it wrote one.
fn run(dir: &Path, mode: i32, start: f64, stop: f64) -> (Output, Option<Vec<f64>>) {
    let csv = dir.join(format!("me_time_{mode}_{start}.csv"));
    // A run of 2 s of a one-state model takes milliseconds: one still going after 60 s
    // spins (M5), and is a failure, not a hung suite.
    let out = within_a_minute(
        Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .arg("run")
            .arg(common::cfmu::fmu("me_time"))
            .args(["--set", &format!("mode={mode}")])
            .args(["--start", &start.to_string(), "--stop", &stop.to_string()])
            .arg("--out")
            .arg(&csv),
    );
    let last = std::fs::read_to_string(&csv).ok().and_then(|t| {
        let header: Vec<String> = t.lines().next()?.split(',').map(String::from).collect();
        let row: Vec<f64> = t
            .lines()
            .last()?
            .split(',')
            .map(|v| v.parse().unwrap_or(f64::NAN))
            .collect();
        let at = |n: &str| header.iter().position(|h| h == n).map(|i| row[i]);
        Some(vec![at("time")?, at("y")?, at("events")?])
    });
    (out, last)
}

/// `twinbench run <the typed_vr FMU> --out OUT` and `more`: its output.
fn run_typed_vr(out: &Path, more: &[&OsStr]) -> Output {
    let fmu = common::cfmu::fmu("typed_vr");
    common::twinbench(args!["run", fmu, "--out", out].iter().chain(more))
}

/// The CSV twinbench wrote at `csv` and the values of its column `name` (the rows after
/// the header and units rows).
fn column(csv: &Path, name: &str) -> (String, Vec<f64>) {
    let text = std::fs::read_to_string(csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == name).unwrap();
    let values = text
        .lines()
        .skip(2)
        .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
        .collect();
    (text, values)
}

/// `cmd`'s output; a failure when it still runs after 60 s (a hang, not a benchmark: what
/// it runs takes well under a second).
fn within_a_minute(cmd: &mut Command) -> Output {
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // Both pipes drained while it runs (a long `info` fills a pipe and would wait on it).
    let drain = |r: Option<Box<dyn std::io::Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut r) = r {
                let _ = r.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let out = drain(child.stdout.take().map(|r| Box::new(r) as _));
    let err = drain(child.stderr.take().map(|r| Box::new(r) as _));
    let until = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > until {
            let _ = child.kill();
            panic!("{cmd:?} still runs after 60 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    Output {
        status,
        stdout: out.join().unwrap(),
        stderr: err.join().unwrap(),
    }
}

/// M5: a time event in the past (here at 0 s in a run from 1 s) is an error naming the
/// time, not a loop at 100 % CPU.
#[test]
fn m05_a_time_event_in_the_past_is_an_error_not_a_spin() {
    let dir = tb_testkit::scratch("m05");
    let (out, _) = run(dir.path(), 1, 1.0, 2.0);
    let err = failed(out, "the run");
    assert_contains(
        &err,
        &["nextEventTime = 0.0 s lies before the current time 1.0 s"],
    );
}

/// M6: nextEventTime = +inf is no event (the run equals the one without, one event at
/// initialisation); −inf is an error.
#[test]
fn m06_an_infinite_next_event_time_is_no_event_and_minus_infinity_an_error() {
    let dir = tb_testkit::scratch("m06");
    let (out, none) = run(dir.path(), 0, 0.0, 2.0);
    succeeded(&out, "the run");
    let (out, inf) = run(dir.path(), 2, 0.0, 2.0);
    succeeded(&out, "the run");
    let (none, inf) = (none.unwrap(), inf.unwrap());
    assert_eq!(inf, none, "+inf changed the run");
    assert_eq!(inf[2], 1.0, "events: {inf:?}");
    let (out, _) = run(dir.path(), 3, 0.0, 2.0);
    let err = failed(out, "the run");
    assert!(err.contains("nextEventTime = -inf is not a time"), "{err}");
}

/// M7: at a Unix-time start the integration is that of a start at 0: y(t0 + 2) = e^−2
/// within the solver's tolerance (a relative 1e-9 time comparison was 1.7 s wide there and
/// gave 0.49999; at 1e10 y stayed 1).
#[test]
fn m07_a_large_start_time_integrates_as_a_start_at_zero() {
    let dir = tb_testkit::scratch("m07");
    let exact = (-2.0f64).exp();
    for start in [0.0, 1.7e9, 1e10] {
        let (out, last) = run(dir.path(), 0, start, start + 2.0);
        succeeded(&out, format!("start {start}"));
        let last = last.unwrap();
        assert_eq!(last[0], start + 2.0);
        // The default relative tolerance 1e-4 of the solver, and the time's own resolution
        // at 1e10 s (2e-6 s): within 1e-3 of e^−2.
        assert!(
            (last[1] - exact).abs() < 1e-3 * exact,
            "start {start}: y = {} (e^-2 = {exact})",
            last[1]
        );
    }
}

/// M8: the time column's unit of an input file is converted (ms here) or, when it is not a
/// time, refused naming it; never read as seconds.
#[test]
fn m08_the_time_columns_unit_is_converted_or_refused() {
    let dir = tb_testkit::scratch("m08");
    let fmu = common::cfmu::fmu("typed_vr");
    let run = |input: &str, out: &str| {
        let file = dir.path().join(format!("{out}.in.csv"));
        std::fs::write(&file, input).unwrap();
        let csv = dir.path().join(format!("{out}.csv"));
        let args = args!["run", fmu, "--input", file, "--out", csv];
        let o = common::twinbench(args.iter().chain(&args!["--stop", "1", "--step", "0.25"]));
        (o, std::fs::read_to_string(&csv).unwrap_or_default())
    };
    // u rises from 0 to 1 over 1000 ms; u_echo shows the input of the step before.
    let (o, ms) = run("time,u\nms,\n0,0\n1000,1\n", "ms");
    succeeded(&o, "in ms");
    let (o, s) = run("time,u\ns,\n0,0\n1,1\n", "s");
    succeeded(&o, "in s");
    assert_eq!(ms, s, "the same input in ms and in s");
    assert!(s.lines().any(|l| l == "0.75,1.75,0.5,3,1"), "{s}");
    let (o, _) = run("time,u\nfurlong,\n0,0\n1000,1\n", "furlong");
    let err = failed(o, "in furlong");
    assert_contains(
        &err,
        &["the time column 'time' is in 'furlong', not a unit of time"],
    );
}

/// M17: input rows of ±1e308 (legal numbers) interpolate to finite values: their difference
/// overflowed to infinity and the NaN that followed was blamed on the FMU.
#[test]
fn m17_inputs_near_the_largest_number_interpolate_without_overflow() {
    let dir = tb_testkit::scratch("m17-huge");
    let file = dir.path().join("huge.in.csv");
    std::fs::write(&file, "time,u\n0,1e308\n1,-1e308\n").unwrap();
    let csv = dir.path().join("huge.csv");
    let more = args!["--input", file, "--set", "gain=0", "--stop", "1", "--step", "0.25"];
    succeeded(&run_typed_vr(&csv, &more), "the input of ±1e308");
    // u_echo is the input of the step before: 1e308 at 0.25 s, then 5e307, 0, -5e307.
    let (text, echoed) = column(&csv, "u_echo");
    assert_eq!(echoed[1..], [1e308, 5e307, 0.0, -5e307], "{text}");
}

/// M9: where a failed run would keep its rows (`<out>.incomplete.<ext>`) is checked before
/// the run like `--out`: an input of the run (here the --input file) or a folder there is
/// refused, and the input is left as it was.
#[test]
fn m09_the_incomplete_file_never_replaces_an_input() {
    let dir = tb_testkit::scratch("m09");
    let input = dir.path().join("r.incomplete.csv");
    let text = "time,u\n0,1\n1,2\n";
    std::fs::write(&input, text).unwrap();
    let fmu = common::cfmu::fmu("typed_vr");
    let err = common::fails(args![
        "run",
        fmu,
        "--input",
        input,
        "--out",
        dir.path().join("r.csv")
    ]);
    assert_contains(&err, &["where a failed run would keep its rows"]);
    assert_eq!(std::fs::read_to_string(&input).unwrap(), text);
    assert!(!dir.path().join("r.csv").exists());
    // A folder in that place: refused before the run, not a recording silently dropped.
    std::fs::create_dir(dir.path().join("d.incomplete.csv")).unwrap();
    let err = common::fails(args!["run", fmu, "--out", dir.path().join("d.csv")]);
    assert!(err.contains("d.incomplete.csv"), "{err}");
}

/// M12: a Model Exchange FMU with more continuous states than the dense solver takes is
/// refused before anything is integrated, saying why (15,000 states took 3.5 GB and 50 s
/// for 0.01 s).
#[test]
fn m12_too_many_states_for_the_dense_solver_are_refused_with_the_reason() {
    use std::io::Write;
    let dir = tb_testkit::scratch("m12");
    let n = 5000;
    let mut vars = String::new();
    for i in 0..n {
        vars.push_str(&format!(
            "<ScalarVariable name=\"x{i}\" valueReference=\"{i}\" causality=\"local\" variability=\"continuous\" initial=\"exact\"><Real start=\"1\"/></ScalarVariable>\n"
        ));
    }
    let mut ders = String::new();
    for i in 0..n {
        vars.push_str(&format!(
            "<ScalarVariable name=\"der(x{i})\" valueReference=\"{}\" causality=\"local\" variability=\"continuous\"><Real derivative=\"{}\"/></ScalarVariable>\n",
            n + i,
            i + 1
        ));
        ders.push_str(&format!("<Unknown index=\"{}\"/>", n + i + 1));
    }
    let xml = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<fmiModelDescription fmiVersion=\"2.0\" modelName=\"me_time\" guid=\"{{5a1e5e7c-0d7c-4c4e-9a61-7b3f0c1d2e07}}\" numberOfEventIndicators=\"0\">\n<ModelExchange modelIdentifier=\"me_time\"/>\n<ModelVariables>\n{vars}</ModelVariables>\n<ModelStructure><Derivatives>{ders}</Derivatives></ModelStructure>\n</fmiModelDescription>\n"
    );
    // The library of the suite's own ME FMU, taken from its archive.
    let mut library = Vec::new();
    {
        use std::io::Read;
        let f = std::fs::File::open(common::cfmu::fmu("me_time")).unwrap();
        let mut z = zip::ZipArchive::new(f).unwrap();
        z.by_name("binaries/linux64/me_time.so")
            .unwrap()
            .read_to_end(&mut library)
            .unwrap();
    }
    let fmu = dir.path().join("big.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&fmu).unwrap());
    let o = zip::write::SimpleFileOptions::default();
    zip.start_file("modelDescription.xml", o).unwrap();
    zip.write_all(xml.as_bytes()).unwrap();
    zip.start_file("binaries/linux64/me_time.so", o).unwrap();
    zip.write_all(&library).unwrap();
    zip.finish().unwrap();
    let big = dir.path().join("big.csv");
    let err = common::fails(args!["run", fmu, "--stop", "0.01", "--out", big]);
    assert_contains(&err, &["5000 continuous states", "at most 4000 states"]);
}

/// M11: an FMI 3.0 variable with 100,000 `<Alias>`es (VanDerPol's x0 here): `info` and a
/// run that records every name take linear time (they took 4.5 s and 49 s: a scan of the
/// variables per name). The deadline is a hang's, not a benchmark's.
#[test]
fn m11_a_hundred_thousand_fmi3_aliases_are_read_and_run_in_linear_time() {
    let dir = tb_testkit::scratch("m11");
    let vdp = common::reference::fmu("VanDerPol", 3);
    let aliases: String = (0..100_000)
        .map(|i| format!("<Alias name=\"x0_{i}\"/>"))
        .collect();
    let fmu = common::reference::with_description(&vdp, dir.path(), "vdp_aliases", |xml| {
        xml.replacen(
            "initial=\"exact\" start=\"2\"/>",
            &format!("initial=\"exact\" start=\"2\">{aliases}</Float64>"),
            1,
        )
    });
    let deadline =
        |args: &[&str]| within_a_minute(Command::new(env!("CARGO_BIN_EXE_twinbench")).args(args));
    let f = fmu.to_str().unwrap();
    succeeded(&deadline(&["info", f]), "info");
    let csv = dir.path().join("a.csv");
    succeeded(
        &deadline(&["run", f, "--stop", "0.1", "--out", csv.to_str().unwrap()]),
        "run",
    );
    let header = std::fs::read_to_string(&csv).unwrap();
    let header = header.lines().next().unwrap();
    // Every alias is a column, with the value of x0.
    assert!(
        header.contains(",x0_99999"),
        "{}",
        &header[..200.min(header.len())]
    );
}

/// M17: a NaN derivative is named as the FMU's (it only showed as CVODE's "t + h = t" or
/// CV_TOO_MUCH_WORK), and a NaN event indicator is an error, not an event silently missed.
#[test]
fn m17_a_nan_derivative_or_event_indicator_is_named_as_the_fmus() {
    let dir = tb_testkit::scratch("m17-nan");
    let err = failed(run(dir.path(), 4, 0.0, 2.0).0, "mode 4");
    assert_contains(
        &err,
        &["since fmi2GetDerivatives returned NaN for der(x) at t = 0.5"],
    );
    let err = failed(run(dir.path(), 5, 0.0, 2.0).0, "mode 5");
    assert_contains(
        &err,
        &["fmi2GetEventIndicators returned NaN for event indicator 1 of 1"],
    );
}

/// M17: a single FMU's `--set Instance.variable` (as in a system) names the variable, not
/// `Instance.Instance.variable`; `cache prune` with a size that is none is refused even
/// when there is no store yet.
#[test]
fn m17_a_single_fmus_instance_prefix_and_a_bad_prune_size() {
    let dir = tb_testkit::scratch("m17-set");
    let csv = dir.path().join("y.csv");
    let run = |set: &str| {
        run_typed_vr(
            &csv,
            &args!["--stop", "0.5", "--step", "0.25", "--set", set],
        )
    };
    let last_y = || *column(&csv, "y").1.last().unwrap();
    // y = gain · u + t with gain 2: u = 2 makes y 4 more than u's start 0 does.
    succeeded(&run("u=2"), "u=2");
    let plain = last_y();
    assert!(plain >= 4.0, "{plain}");
    succeeded(&run("typed_vr.u=2"), "typed_vr.u=2");
    assert_eq!(last_y(), plain);
    let err = failed(run("typed_vr.nothing=3"), "typed_vr.nothing=3");
    assert!(err.contains("unknown variable"), "{err}");
    let o = Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(["cache", "prune", "--max-size", "5X"])
        .env("TWINBENCH_CACHE", dir.path().join("no-store"))
        .output()
        .unwrap();
    let err = failed(o, "cache prune --max-size 5X");
    assert!(err.contains("--max-size 5X: unknown unit"), "{err}");
}
