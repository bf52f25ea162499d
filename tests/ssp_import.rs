//! `twinbench run X.ssp`: SSP 1.0 import. The package of `export-ssp` repeats the TOML run
//! bit for bit; a hand-written package (an external .ssv with a prefix, a unit conversion
//! between connectors, a LinearTransformation, every parameter type) gives what physics
//! says; what the import does not support, a missing FMU, a malformed SSD and an unknown
//! parameter are errors naming the package, the file and the line. No file is left in the
//! temporary folder.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use tb_cosim::ssp_import::SspImportError;
use tb_cosim::{Plan, Simulation, SystemError};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

fn twinbench(tmp: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_twinbench"));
    c.env("TMPDIR", tmp);
    c
}

/// rls_v as shipped (Gauss-Seidel, one lap, decimation 5), FMU paths made absolute.
fn rls_v(dir: &Path) -> PathBuf {
    let fmu_dir = common::fmu_dir();
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()));
    let p = dir.join("rls_v.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn run_lib(system: &Path) -> (tb_cosim::RunSummary, tb_cosim::Table) {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let mut sim = Simulation::new(Plan::load(system, cache).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    (s, sim.recording().clone())
}

/// Nothing is left in the temporary folder `tmp`.
fn assert_empty(tmp: &Path) {
    let left: Vec<_> = std::fs::read_dir(tmp).unwrap().collect();
    assert!(left.is_empty(), "left in TMPDIR: {left:?}");
}

#[test]
fn exported_rls_v_runs_from_its_ssp_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let system = rls_v(dir.path());
    let ssp = dir.path().join("rls_v.ssp");
    let out = twinbench(tmp.path())
        .args(["export-ssp"])
        .arg(&system)
        .arg("-o")
        .arg(&ssp)
        .output()
        .unwrap();
    common::cli::assert_success(&out);
    // The binary: the same result file, byte for byte, and the same summary.
    let mut summaries = Vec::new();
    for (input, csv) in [(&system, "toml.csv"), (&ssp, "ssp.csv")] {
        let out = twinbench(tmp.path())
            .arg("run")
            .arg(input)
            .arg("--json")
            .arg("-o")
            .arg(dir.path().join(csv))
            .output()
            .unwrap();
        common::cli::assert_success(&out);
        let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        summaries.push(j);
    }
    for key in [
        "steps",
        "simulated_time",
        "lap_time",
        "reported",
        "stopped_by",
        "order",
        "recorded_rows",
    ] {
        assert_eq!(summaries[0][key], summaries[1][key], "{key}");
    }
    assert!(summaries[1]["steps"].as_u64().unwrap() > 90_000);
    let toml_csv = std::fs::read(dir.path().join("toml.csv")).unwrap();
    let ssp_csv = std::fs::read(dir.path().join("ssp.csv")).unwrap();
    assert!(toml_csv == ssp_csv, "the result files differ");
    // The library: every recorded column bit for bit.
    let (a, ta) = run_lib(&system);
    let (b, tb) = run_lib(&ssp);
    assert_eq!(a.steps, b.steps);
    assert_eq!(a.simulated_time.to_bits(), b.simulated_time.to_bits());
    assert_eq!(a.stopped_by, b.stopped_by);
    assert_eq!(a.reported.len(), 1);
    assert_eq!(a.reported[0].0, b.reported[0].0);
    assert_eq!(a.reported[0].1.to_bits(), b.reported[0].1.to_bits());
    assert_eq!(ta.names(), tb.names());
    assert_eq!(ta.units(), tb.units());
    assert_eq!(ta.names().len(), 26);
    assert_eq!(ta.len(), tb.len());
    for (k, (x, y)) in ta.columns().iter().zip(tb.columns()).enumerate() {
        let same = x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
        assert!(same, "column {} differs", ta.names()[k]);
    }
    // The unpacked package and FMUs went with the runs.
    assert_empty(tmp.path());
}

