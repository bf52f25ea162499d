//! Third-party FMI 2.0 Co-Simulation FMUs: standard-valid model descriptions that our
//! exporter never writes (extra root attributes, vendor annotations, vendor attributes,
//! unit names we do not know but that the FMU defines) load, convert and run.
//!
//! The FMUs are made here by rewriting the model description of the packed test FMU
//! `faulty` (`y = ∫ gain·u dt`, `y_direct = gain·u`) into a new archive; the GUID is kept,
//! so the binary accepts them.

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::plan::ConversionError;
use tb_cosim::{Plan, Simulation, SystemError, SystemFile, Table};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

fn faulty_xml() -> String {
    let fmu = common::fmu("faulty");
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&fmu).unwrap()).unwrap();
    let mut text = String::new();
    zip.by_name("modelDescription.xml")
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    text
}

/// `faulty.fmu` with its modelDescription.xml replaced by `xml`, written to `dir/name.fmu`.
fn repack(dir: &Path, name: &str, xml: &str) -> PathBuf {
    common::reference::with_description(&common::fmu("faulty"), dir, name, |_| xml.to_string())
}

/// Replace exactly one occurrence of `from` (the rewrite must hit the intended place).
fn edit(xml: &str, from: &str, to: &str) -> String {
    assert_eq!(xml.matches(from).count(), 1, "'{from}' in:\n{xml}");
    xml.replacen(from, to, 1)
}

const ACME: &str = "http://example.com/acme-sim";

/// An extra (namespaced and plain) root attribute.
fn extra_root_attributes(xml: &str) -> String {
    edit(
        xml,
        "<fmiModelDescription\n",
        &format!("<fmiModelDescription xmlns:acme=\"{ACME}\" acme:buildId=\"4711\" exportedBy=\"ACME Sim 12.3\"\n"),
    )
}

/// `<VendorAnnotations>` at the model level and `<Annotations>` inside a ScalarVariable.
fn annotations(xml: &str) -> String {
    let xml = edit(
        xml,
        "<ModelVariables>",
        &format!(
            "<VendorAnnotations>\n    <Tool name=\"com.acme.sim\">\n      <acme:Solver xmlns:acme=\"{ACME}\" kind=\"fixed\"><acme:Order>2</acme:Order></acme:Solver>\n    </Tool>\n    <Tool name=\"org.other\"/>\n  </VendorAnnotations>\n  <ModelVariables>"
        ),
    );
    edit(
        &xml,
        "<Real unit=\"1\" start=\"0\"/>\n",
        "<Real unit=\"1\" start=\"0\"/>\n      <Annotations>\n        <Tool name=\"com.acme.sim\"><Calibration source=\"bench 3\">text &amp; more</Calibration></Tool>\n      </Annotations>\n",
    )
}

/// Vendor attributes on CoSimulation, ScalarVariable and Real, and an optional standard
/// element (`SourceFiles`) our exporter does not write.
fn vendor_attributes(xml: &str) -> String {
    let xml = edit(
        xml,
        "providesDirectionalDerivative=\"false\"/>",
        &format!("providesDirectionalDerivative=\"false\" xmlns:acme=\"{ACME}\" acme:threads=\"1\">\n    <SourceFiles><File name=\"faulty.c\"/></SourceFiles>\n  </CoSimulation>"),
    );
    let xml = edit(
        &xml,
        "causality=\"input\" variability=\"continuous\">",
        &format!("causality=\"input\" variability=\"continuous\" xmlns:acme=\"{ACME}\" acme:color=\"red\">"),
    );
    edit(
        &xml,
        "<Real unit=\"1\" start=\"0\"/>",
        &format!("<Real xmlns:acme=\"{ACME}\" unit=\"1\" acme:quantity=\"Ratio\" start=\"0\" vendorHint=\"3\"/>"),
    )
}

fn cache() -> Arc<FmuCache> {
    Arc::new(FmuCache::temporary(false).unwrap())
}

fn system(dir: &Path, fmus: &[(&str, &Path)], body: &str) -> Result<Plan, SystemError> {
    let mut text = format!("{body}\n[fmus]\n");
    for (k, p) in fmus {
        text.push_str(&format!("{k} = \"{}\"\n", p.display()));
    }
    let path = dir.join("system.toml");
    let file = SystemFile::parse(&text, &path)?;
    Plan::from_file(file, &path, cache())
}

fn run(sys: Plan) -> Table {
    let mut sim = Simulation::new(sys).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    assert_eq!(s.steps, 1000);
    sim.recording().clone()
}

/// `src` (u = 1, gain 2) drives `dst` through `y_direct -> u`: dst.y = 2·t.
const CHAIN: &str = r#"connections = ["src.y_direct -> dst.u"]
[[instance]]
name = "src"
fmu = "third_party"

