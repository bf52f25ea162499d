//! The Modelica Reference FMUs as the importer's conformance suite: each Co-Simulation
//! model is built from its sources (tests/common/reference.rs), run in twinbench and in
//! FMPy's `simulate_fmu` with the same step and inputs, and every output sample compared.
//! The largest differences are printed (`--nocapture`) and kept in docs/cross_validation.md.

mod common;

use common::kinds::invalid;

use common::reference;
use std::path::Path;
use std::sync::Arc;
use tb_cosim::replay::ReplayError;
use tb_cosim::{Plan, Simulation, SystemError, SystemFile, Table};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

/// One comparison: the model, its FMI version, the experiment and the input file.
struct Case {
    model: &'static str,
    version: u8,
    stop: f64,
    step: f64,
    input: Option<std::path::PathBuf>,
    /// Run the instance in a worker process.
    isolate: bool,
    /// `[experiment] step_convention` ("h" when None).
    step_convention: Option<&'static str>,
}

fn case(model: &'static str, version: u8) -> Case {
    // The models' default experiments; Feedthrough and Resource have no step size.
    let (stop, step) = match model {
        "BouncingBall" => (3.0, 1e-2),
        "Dahlquist" => (10.0, 0.1),
        "Feedthrough" => (2.0, 0.1),
        "Resource" => (1.0, 0.1),
        "Stair" => (10.0, 0.2),
        "VanDerPol" => (20.0, 1e-2),
        "StateSpace" => (10.0, 1.0),
        // A dyadic step: FMPy passes t[n+1] - t[n] as the step size, twinbench h itself;
        // they are equal for 2^-10 (the stiff model counts its 1e-6 substeps from it).
        "Roberts" => (1.0, 1.0 / 1024.0),
        m => panic!("no experiment for {m}"),
    };
    Case {
        model,
        version,
        stop,
        step,
        input: (model == "Feedthrough")
            .then(|| reference::sources().join("Feedthrough/Feedthrough_in.csv")),
        isolate: false,
        step_convention: None,
    }
}

/// FMPy's result for a case.
fn fmpy(c: &Case, fmu: &Path, dir: &Path) -> Table {
    let out = dir.join(format!("{}-fmi{}-fmpy.csv", c.model, c.version));
    let script = twinbench::pack::workspace_root().join("tools/fmpy_simulate.py");
    let mut cmd = std::process::Command::new(common::python::python());
    cmd.arg(&script).arg(fmu).arg(&out).args([
        "--stop",
        &c.stop.to_string(),
        "--step",
        &c.step.to_string(),
    ]);
    if let Some(i) = &c.input {
        cmd.arg("--input").arg(i);
    }
    let r = cmd.output().unwrap();
    assert!(
        r.status.success(),
        "FMPy on {}: {}",
        fmu.display(),
        String::from_utf8_lossy(&r.stderr)
    );
    Table::read_any(&out).unwrap()
}

/// twinbench's result for a case: one instance `m`, every output recorded.
fn twinbench(c: &Case, fmu: &Path, dir: &Path) -> Result<(Table, String), SystemError> {
    let mut text = format!(
        "[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"m\"\nisolate = {}\n\n[experiment]\nstep = {}\nstop = {}\n",
        fmu.display(),
        c.isolate,
        c.step,
        c.stop
    );
    if let Some(sc) = c.step_convention {
        text.push_str(&format!("step_convention = \"{sc}\"\n"));
    }
    if let Some(file) = &c.input {
        // As FMPy: every column named as an input of the model drives it.
        let header = std::fs::read_to_string(file).unwrap();
        let md = tb_fmi::FmuCache::temporary(false)
            .unwrap()
            .load(fmu)
            .unwrap()
            .description
            .clone();
        let connections: Vec<String> = header
            .lines()
            .next()
            .unwrap()
            .split(',')
            .filter(|n| {
                md.variable(n)
                    .is_some_and(|v| v.causality == tb_fmi::Causality::Input)
            })
            .map(|n| format!("\"in.{n} -> m.{n}\""))
            .collect();
        assert!(
            !connections.is_empty(),
            "{}: no input of the model",
            file.display()
        );
        text = format!("connections = [{}]\n{text}", connections.join(", "));
        text.push_str(&format!(
            "\n[[replay]]\nname = \"in\"\nfile = \"{}\"\nbasis = \"time\"\n",
            file.display()
        ));
    }
    let path = dir.join(format!("{}-fmi{}.toml", c.model, c.version));
    let file = SystemFile::parse(&text, &path).unwrap();
    let plan = common::compile(file, &path)?;
    let mut sim = Simulation::new(plan).unwrap();
    sim.echo_fmu_log = false;
    let summary = sim.run()?;
    Ok((sim.recording().clone(), summary.stopped_by))
}