/// Port maps, a connection gain, Jacobi and a fixed stop time: the SSP names the FMU's own
/// variables (the recorded column of `edu.power` is `edu.electric_power`), the values are
/// the same bit for bit.
#[test]
fn port_maps_gains_and_jacobi_round_trip_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(rls_v(dir.path()))
        .unwrap()
        .replace("algorithm = \"gauss-seidel\"", "algorithm = \"jacobi\"")
        .replace("stop = \"vehicle.lap >= 1\"", "stop = 5.0")
        .replace(
            "name = \"edu\"\nfmu = \"edu\"\n",
            "name = \"edu\"\nfmu = \"edu\"\nports = { pedal = \"accel_pedal\", power = \"electric_power\" }\n",
        )
        .replace("\"driver.accel_pedal -> edu.accel_pedal\"", "\"driver.accel_pedal -> edu.pedal\"")
        .replace(
            "\"vehicle.v -> driver.v\",",
            "{ from = \"vehicle.v\", to = \"driver.v\", scale = 0.999, offset = 0.01 },",
        )
        .replace("\"edu.electric_power\"", "\"edu.power\"");
    assert!(
        text.contains("edu.pedal")
            && text.contains("scale = 0.999")
            && text.contains("\"edu.power\"")
    );
    let system = dir.path().join("mapped.toml");
    std::fs::write(&system, text).unwrap();
    let ssp = dir.path().join("mapped.ssp");
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    tb_cosim::ssp::export(
        &Plan::load(&system, cache).unwrap(),
        &ssp,
        &Default::default(),
    )
    .unwrap();
    let (a, ta) = run_lib(&system);
    let (b, tb) = run_lib(&ssp);
    assert_eq!(a.steps, 5000);
    assert_eq!(a.steps, b.steps);
    assert_eq!(a.stopped_by, b.stopped_by);
    let renamed: Vec<String> = ta
        .names()
        .iter()
        .map(|n| {
            if n == "edu.power" {
                "edu.electric_power".into()
            } else {
                n.clone()
            }
        })
        .collect();
    assert_eq!(renamed, tb.names());
    for (k, (x, y)) in ta.columns().iter().zip(tb.columns()).enumerate() {
        let same = x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
        assert!(same, "column {} differs", ta.names()[k]);
    }
}

const HEAD: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="hand">"#;

/// Two Feedthrough FMUs and a dyno: `speed` holds 72 km/h (from speed.ssv) and its other
/// types; `conv` receives it in m/s (a unit conversion between the connectors); `rotor`
/// (inertia 2 kg·m², 60 rpm at the start, from rotor.ssv with the prefix "rotor.") is driven
/// by 0.5·v + 1 N·m (a LinearTransformation, units suppressed); its speed goes back to
/// `speed` in rpm, doubled (conversion, then transformation).
fn hand_ssd(elements_extra: &str, connections_extra: &str) -> String {
    format!(
        r#"{HEAD}
  <ssd:System name="hand">
    <ssd:ParameterBindings>
      <ssd:ParameterBinding source="resources/rotor.ssv" prefix="rotor."/>
    </ssd:ParameterBindings>
    <ssd:Elements>
      <ssd:Component name="speed" type="application/x-fmu-sharedlibrary" source="resources/Feedthrough.fmu">
        <ssd:Connectors>
          <ssd:Connector name="Float64_continuous_output" kind="output"><ssc:Real unit="km/h"/></ssd:Connector>
          <ssd:Connector name="Float64_discrete_input" kind="input"><ssc:Real unit="rpm"/></ssd:Connector>
          <ssd:Connector name="Float64_discrete_output" kind="output"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="Int32_output" kind="output"><ssc:Integer/></ssd:Connector>
          <ssd:Connector name="Boolean_output" kind="output"><ssc:Boolean/></ssd:Connector>
          <ssd:Connector name="Enumeration_output" kind="output"><ssc:Enumeration name="Option"/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding source="resources/speed.ssv"/>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="conv" source="resources/Feedthrough.fmu">
        <ssd:Connectors>
          <ssd:Connector name="Float64_continuous_input" kind="input"><ssc:Real unit="m/s"/></ssd:Connector>
          <ssd:Connector name="Float64_continuous_output" kind="output"><ssc:Real/></ssd:Connector>
          <ssd:Connector name="Int32_input" kind="input"><ssc:Integer/></ssd:Connector>
        </ssd:Connectors>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="inline">
                <ssv:Parameters>
                  <ssv:Parameter name="Float64_fixed_parameter"><ssv:Real value="1.5"/></ssv:Parameter>
                </ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="rotor" type="application/x-fmu-sharedlibrary" source="resources/dyno.fmu">
        <ssd:Connectors>
          <ssd:Connector name="shaft_torque" kind="input"><ssc:Real unit="N.m"/></ssd:Connector>
          <ssd:Connector name="omega" kind="output"><ssc:Real unit="rad/s"/></ssd:Connector>
        </ssd:Connectors>
      </ssd:Component>{elements_extra}
    </ssd:Elements>
    <ssd:Connections>
      <ssd:Connection startElement="speed" startConnector="Float64_continuous_output" endElement="conv" endConnector="Float64_continuous_input"/>
      <ssd:Connection startElement="speed" startConnector="Int32_output" endElement="conv" endConnector="Int32_input"/>
      <ssd:Connection startElement="conv" startConnector="Float64_continuous_output" endElement="rotor" endConnector="shaft_torque" suppressUnitConversion="true">
        <ssc:LinearTransformation factor="0.5" offset="1"/>
      </ssd:Connection>
      <ssd:Connection startElement="rotor" startConnector="omega" endElement="speed" endConnector="Float64_discrete_input">
        <ssc:LinearTransformation factor="2"/>
      </ssd:Connection>{connections_extra}
    </ssd:Connections>
  </ssd:System>
  <ssd:Units>
    <ssc:Unit name="km/h"><ssc:BaseUnit m="1" s="-1" factor="0.2777777777777778"/></ssc:Unit>
  </ssd:Units>
  <ssd:DefaultExperiment startTime="0" stopTime="2">
    <ssd:Annotations>
      <ssc:Annotation type="com.opensimulationplatform"><osp:Algorithm xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"><osp:FixedStepAlgorithm baseStepSize="0.001"/></osp:Algorithm></ssc:Annotation>
    </ssd:Annotations>
  </ssd:DefaultExperiment>
</ssd:SystemStructureDescription>
"#
    )
}