[[instance]]
name = "dst"
fmu = "third_party"

[parameters]
"src.u" = 1.0
"src.gain" = 2.0

[experiment]
step = 1e-3
stop = 1.0

[record]
signals = ["src.y", "src.y_direct", "dst.u", "dst.y", "dst.steps"]
"#;

#[test]
fn fmus_with_extra_root_attributes_annotations_and_vendor_attributes_load_and_run() {
    let original = faulty_xml();
    let dir = tempfile::tempdir().unwrap();
    fn all(x: &str) -> String {
        vendor_attributes(&annotations(&extra_root_attributes(x)))
    }
    type Rewrite = fn(&str) -> String;
    let cases: [(&str, Rewrite); 4] = [
        ("extra_root_attributes", extra_root_attributes),
        ("annotations", annotations),
        ("vendor_attributes", vendor_attributes),
        ("all", all),
    ];
    for (name, rewrite) in cases {
        let xml = rewrite(&original);
        let fmu = repack(dir.path(), name, &xml);
        // The reader keeps what it needs from the standard part.
        let loaded = cache().load(&fmu).unwrap_or_else(|e| panic!("{name}: {e}"));
        let md = &loaded.description;
        assert_eq!(md.model_name, "faulty", "{name}");
        let u = md.variable("u").unwrap();
        assert_eq!(
            (u.causality.xml_name(), u.start.as_deref()),
            ("input", Some("0")),
            "{name}"
        );
        assert_eq!(md.unit_of(u), Some("1"), "{name}");
        assert_eq!(md.outputs.len(), 4, "{name}");
        // And it runs in a system.
        let sys = system(dir.path(), &[("third_party", &fmu)], CHAIN)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let rec = run(sys);
        let y = *rec.require("dst.y").unwrap().last().unwrap();
        assert!((y - 2.0).abs() < 1e-9, "{name}: dst.y(1 s) = {y}");
        assert_eq!(*rec.require("dst.steps").unwrap().last().unwrap(), 1000.0);
    }
}

#[test]
fn units_unknown_to_us_but_defined_by_the_fmus_are_converted() {
    let original = faulty_xml();
    let dir = tempfile::tempdir().unwrap();
    // The source's y_direct is in hours and degrees Celsius; the sinks' u in minutes and
    // degrees Fahrenheit. None of these names is in our unit table.
    let with_unit = |name: &str, var: &str, unit: &str, base: &str| {
        with_unit(dir.path(), &original, name, var, unit, base)
    };
    assert!(tb_fmi::import::description::ModelDescription::default()
        .unit_def("hr")
        .is_none());
    for u in ["hr", "mins", "degC", "degF", "furlong"] {
        assert!(fmu_export::units::lookup(u).is_none(), "{u} is known to us");
    }
    let src_h = with_unit("src_h", "y_direct", "hr", "s=\"1\" factor=\"3600\"");
    let dst_min = with_unit("dst_min", "u", "mins", "s=\"1\" factor=\"60\"");
    let src_c = with_unit("src_c", "y_direct", "degC", "K=\"1\" offset=\"273.15\"");
    let dst_f = with_unit(
        "dst_f",
        "u",
        "degF",
        "K=\"1\" factor=\"0.5555555555555556\" offset=\"255.3722222222222\"",
    );
    let body = r#"connections = ["time.y_direct -> minutes.u", "celsius.y_direct -> fahrenheit.u"]
[[instance]]
name = "time"
fmu = "src_h"

[[instance]]
name = "minutes"
fmu = "dst_min"

[[instance]]
name = "celsius"
fmu = "src_c"

[[instance]]
name = "fahrenheit"
fmu = "dst_f"

[parameters]
"time.u" = 1.0
"time.gain" = 0.5
"celsius.u" = 1.0
"celsius.gain" = 100.0

[experiment]
step = 1e-3
stop = 1.0

[record]
signals = ["minutes.u", "fahrenheit.u"]
"#;
    let sys = system(
        dir.path(),
        &[
            ("src_h", &src_h),
            ("dst_min", &dst_min),
            ("src_c", &src_c),
            ("dst_f", &dst_f),
        ],
        body,
    )
    .unwrap();
    let conv = |text: &str| {
        let c = sys.connections.iter().find(|c| c.text == text).unwrap();
        (c.scale, c.offset)
    };
    let (s, o) = conv("time.y_direct -> minutes.u");
    assert!((s - 60.0).abs() < 1e-12 && o == 0.0, "h -> min: {s}, {o}");
    let (s, o) = conv("celsius.y_direct -> fahrenheit.u");
    assert!(
        (s - 1.8).abs() < 1e-12 && (o - 32.0).abs() < 1e-9,
        "degC -> degF: {s}, {o}"
    );
    let rec = run(sys);
    // 0.5 h = 30 min; 100 °C = 212 °F.
    for (name, expected) in [("minutes.u", 30.0), ("fahrenheit.u", 212.0)] {
        for x in rec.require(name).unwrap() {
            assert!(
                (x - expected).abs() < 1e-9,
                "{name} = {x}, expected {expected}"
            );
        }
    }
    // A unit nobody defines is refused, naming both units.
    let undefined = repack(
        dir.path(),
        "undefined",
        &edit(
            &original,
            "<Real unit=\"1\" start=\"0\"/>",
            "<Real unit=\"furlong\" start=\"0\"/>",
        ),
    );
    let e = match system(
        dir.path(),
        &[("src_h", &src_h), ("undefined", &undefined)],
        "connections = [\"a.y_direct -> b.u\"]\n[[instance]]\nname = \"a\"\nfmu = \"src_h\"\n\n[[instance]]\nname = \"b\"\nfmu = \"undefined\"\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n",
    ) {
        Ok(_) => panic!("a connection to an undefined unit was accepted"),
        Err(e) => e,
    };
    assert!(
        matches!(&e, SystemError::Conversion { error: ConversionError::NoDefinition { from, to }, .. }
            if from == "hr" && to == "furlong"),
        "{e}"
    );
}