/// The largest difference of each output FMPy recorded, and the rows compared.
fn compare(model: &str, ours: &Table, theirs: &Table) -> Vec<(String, f64)> {
    reference::worst_differences(model, ours, theirs)
        .into_iter()
        .map(|(name, worst, _)| (name, worst))
        .collect()
}

fn check(model: &'static str, version: u8) {
    check_case(case(model, version));
}

fn check_case(c: Case) {
    let (model, version) = (c.model, c.version);
    let dir = tb_testkit::scratch("reference");
    let fmu = reference::fmu(model, version);
    let theirs = fmpy(&c, &fmu, dir.path());
    let (ours, stopped_by) =
        twinbench(&c, &fmu, dir.path()).unwrap_or_else(|e| panic!("{model}: {e}"));
    let diffs = compare(model, &ours, &theirs);
    eprintln!("{model} FMI {version}: stopped by {stopped_by}; FMPy: {diffs:?}");
    for (name, d) in diffs {
        assert!(
            d <= 1e-12,
            "{model} FMI {version}: {name} differs from FMPy by {d:e}"
        );
    }
    // The shipped reference result, where it was made with the same input and grid
    // (Feedthrough's is not: its input file is applied with other types there).
    let shipped = reference::sources().join(format!("{model}/{model}_out.csv"));
    // (Roberts_out.csv in the snapshot holds another model's result: columns h and v.)
    if shipped.exists() && !["Feedthrough", "Roberts"].contains(&model) && c.input.is_none() {
        let worst = compare_at_shared_times(&ours, &read_shipped(&shipped, dir.path()));
        assert!(
            !worst.is_empty(),
            "{model}: no column of {} compared",
            shipped.display()
        );
        eprintln!("{model} FMI {version}: shipped result: {worst:?}");
        for (name, rows, d) in worst {
            assert!(
                rows > 0 && d <= 1e-12,
                "{model}: {name} differs from the shipped result by {d:e} over {rows} rows"
            );
        }
    }
}

/// A shipped result; an FMI 3.0 array is one cell of space-separated values there, which
/// becomes one column per element (`y[1]`, `y[2]`, …) as twinbench records it.
fn read_shipped(path: &Path, dir: &Path) -> Table {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let rows: Vec<Vec<&str>> = lines
        .filter(|l| !l.is_empty())
        .map(|l| l.split(',').collect())
        .collect();
    if !rows.iter().flatten().any(|c| c.trim().contains(' ')) {
        return Table::read_any(path).unwrap();
    }
    let mut names = Vec::new();
    for (k, h) in header.iter().enumerate() {
        match rows[0][k].split_whitespace().count() {
            1 => names.push(h.to_string()),
            n => names.extend((1..=n).map(|i| format!("{h}[{i}]"))),
        }
    }
    let mut out = names.join(",") + "\n";
    for r in &rows {
        let cells: Vec<&str> = r.iter().flat_map(|c| c.split_whitespace()).collect();
        out += &(cells.join(",") + "\n");
    }
    let expanded = dir.join("shipped.csv");
    std::fs::write(&expanded, out).unwrap();
    Table::read_any(&expanded).unwrap()
}

/// Per numeric column of `shipped`: the rows at a time `ours` has too, and the largest
/// difference there.
fn compare_at_shared_times(ours: &Table, shipped: &Table) -> Vec<(String, usize, f64)> {
    let (t_ours, t_ref) = (ours.column_at(0), shipped.column_at(0));
    let mut out = Vec::new();
    for (k, name) in shipped.names().iter().enumerate().skip(1) {
        if shipped.is_text(k) {
            continue;
        }
        let Ok(col) = ours.require(&format!("m.{name}")) else {
            continue;
        };
        let (mut rows, mut worst) = (0, 0.0f64);
        for (j, t) in t_ref.iter().enumerate() {
            if let Some(i) = t_ours.iter().position(|x| (x - t).abs() <= 1e-9) {
                rows += 1;
                worst = worst.max((col[i] - shipped.column_at(k)[j]).abs());
            }
        }
        out.push((name.clone(), rows, worst));
    }
    out
}