fn ssv(params: &str) -> Vec<u8> {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<ssv:ParameterSet xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="set">
  <ssv:Parameters>
{params}
  </ssv:Parameters>
</ssv:ParameterSet>
"#
    )
    .into_bytes()
}

const SPEED_SSV: &str = r#"    <ssv:Parameter name="Float64_continuous_input"><ssv:Real value="72"/></ssv:Parameter>
    <ssv:Parameter name="Int32_input"><ssv:Integer value="7"/></ssv:Parameter>
    <ssv:Parameter name="Boolean_input"><ssv:Boolean value="true"/></ssv:Parameter>
    <ssv:Parameter name="String_input"><ssv:String value="set by speed.ssv"/></ssv:Parameter>
    <ssv:Parameter name="Enumeration_input"><ssv:Enumeration value="Option 2"/></ssv:Parameter>"#;

const ROTOR_SSV: &str = r#"    <ssv:Parameter name="inertia"><ssv:Real value="2.0" unit="kg.m2"/></ssv:Parameter>
    <ssv:Parameter name="omega_start"><ssv:Real value="60" unit="rpm"/></ssv:Parameter>"#;

/// The hand-written package with this SSD and rotor.ssv; `leave_out` drops an entry.
fn hand_package(dir: &Path, name: &str, ssd: &str, rotor_ssv: &str, leave_out: &str) -> PathBuf {
    common::fmu_dir();
    let feedthrough = common::reference::fmu("Feedthrough", 2);
    let entries = vec![
        ("SystemStructure.ssd", ssd.as_bytes().to_vec()),
        (
            "resources/Feedthrough.fmu",
            std::fs::read(feedthrough).unwrap(),
        ),
        (
            "resources/dyno.fmu",
            std::fs::read(common::fmu("dyno")).unwrap(),
        ),
        ("resources/speed.ssv", ssv(SPEED_SSV)),
        ("resources/rotor.ssv", ssv(rotor_ssv)),
    ];
    let entries: Vec<_> = entries
        .into_iter()
        .filter(|(n, _)| *n != leave_out)
        .collect();
    let entries: Vec<(&str, &[u8])> = entries.iter().map(|(n, b)| (*n, &b[..])).collect();
    let p = dir.join(name);
    common::build::zip(&p, &entries);
    p
}

/// The error loading `ssp` gives: the package's own (an SSP import error), the test fails
/// on any other.
/// The hand-made package written as `name` without the entry `left_out`, and why it does
/// not load.
fn refused_without(dir: &Path, name: &str, left_out: &str) -> (PathBuf, SspImportError) {
    let ssp = hand_package(dir, name, &hand_ssd("", ""), ROTOR_SSV, left_out);
    let e = load_err(&ssp);
    (ssp, e)
}