/// `faulty` with `var` ("u" or "y_direct") declared in `unit`, defined by `<BaseUnit base/>`.
fn with_unit(dir: &Path, original: &str, name: &str, var: &str, unit: &str, base: &str) -> PathBuf {
    let defs = "<UnitDefinitions>\n";
    let xml = edit(
        original,
        defs,
        &format!(
            "{defs}    <Unit name=\"{unit}\">\n      <BaseUnit {base}/>\n      <DisplayUnit name=\"x{unit}\" factor=\"2\"/>\n    </Unit>\n"
        ),
    );
    let (from, to) = match var {
        "u" => ("<Real unit=\"1\" start=\"0\"/>".to_string(), format!("<Real unit=\"{unit}\" start=\"0\"/>")),
        _ => (
            "gain·u: direct feed-through of the input\" causality=\"output\" variability=\"continuous\">\n      <Real unit=\"1\"/>".to_string(),
            format!("gain·u: direct feed-through of the input\" causality=\"output\" variability=\"continuous\">\n      <Real unit=\"{unit}\"/>"),
        ),
    };
    repack(dir, name, &edit(&xml, &from, &to))
}

/// Two instances `a` (of `src`, u = 1, gain 1: y_direct = 1) and `b` (of `dst`), joined by
/// `connection`; b.u recorded.
fn pair(dir: &Path, src: &Path, dst: &Path, connection: &str) -> Result<Plan, SystemError> {
    system(
        dir,
        &[("src", src), ("dst", dst)],
        &format!(
            "connections = [{connection}]\n[[instance]]\nname = \"a\"\nfmu = \"src\"\n\n[[instance]]\nname = \"b\"\nfmu = \"dst\"\n\n[parameters]\n\"a.u\" = 1.0\n\"a.gain\" = 1.0\n\n[experiment]\nstep = 1e-3\nstop = 1.0\n\n[record]\nsignals = [\"b.u\"]\n"
        ),
    )
}