#[test]
fn fmi2_bouncing_ball() {
    check("BouncingBall", 2);
}

#[test]
fn fmi2_dahlquist() {
    check("Dahlquist", 2);
}

#[test]
fn fmi2_van_der_pol() {
    check("VanDerPol", 2);
}

#[test]
fn fmi2_resource() {
    check("Resource", 2);
}

#[test]
fn fmi2_stair() {
    check("Stair", 2);
}

#[test]
fn fmi2_feedthrough() {
    check("Feedthrough", 2);
}

#[test]
fn fmi3_bouncing_ball() {
    check("BouncingBall", 3);
}

#[test]
fn fmi3_dahlquist() {
    check("Dahlquist", 3);
}

#[test]
fn fmi3_van_der_pol() {
    check("VanDerPol", 3);
}

#[test]
fn fmi3_resource() {
    check("Resource", 3);
}

#[test]
fn fmi3_stair() {
    check("Stair", 3);
}

#[test]
fn fmi3_feedthrough() {
    check("Feedthrough", 3);
}

/// A stiff test problem (Robertson's chemical kinetics) on a short span: its
/// Co-Simulation interface integrates with the framework's fixed-step solver.
#[test]
fn fmi3_roberts() {
    check("Roberts", 3);
}

/// The stiff model counts its fixed 1e-6 s substeps from the step size: with a decimal
/// step (1e-3 s) FMPy's `t[n+1] − t[n]` differs from h by an ulp at some steps, and one
/// substep more or less shows as 4e-8. `step_convention = "grid"` passes FMPy's step sizes:
/// the same bits.
#[test]
fn fmi3_roberts_with_a_decimal_step_and_fmpy_step_sizes() {
    check_case(Case {
        step: 1e-3,
        step_convention: Some("grid"),
        ..case("Roberts", 3)
    });
}

/// Arrays: the matrices and vectors of a state-space model, one column per element.
#[test]
fn fmi3_state_space() {
    check("StateSpace", 3);
}

#[test]
fn fmi2_feedthrough_replays_steps_holds_and_interpolates_as_fmpy() {
    // Every input type; a repeated time is a step; a Real row between the grid points is
    // interpolated for the continuous input and held for the discrete one; a text column
    // nobody uses.
    let rows = "time,Float64_continuous_input,Float64_discrete_input,Int32_input,Boolean_input,Enumeration_input,comment\n\
         0,0,0,0,0,1,start\n\
         0.3,1,2.5,3,1,2,x\n\
         0.3,2,-1,4,0,1,\"a step, here\"\n\
         0.7,-1,7,-5,1,2,y\n\
         1.25,3,7,-5,1,2,between\n\
         1.2000000000000002,3,7,-5,1,2,not sorted\n";
    let dir = common::scratch_with("feedthrough-in", &[("in.csv", rows)]);
    let input = dir.path().join("in.csv");
    // The last row goes back in time: refused with the line.
    let c = Case {
        input: Some(input.clone()),
        ..case("Feedthrough", 2)
    };
    let fmu = reference::fmu("Feedthrough", 2);
    let e = twinbench(&c, &fmu, dir.path()).err().unwrap();
    assert!(
        matches!(&e, SystemError::Replay { name, error, .. } if name == "in"
            && matches!(**error, ReplayError::TimeDecreases { line: 7, time, before }
                if time == 1.2000000000000002 && before == 1.25)),
        "{e}"
    );
    let text = std::fs::read_to_string(&input).unwrap();
    std::fs::write(
        &input,
        text.replace(
            "1.2000000000000002,3,7,-5,1,2,not sorted",
            "2,0,1,1,0,2,end",
        ),
    )
    .unwrap();
    check_case(c);
}

#[test]
fn fmi2_feedthrough_strings_are_set_recorded_and_connected() {
    strings_are_set_recorded_and_connected(2);
}

#[test]
fn fmi3_feedthrough_strings_are_set_recorded_and_connected() {
    strings_are_set_recorded_and_connected(3);
}