fn load_err(ssp: &Path) -> SspImportError {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    match Plan::load(ssp, cache) {
        Ok(_) => panic!("{} loaded", ssp.display()),
        Err(SystemError::Ssp(e)) => {
            eprintln!("{e}");
            *e
        }
        Err(e) => panic!("{}: not an SSP import error: {e:?}", ssp.display()),
    }
}

/// The SSD's name inside a package.
const SSD: &str = "SystemStructure.ssd";

#[test]
fn hand_written_ssp_gives_what_physics_says() {
    let dir = tempfile::tempdir().unwrap();
    let ssp = hand_package(dir.path(), "hand.ssp", &hand_ssd("", ""), ROTOR_SSV, "");
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let plan = Plan::load(&ssp, cache).unwrap();
    assert_eq!(plan.file.name.as_deref(), Some("hand"));
    assert_eq!(plan.file.experiment.step, 0.001);
    let mut sim = Simulation::new(Arc::new(plan)).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    assert_eq!(s.steps, 2000);
    let t = sim.recording();
    let last = |name: &str| -> f64 {
        let c = t
            .column(name)
            .unwrap()
            .unwrap_or_else(|| panic!("no column {name}: {:?}", t.names()));
        c[c.len() - 1]
    };
    // 72 km/h through the connectors' units: 20 m/s.
    assert!((last("conv.Float64_continuous_output") - 20.0).abs() < 1e-12);
    // Every type from the .ssv (the Enumeration by its item's name).
    assert_eq!(last("speed.Int32_output"), 7.0);
    assert_eq!(last("conv.Int32_output"), 7.0);
    assert_eq!(last("speed.Boolean_output"), 1.0);
    assert_eq!(last("speed.Enumeration_output"), 2.0);
    let text = t
        .text_at(t.find("speed.String_output").unwrap().unwrap())
        .unwrap();
    assert_eq!(text.last().map(String::as_str), Some("set by speed.ssv"));
    // The rotor: J dω/dt = 0.5·20 + 1 = 11 N·m from 60 rpm = 2π rad/s, J = 2 kg·m².
    let omega = t.column("rotor.omega").unwrap().unwrap();
    let time = t.column("time").unwrap().unwrap();
    // The dyno integrates a constant torque exactly (the initialisation exchange gives it
    // the torque from t = 0): rounding only.
    let tol = 1e-9;
    for (k, (&w, &tk)) in omega.iter().zip(time).enumerate() {
        let expected = 2.0 * std::f64::consts::PI + 11.0 / 2.0 * tk;
        assert!(
            (w - expected).abs() <= tol,
            "row {k}, t = {tk}: omega {w}, physics {expected}"
        );
    }
    let w_end = last("rotor.omega");
    assert!(
        (w_end - (2.0 * std::f64::consts::PI + 11.0)).abs() <= tol,
        "{w_end}"
    );
    // Back in rpm, doubled: 2·ω·30/π (one step late at most, through the loop).
    let rpm2 = last("speed.Float64_discrete_output");
    let step = 11.0 / 2.0 * 0.001;
    eprintln!(
        "omega(2 s) = {w_end} rad/s (physics {}), 2·rpm = {rpm2}",
        2.0 * std::f64::consts::PI + 11.0
    );
    let expected = 2.0 * w_end * 30.0 / std::f64::consts::PI;
    assert!(
        (rpm2 - expected).abs() <= 2.0 * 30.0 / std::f64::consts::PI * (step + tol),
        "{rpm2} vs {expected}"
    );
}