#[test]
fn a_suppliers_rpm_without_rad_converts_and_the_system_file_can_override_units() {
    let original = faulty_xml();
    let dir = tb_testkit::scratch("rpm");
    let d = dir.path();
    // Ours: rad/s with the rad exponent; the supplier's: rpm as 1/s with a factor.
    let rad_s = with_unit(
        d,
        &original,
        "rad_s",
        "y_direct",
        "rad/s",
        "s=\"-1\" rad=\"1\"",
    );
    let rpm = with_unit(
        d,
        &original,
        "rpm_1_s",
        "u",
        "rpm",
        "s=\"-1\" factor=\"0.10471975511965977\"",
    );
    let sys = pair(d, &rad_s, &rpm, "\"a.y_direct -> b.u\"").unwrap();
    assert_eq!(sys.notes.len(), 1, "{:?}", sys.notes);
    assert_contains(&sys.notes[0], &["differ only in their rad exponent (1 and 0): rad taken as dimensionless (SI), 1 rad/s = 9.549"]);
    let rec = run(sys);
    // 1 rad/s = 30/π rpm.
    for x in rec.require("b.u").unwrap() {
        assert!((x - 30.0 / std::f64::consts::PI).abs() < 1e-12, "{x}");
    }
    // A unit nobody defines: a gain given in the system file, or a unit named for it.
    let furlong = with_unit(
        d,
        &original,
        "furlong",
        "u",
        "furlong",
        "m=\"1\" factor=\"201.168\"",
    );
    let undefined = repack(
        d,
        "undefined",
        &edit(
            &original,
            "<Real unit=\"1\" start=\"0\"/>",
            "<Real unit=\"fur\" start=\"0\"/>",
        ),
    );
    let Err(e) = pair(d, &furlong, &undefined, "\"a.y_direct -> b.u\"") else {
        panic!("a connection to an undefined unit was accepted")
    };
    assert!(
        matches!(&e, SystemError::Conversion { error: ConversionError::NoDefinition { from, to }, .. }
            if from == "1" && to == "fur"),
        "{e}"
    );
    let by_gain = pair(
        d,
        &rad_s,
        &undefined,
        "{ from = \"a.y_direct\", to = \"b.u\", scale = 4.0, offset = 0.5 }",
    )
    .unwrap();
    assert!(by_gain.notes[0].contains("scale 4 and offset 0.5 from the system file (declared units 'rad/s' and 'fur' not used)"), "{:?}", by_gain.notes);
    for x in run(by_gain).require("b.u").unwrap() {
        assert_eq!(*x, 4.5);
    }
    let by_unit = pair(
        d,
        &rad_s,
        &undefined,
        "{ from = \"a.y_direct\", to = \"b.u\", to_unit = \"deg/s\" }",
    )
    .unwrap();
    assert!(
        by_unit.notes[0].contains("units overridden in the system file: 'rad/s' -> 'deg/s'"),
        "{:?}",
        by_unit.notes
    );
    for x in run(by_unit).require("b.u").unwrap() {
        assert!((x - 180.0 / std::f64::consts::PI).abs() < 1e-12, "{x}");
    }
    // The SSP export carries the gain as the connection's linear transformation.
    let plan = pair(
        d,
        &rad_s,
        &rpm,
        "{ from = \"a.y_direct\", to = \"b.u\", scale = 2.0 }",
    )
    .unwrap();
    let conn = &plan.connections[0];
    assert_eq!((conn.scale, conn.offset), (2.0, 0.0));
}

#[test]
fn missing_initial_unknowns_are_warned_about_as_fmpy_flags_them() {
    let scratch = tb_testkit::scratch("noinitial");
    let d = scratch.path();
    let original = faulty_xml();
    let start = original.find("    <InitialUnknowns>").unwrap();
    let end = original.find("</InitialUnknowns>\n").unwrap() + "</InitialUnknowns>\n".len();
    let stripped = format!("{}{}", &original[..start], &original[end..]);
    let fmu = repack(d, "noinitial", &stripped);
    let text = format!(
        "[fmus]\nx = \"{}\"\n\n[[instance]]\nname = \"a\"\nfmu = \"x\"\n\n[experiment]\nstep = 1e-3\nstop = 0.01\n",
        fmu.display()
    );
    let path = d.join("sys.toml");
    let sys = Plan::from_file(SystemFile::parse(&text, &path).unwrap(), &path, cache()).unwrap();
    let w = sys.warnings.join("\n");
    assert_contains(&w, &["ModelStructure/InitialUnknowns is missing; it must list 4 variable(s) computed at initialisation"]);
    // The original lists them all: no warning.
    repack(d, "complete", &original);
    let text = text.replace("noinitial.fmu", "complete.fmu");
    let sys = Plan::from_file(SystemFile::parse(&text, &path).unwrap(), &path, cache()).unwrap();
    assert!(
        sys.warnings.iter().all(|w| !w.contains("ModelStructure")),
        "{:?}",
        sys.warnings
    );
    // FMPy's validator flags the stripped FMU too (the same standard rule).
    let out = std::process::Command::new(common::python::python())
        .args(["-c", "import sys; from fmpy.validation import validate_fmu; p = validate_fmu(sys.argv[1]); print(len(p)); print(*p, sep='\\n')"])
        .arg(d.join("noinitial.fmu"))
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    common::cli::assert_success(&out);
    assert!(
        said.lines().next().unwrap().trim() != "0",
        "FMPy found nothing: {said}"
    );
}

#[test]
fn an_unconnected_input_without_a_start_value_is_warned_about() {
    let scratch = tb_testkit::scratch("nostart");
    let dir = scratch.path().to_path_buf();
    let xml = edit(
        &faulty_xml(),
        "<Real unit=\"1\" start=\"0\"/>",
        "<Real unit=\"1\"/>",
    );
    let fmu = repack(&dir, "nostart", &xml);
    let text = format!(
        "[fmus]\nx = \"{}\"\n\n[[instance]]\nname = \"a\"\nfmu = \"x\"\n\n[experiment]\nstep = 1e-3\nstop = 0.01\n",
        fmu.display()
    );
    let path = dir.join("sys.toml");
    let file = SystemFile::parse(&text, &path).unwrap();
    let system =
        Plan::from_file(file, &path, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    assert_eq!(
        system.warnings,
        vec!["input 'a.u' is not connected and has no start value".to_string()]
    );
}