fn strings_are_set_recorded_and_connected(version: u8) {
    // A String input set in [parameters] reaches the FMU (fmi2SetString, fmi3SetString)
    // and its String output is recorded as text; a second instance gets it through a
    // connection.
    let dir = tb_testkit::scratch("feedthrough-str");
    let fmu = reference::fmu("Feedthrough", version);
    let text = format!(
        "connections = [\"a.String_output -> b.String_input\"]\n[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"a\"\nfmu = \"m\"\n\n[[instance]]\nname = \"b\"\nfmu = \"m\"\n\n[parameters]\n\"a.String_input\" = \"a, \\\"quoted\\\" text\"\n\n[experiment]\nstep = 0.5\nstop = 1.0\n\n[record]\nsignals = [\"a.String_output\", \"b.String_output\"]\n",
        fmu.display()
    );
    let path = dir.path().join("strings.toml");
    let plan = Plan::from_file(
        SystemFile::parse(&text, &path).unwrap(),
        &path,
        Arc::new(FmuCache::temporary(false).unwrap()),
    )
    .unwrap();
    let mut sim = Simulation::new(plan).unwrap();
    sim.run().unwrap();
    for k in [1, 2] {
        let col = sim.recording().text_at(k).unwrap();
        assert_eq!(col.len(), 3);
        assert!(col.iter().all(|v| v == "a, \"quoted\" text"), "{col:?}");
    }
    // And through the CSV writer and reader.
    let csv = dir.path().join("strings.csv");
    sim.recording().write_csv(&csv).unwrap();
    let back = Table::read_any(&csv).unwrap();
    assert_eq!(back.text_at(1).unwrap()[2], "a, \"quoted\" text");
}

/// A plan of one Feedthrough instance `m` with `extra` lines, or the error.
fn feedthrough_plan(dir: &Path, head: &str, extra: &str) -> Result<Plan, SystemError> {
    let text = format!(
        "{head}\n[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"m\"\n\n[experiment]\nstep = 0.1\nstop = 1.0\n{extra}",
        reference::fmu("Feedthrough", 2).display()
    );
    let path = dir.join("sys.toml");
    let file = SystemFile::parse(&text, &path)?;
    Plan::from_file(file, &path, Arc::new(FmuCache::temporary(false).unwrap()))
}

#[test]
fn enumeration_and_integer_values_are_checked_before_the_first_step() {
    let dir = tb_testkit::scratch("enum-check");
    let d = dir.path();
    let e = feedthrough_plan(d, "", "[parameters]\n\"m.Enumeration_input\" = 3\n")
        .err()
        .unwrap();
    assert!(invalid(&e, "parameter \"m.Enumeration_input\""), "{e}");
    assert_contains(&e.to_string(), &["3 is not an item of the Enumeration 'm.Enumeration_input' (1 'Option 1', 2 'Option 2')"]);
    assert!(feedthrough_plan(d, "", "[parameters]\n\"m.Enumeration_input\" = 2\n").is_ok());
    // Replayed values must fit the input they drive.
    for (column, value, expected) in [
        (
            "Enumeration_input",
            "5",
            "value 5 is not an item of the Enumeration 'm.Enumeration_input'",
        ),
        (
            "Int32_input",
            "1.5",
            "value 1.5 is not a 32-bit integer for Integer 'm.Int32_input'",
        ),
        (
            "Int32_input",
            "3e9",
            "value 3000000000 is not a 32-bit integer",
        ),
        (
            "Boolean_input",
            "2",
            "value 2 is not 0 or 1 for the Boolean 'm.Boolean_input'",
        ),
    ] {
        let input = d.join(format!("{column}.csv"));
        std::fs::write(&input, format!("time,{column}\n0,1\n0.5,{value}\n")).unwrap();
        let e = feedthrough_plan(
            d,
            &format!("connections = [\"in.{column} -> m.{column}\"]"),
            &format!(
                "[[replay]]\nname = \"in\"\nfile = \"{}\"\nbasis = \"time\"\n",
                input.display()
            ),
        )
        .err()
        .unwrap_or_else(|| panic!("{column} = {value} accepted"));
        assert!(
            matches!(&e, SystemError::Invalid { context, .. }
                if context.ends_with(&format!("connection \"in.{column} -> m.{column}\""))),
            "{e}"
        );
        assert_contains(&e.to_string(), &[expected, "row 2"]);
    }
}

#[test]
fn fmi2_stair_isolated_ends_where_in_process_does() {
    let dir = tb_testkit::scratch("stair-iso");
    let c = case("Stair", 2);
    let fmu = reference::fmu("Stair", 2);
    let (in_process, stopped) = twinbench(&c, &fmu, dir.path()).unwrap();
    let text = format!(
        "[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"m\"\nisolate = true\n\n[experiment]\nstep = 0.2\nstop = 10.0\n",
        fmu.display()
    );
    let path = dir.path().join("iso.toml");
    let plan = common::compile(SystemFile::parse(&text, &path).unwrap(), &path).unwrap();
    let mut sim = Simulation::new(plan).unwrap();
    let s = sim.run().unwrap();
    assert_eq!(s.stopped_by, stopped);
    assert_eq!(sim.recording().column_at(0), in_process.column_at(0));
    assert_eq!(sim.recording().column_at(1), in_process.column_at(1));
    assert_eq!(*sim.recording().column_at(0).last().unwrap(), 9.0);
}