#[test]
fn unsupported_elements_are_named_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let line_of = |ssd: &str, what: &str| ssd.lines().position(|l| l.contains(what)).unwrap() + 1;
    // A nested system.
    let ssd = hand_ssd("\n      <ssd:System name=\"inner\"/>", "");
    let e = load_err(&hand_package(dir.path(), "nested.ssp", &ssd, ROTOR_SSV, ""));
    let line = line_of(&ssd, "name=\"inner\"");
    assert!(
        matches!(&e, SspImportError::Unsupported { ssp, file, line: l, element, .. }
            if ssp.ends_with("nested.ssp") && file == SSD && *l == line && element == "System"),
        "{e}"
    );
    assert_contains(&e.to_string(), &["nested systems"]);
    // A signal dictionary.
    let ssd = hand_ssd("", "").replace(
        "    <ssd:Elements>",
        "    <ssd:SignalDictionaries><ssd:SignalDictionary name=\"d\"/></ssd:SignalDictionaries>\n    <ssd:Elements>",
    );
    let e = load_err(&hand_package(dir.path(), "dict.ssp", &ssd, ROTOR_SSV, ""));
    let line = line_of(&ssd, "SignalDictionaries");
    assert!(
        matches!(&e, SspImportError::Unsupported { line: l, element, .. }
            if *l == line && element == "SignalDictionaries"),
        "{e}"
    );
    assert_contains(&e.to_string(), &["signal dictionaries"]);
    // A mapping transformation.
    let ssd = hand_ssd(
        "",
        "\n      <ssd:Connection startElement=\"speed\" startConnector=\"Boolean_output\" endElement=\"conv\" endConnector=\"Int32_input\"><ssc:BooleanMappingTransformation/></ssd:Connection>",
    );
    let e = load_err(&hand_package(dir.path(), "map.ssp", &ssd, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Unsupported { element, .. }
            if element == "BooleanMappingTransformation"),
        "{e}"
    );
    // What is supported instead.
    assert_contains(&e.to_string(), &["LinearTransformation"]);
    // A connection to the system's own connector.
    let ssd = hand_ssd(
        "",
        "\n      <ssd:Connection startConnector=\"in\" endElement=\"conv\" endConnector=\"Int32_input\"/>",
    );
    let e = load_err(&hand_package(
        dir.path(),
        "sysconn.ssp",
        &ssd,
        ROTOR_SSV,
        "",
    ));
    assert!(
        matches!(&e, SspImportError::Unsupported { element, .. } if element == "Connection"),
        "{e}"
    );
    assert!(e.to_string().contains("system's own connectors"), "{e}");
    // A parameter mapping.
    let ssd = hand_ssd("", "").replace(
        "<ssd:ParameterBinding source=\"resources/speed.ssv\"/>",
        "<ssd:ParameterBinding source=\"resources/speed.ssv\"><ssd:ParameterMapping source=\"resources/m.ssm\"/></ssd:ParameterBinding>",
    );
    let e = load_err(&hand_package(dir.path(), "pmap.ssp", &ssd, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Unsupported { element, .. } if element == "ParameterMapping"),
        "{e}"
    );
    assert_contains(&e.to_string(), &["parameter mappings are not supported"]);
}

#[test]
fn missing_fmu_malformed_ssd_and_unknown_parameter_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    // The dyno is not in the package.
    let (ssp, e) = refused_without(dir.path(), "nodyno.ssp", "resources/dyno.fmu");
    assert!(
        matches!(&e, SspImportError::MissingFmu { ssp, component, fmu, available }
            if ssp.ends_with("nodyno.ssp") && component == "rotor" && fmu == "resources/dyno.fmu"
                && available.contains("resources/Feedthrough.fmu")),
        "{e}"
    );
    // The binary says the same, exits with an error and leaves nothing behind.
    let out = twinbench(tmp.path()).arg("run").arg(&ssp).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_contains(&stderr, &["'resources/dyno.fmu' is not in the package"]);
    // A malformed SSD: an end tag that does not match, on line 6.
    let mut ssd = hand_ssd("", "");
    let bad_line = ssd
        .lines()
        .position(|l| l.contains("<ssd:Elements>"))
        .unwrap()
        + 1;
    ssd = ssd.replacen("<ssd:Elements>", "<ssd:Elements></ssd:Element>", 1);
    let ssp = hand_package(dir.path(), "malformed.ssp", &ssd, ROTOR_SSV, "");
    let e = load_err(&ssp);
    assert!(
        matches!(&e, SspImportError::Xml { ssp, file, line, .. }
            if ssp.ends_with("malformed.ssp") && file == SSD && *line == bad_line),
        "{e}"
    );
    let out = twinbench(tmp.path()).arg("run").arg(&ssp).output().unwrap();
    assert!(!out.status.success());
    // An unclosed document.
    let ssd = hand_ssd("", "").replace("</ssd:SystemStructureDescription>\n", "");
    let e = load_err(&hand_package(dir.path(), "cut.ssp", &ssd, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Xml { file, .. } if file == SSD),
        "{e}"
    );
    // The element left open.
    assert_contains(
        &e.to_string(),
        &["not closed", "SystemStructureDescription"],
    );
    // A parameter of the .ssv naming no variable of the FMU.
    let rotor = ROTOR_SSV.replace("name=\"inertia\"", "name=\"inertiaa\"");
    let ssp = hand_package(dir.path(), "badparam.ssp", &hand_ssd("", ""), &rotor, "");
    let e = load_err(&ssp);
    let line = ssv(&rotor)
        .split(|&b| b == b'\n')
        .position(|l| String::from_utf8_lossy(l).contains("inertiaa"))
        .unwrap()
        + 1;
    assert!(
        matches!(&e, SspImportError::Invalid { ssp, file, line: l, .. }
            if ssp.ends_with("badparam.ssp") && file == "resources/rotor.ssv" && *l == line),
        "{e}"
    );
    // The name, and the closest one the FMU has.
    assert_contains(&e.to_string(), &["no variable 'inertiaa'", "inertia"]);
    // No SSD, a missing .ssv, an SSD nested too deep: named, no panic.
    let ssp = hand_package(
        dir.path(),
        "nossd.ssp",
        "",
        ROTOR_SSV,
        "SystemStructure.ssd",
    );
    let e = load_err(&ssp);
    assert!(matches!(&e, SspImportError::Package { .. }), "{e}");
    assert_contains(
        &e.to_string(),
        &["nossd.ssp: the package has no SystemStructure.ssd"],
    );
    let (_, e) = refused_without(dir.path(), "nossv.ssp", "resources/speed.ssv");
    assert!(
        matches!(&e, SspImportError::Invalid { ssp, file, .. }
            if ssp.ends_with("nossv.ssp") && file == SSD),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["'resources/speed.ssv' is not in the package"],
    );
    let deep = format!("{HEAD}{}", "<ssd:System>".repeat(100_000));
    let e = load_err(&hand_package(dir.path(), "deep.ssp", &deep, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Xml { file, .. } if file == SSD),
        "{e}"
    );
    assert!(e.to_string().contains("nested deeper than"), "{e}");
    // An entry escaping the package is refused by the archive checks before anything is written.
    let evil = dir.path().join("evil.ssp");
    let ssd = hand_ssd("", "");
    common::build::zip(
        &evil,
        &[
            ("../evil.ssd", b"x"),
            ("SystemStructure.ssd", ssd.as_bytes()),
        ],
    );
    let e = load_err(&evil);
    assert!(
        matches!(&e, SspImportError::Archive(a)
            if matches!(&**a, tb_fmi::FmuError::Archive { path, .. }
                if path.ends_with("evil.ssp"))),
        "{e}"
    );
    assert!(e.to_string().contains("escapes the archive"), "{e}");
    assert!(!dir.path().parent().unwrap().join("evil.ssd").exists());
    let out = twinbench(tmp.path())
        .arg("run")
        .arg(&evil)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert_empty(tmp.path());
}

/// Damaged SSDs (cut anywhere, a byte replaced by markup) are errors, never a panic.
#[test]
fn damaged_ssds_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let ssd = hand_ssd("", "");
    let bytes = ssd.as_bytes();
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let mut cases = 0;
    for k in (0..bytes.len()).step_by(13) {
        let mut variants = vec![bytes[..k].to_vec()];
        for c in [b'<', b'"', b'&', b'>', b'/', 0xff] {
            let mut v = bytes.to_vec();
            v[k] = c;
            variants.push(v);
        }
        for v in variants {
            let p = dir.path().join("damaged.ssp");
            // No FMUs: the SSD is read before any component's FMU is looked for.
            common::build::zip(&p, &[("SystemStructure.ssd", &v)]);
            let e = Plan::load(&p, cache.clone())
                .err()
                .expect("a damaged package loads");
            // The package's own error, never another kind (an FMU's, a panic's).
            assert!(matches!(e, SystemError::Ssp(_)), "{e:?}");
            assert!(e.to_string().contains("damaged.ssp"), "{e}");
            cases += 1;
        }
    }
    assert!(cases > 1000);
}