/// FMI 3.0 in a worker process: every column equal to the in-process run, bit for bit
/// (arrays, every integer type and Strings through the protocol, the FMU's own end).
#[test]
fn fmi3_isolated_runs_equal_in_process_runs() {
    let dir = tb_testkit::scratch("fmi3-iso");
    for model in ["Feedthrough", "StateSpace", "Stair"] {
        let fmu = reference::fmu(model, 3);
        let (a, stop_a) =
            twinbench(&case(model, 3), &fmu, dir.path()).unwrap_or_else(|e| panic!("{model}: {e}"));
        let c = Case {
            isolate: true,
            ..case(model, 3)
        };
        let (b, stop_b) =
            twinbench(&c, &fmu, dir.path()).unwrap_or_else(|e| panic!("{model}: {e}"));
        assert_eq!(stop_a, stop_b, "{model}");
        assert_eq!(a.names(), b.names(), "{model}");
        for k in 0..a.names().len() {
            if a.is_text(k) {
                continue;
            }
            let (x, y) = (a.column_at(k), b.column_at(k));
            assert!(
                x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()) && x.len() == y.len(),
                "{model}: column {} differs isolated",
                a.names()[k]
            );
        }
    }
}

#[test]
fn export_ssp_types_strings_and_enumerations_as_ssp_does() {
    let dir = tb_testkit::scratch("ssp-types");
    let fmu = reference::fmu("Feedthrough", 2);
    let path = common::system_file(
        &dir.path().join("types.toml"),
        "connections = [\"a.String_output -> b.String_input\", \"a.Enumeration_output -> b.Enumeration_input\"]",
        &[("m", &fmu)],
        "[[instance]]\nname = \"a\"\nfmu = \"m\"\n\n[[instance]]\nname = \"b\"\nfmu = \"m\"\n\n[parameters]\n\"a.String_input\" = \"<&>\"\n\"a.Enumeration_input\" = 2\n\"a.Int32_input\" = 7\n\n[experiment]\nstep = 0.5\nstop = 1.0\n",
    );
    let plan = Plan::load(&path, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let ssp = dir.path().join("types.ssp");
    let summary = tb_cosim::ssp::export(
        &plan,
        &ssp,
        &tb_cosim::ssp::ExportOptions { stop_time: None },
    )
    .unwrap();
    // Exactly the parameters the system file sets.
    assert_eq!(summary.parameters, 3);
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&ssp).unwrap()).unwrap();
    let mut ssd = String::new();
    std::io::Read::read_to_string(&mut zip.by_name("SystemStructure.ssd").unwrap(), &mut ssd)
        .unwrap();
    for fragment in [
        "<ssv:Parameter name=\"Enumeration_input\"><ssv:Enumeration value=\"Option 2\"/></ssv:Parameter>",
        "<ssv:Parameter name=\"String_input\"><ssv:String value=\"&lt;&amp;&gt;\"/></ssv:Parameter>",
        "<ssv:Parameter name=\"Int32_input\"><ssv:Integer value=\"7\"/></ssv:Parameter>",
        "<ssd:Connector name=\"Enumeration_output\" kind=\"output\"><ssc:Enumeration name=\"Option\"/></ssd:Connector>",
        "<ssd:Connector name=\"String_input\" kind=\"input\"><ssc:String/></ssd:Connector>",
        "<ssc:Enumeration name=\"Option\">",
        "<ssc:Item name=\"Option 1\" value=\"1\"/>",
    ] {
        assert!(ssd.contains(fragment), "{fragment} not in\n{ssd}");
    }
    // Valid against the SSP 1.0 schema FMPy ships.
    let out = std::process::Command::new(common::python::python())
        .arg(twinbench::pack::workspace_root().join("tools/ssp_check.py"))
        .arg(&ssp)
        .arg("--json")
        .output()
        .unwrap();
    let j: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|_| panic!("{}", String::from_utf8_lossy(&out.stderr)));
    assert_eq!(
        j["validation"]["valid"], true,
        "{}",
        j["validation"]["problems"]
    );
}