/// Every parameter type through export and import: the same typed values (the Enumeration
/// by its item's name in the SSV), the same run.
#[test]
fn every_parameter_type_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let ft = common::reference::fmu("Feedthrough", 2);
    let system = dir.path().join("types.toml");
    std::fs::write(
        &system,
        format!(
            r#"name = "types"
connections = ["a.Float64_continuous_output -> b.Float64_continuous_input", "a.Enumeration_output -> b.Enumeration_input"]
[fmus]
ft = "{}"
[[instance]]
name = "a"
fmu = "ft"
[[instance]]
name = "b"
fmu = "ft"
[parameters]
"a.Float64_fixed_parameter" = 3.25
"a.Float64_continuous_input" = 0.1
"a.Int32_input" = -4
"a.Boolean_input" = true
"a.String_input" = "x & <y>"
"a.Enumeration_input" = 2
[experiment]
step = 0.01
stop = 0.1
"#,
            ft.display()
        ),
    )
    .unwrap();
    let ssp = dir.path().join("types.ssp");
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let toml_plan = Plan::load(&system, cache.clone()).unwrap();
    tb_cosim::ssp::export(&toml_plan, &ssp, &Default::default()).unwrap();
    let ssp_plan = Plan::load(&ssp, cache).unwrap();
    let values = |p: &Plan| {
        p.parameters
            .iter()
            .map(|(s, v)| (s.name.clone(), v.clone()))
            .collect::<Vec<_>>()
    };
    assert_eq!(values(&toml_plan), values(&ssp_plan));
    assert_eq!(values(&ssp_plan).len(), 6);
    let (a, ta) = run_lib(&system);
    let (b, tb) = run_lib(&ssp);
    assert_eq!(a.steps, b.steps);
    assert_eq!(ta.names(), tb.names());
    for (k, (x, y)) in ta.columns().iter().zip(tb.columns()).enumerate() {
        let same = x.len() == y.len() && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits());
        assert!(same, "column {} differs", ta.names()[k]);
        assert_eq!(ta.text_at(k), tb.text_at(k), "column {}", ta.names()[k]);
    }
    let text = tb
        .text_at(tb.find("a.String_output").unwrap().unwrap())
        .unwrap();
    assert_eq!(text.last().map(String::as_str), Some("x & <y>"));
    assert_eq!(
        *tb.column("b.Enumeration_output")
            .unwrap()
            .unwrap()
            .last()
            .unwrap(),
        2.0
    );
}

/// N29: what a package says that defines nothing or contradicts itself is refused, not
/// taken: a unit with factor 0 (it zeroed a start value), one parameter set twice in one
/// parameter set (the last one won); and a value in a unit given for a variable without one
/// is converted, not taken as a number in the variable's unit.
#[test]
fn n29_degenerate_units_and_parameter_sets_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let zero = hand_ssd("", "").replace("factor=\"0.2777777777777778\"", "factor=\"0\"");
    let e = load_err(&hand_package(dir.path(), "zero.ssp", &zero, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Invalid { file, .. } if file == SSD),
        "{e}"
    );
    assert_contains(&e.to_string(), &["unit 'km/h': factor 0.0 and offset 0.0 do not define a unit (a finite, non-zero factor)"]);
    let twice = format!(
        "{ROTOR_SSV}\n    <ssv:Parameter name=\"inertia\"><ssv:Real value=\"3.0\" unit=\"kg.m2\"/></ssv:Parameter>"
    );
    let e = load_err(&hand_package(
        dir.path(),
        "twice.ssp",
        &hand_ssd("", ""),
        &twice,
        "",
    ));
    assert!(
        matches!(&e, SspImportError::Invalid { file, .. } if file == "resources/rotor.ssv"),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("is set twice in this parameter set (first at line"),
        "{e}"
    );
    // The Feedthrough's unitless parameter given in percent: converted (150 % = 1.5).
    let percent = hand_ssd("", "").replace(
        "<ssv:Real value=\"1.5\"/>",
        "<ssv:Real value=\"150\" unit=\"%\"/>",
    );
    let ssp = hand_package(dir.path(), "percent.ssp", &percent, ROTOR_SSV, "");
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let file = Plan::read_system(&ssp, &cache).unwrap();
    let x = file
        .parameters
        .get("conv.Float64_fixed_parameter")
        .and_then(|v| v.as_float())
        .unwrap();
    assert!((x - 1.5).abs() < 1e-15, "150 % = {x}");
    // A time for it: refused (500 ms used to be taken as 500).
    let ms = hand_ssd("", "").replace(
        "<ssv:Real value=\"1.5\"/>",
        "<ssv:Real value=\"500\" unit=\"ms\"/>",
    );
    let e = load_err(&hand_package(dir.path(), "ms.ssp", &ms, ROTOR_SSV, ""));
    assert!(
        matches!(&e, SspImportError::Invalid { file, .. } if file == SSD),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["parameter 'conv.Float64_fixed_parameter': incompatible units 'ms' and '1'"],
    );
}
