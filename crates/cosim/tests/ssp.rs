//! SSP 1.0 export and import round trips over the test models: the imported system is the
//! exported one (instances, connections with their conversion, typed parameters, the
//! experiment, recording, report, checks) and runs bit for bit like it; and the packages
//! the import refuses.

mod support;

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use support::Bench;
use tb_cosim::ssp::{export, ExportOptions, SspError};
use tb_cosim::ssp_import::SspImportError;
use tb_cosim::{ssp_import, Algorithm, Simulation, StopConfig, SystemError};
use tb_fmi::FmuError;
use tb_testkit::assert_contains;

/// Every kind of connection and parameter, a stop condition, a report and a check.
fn system(algorithm: &str) -> String {
    format!(
        r#"name = "round"
connections = [
    "int.x -> g.u",
    "src.y_kmh -> snk.v",
    "src.temp -> snk.temp_k",
    {{ from = "src.y_rpm", to = "snk.w", scale = 2.0, offset = 0.5 }},
    "src.label -> snk.text",
    "src.gear -> snk.gear_in",
    "src.count -> snk.n",
    "src.odd -> snk.on",
]

[[instance]]
name = "int"
fmu = "integrator"
ports = {{ rate = "u" }}

[[instance]]
name = "g"
fmu = "gain"

[[instance]]
name = "src"
fmu = "source"

[[instance]]
name = "snk"
fmu = "sink"

[parameters]
"int.rate" = 0.5
"int.x0" = 1.0
"g.k" = -3.0
"src.speed" = 72.0
"src.prefix" = "lap "
"snk.level" = 4
"snk.mode" = 3
"snk.invert" = true
"snk.name" = "got"

[experiment]
step = 0.125
stop = "int.steps >= 12"
max_time = 10.0
algorithm = "{algorithm}"
report = ["g.y", "snk.n_out"]

[record]
signals = ["int.x", "g.y", "snk.v_out", "snk.w_out", "snk.temp_out", "snk.text_out", "snk.gear_out", "snk.n_out", "snk.on_out", "snk.mode_out", "snk.level_out"]
decimation = 2

[[check]]
equal = ["src.y_kmh", "src.y_rpm"]
relative_tolerance = 0.01
why = "speeds agree"
"#
    )
}

/// The system exported to `<bench>/round.ssp`, and the export's summary.
fn exported(b: &Bench, algorithm: &str) -> (PathBuf, tb_cosim::ssp::ExportSummary) {
    let plan = b.plan(&system(algorithm)).unwrap();
    let out = b.path("round.ssp");
    let summary = export(&plan, &out, &ExportOptions::default()).unwrap();
    (out, summary)
}

/// An entry of a zip archive as text.
fn entry(zip: &Path, name: &str) -> String {
    let mut a = zip::ZipArchive::new(std::fs::File::open(zip).unwrap()).unwrap();
    let mut text = String::new();
    a.by_name(name).unwrap().read_to_string(&mut text).unwrap();
    text
}

/// `zip` rewritten to `out` with `edit` applied to each (name, bytes); None leaves it out.
fn rewrite(zip: &Path, out: &Path, edit: impl Fn(&str, Vec<u8>) -> Option<Vec<u8>>) {
    let mut a = zip::ZipArchive::new(std::fs::File::open(zip).unwrap()).unwrap();
    let mut w = zip::ZipWriter::new(std::fs::File::create(out).unwrap());
    for i in 0..a.len() {
        let mut f = a.by_index(i).unwrap();
        let name = f.name().to_string();
        let mut bytes = Vec::new();
        f.read_to_end(&mut bytes).unwrap();
        if let Some(bytes) = edit(&name, bytes) {
            w.start_file(name, zip::write::SimpleFileOptions::default())
                .unwrap();
            w.write_all(&bytes).unwrap();
        }
    }
    w.finish().unwrap();
}

/// `zip` rewritten to `out` with its SystemStructure.ssd as `edit` makes it.
fn rewrite_ssd(zip: &Path, out: &Path, edit: impl Fn(Vec<u8>) -> Vec<u8>) {
    rewrite(zip, out, |n, bytes| {
        Some(if n == "SystemStructure.ssd" {
            edit(bytes)
        } else {
            bytes
        })
    });
}

/// `zip` rewritten to `out` with `from` replaced by `to` in its SystemStructure.ssd.
fn replace_in_ssd(zip: &Path, out: &Path, from: &str, to: &str) {
    rewrite_ssd(zip, out, |ssd| {
        let text = String::from_utf8(ssd).unwrap();
        text.replace(from, to).into_bytes()
    });
}

fn run(b: &Bench, path: &Path) -> (Simulation, tb_cosim::RunSummary) {
    let mut sim = support::quiet(Simulation::new(b.load(path).unwrap()).unwrap());
    let summary = sim.run().unwrap();
    (sim, summary)
}

#[test]
fn an_export_says_what_it_wrote() {
    let b = Bench::new();
    let (out, summary) = exported(&b, "gauss-seidel");
    assert_eq!(
        (summary.components, summary.connections, summary.parameters),
        (4, 8, 9)
    );
    assert_eq!(
        summary.fmus,
        [
            "resources/integrator.fmu",
            "resources/gain.fmu",
            "resources/source.fmu",
            "resources/sink.fmu"
        ]
    );
    // The stop time of a condition is start + max_time.
    assert_eq!(
        (summary.start_time, summary.stop_time, summary.step),
        (0.0, 10.0, 0.125)
    );
    // "int.rate" is an input set as a start value: said, and given no connector.
    assert_contains(
        &summary.notes.join("\n"),
        &["'int.rate' is an input set as a start value"],
    );
    // The package holds the SSD and the FMUs as they were.
    let ssd = entry(&out, "SystemStructure.ssd");
    assert_contains(
        &ssd,
        &[
            "<ssd:Component name=\"int\" type=\"application/x-fmu-sharedlibrary\" source=\"resources/integrator.fmu\">",
            "<ssv:Parameter name=\"u\"><ssv:Real value=\"0.5\" unit=\"m/s\"/></ssv:Parameter>",
            "<ssv:Parameter name=\"mode\"><ssv:Enumeration value=\"sport\"/></ssv:Parameter>",
            "<ssv:Parameter name=\"prefix\"><ssv:String value=\"lap \"/></ssv:Parameter>",
            "<ssv:Parameter name=\"invert\"><ssv:Boolean value=\"true\"/></ssv:Parameter>",
            "<ssc:LinearTransformation factor=\"2.0\" offset=\"0.5\"/>",
            "<ssc:LinearTransformation factor=\"1.0\" offset=\"273.15\"/>",
            "<ssc:Unit name=\"degC\"><ssc:BaseUnit K=\"1\" offset=\"273.15\"/></ssc:Unit>",
            "<osp:FixedStepAlgorithm baseStepSize=\"0.125\"/>",
        ],
    );
    let mut a = zip::ZipArchive::new(std::fs::File::open(&out).unwrap()).unwrap();
    let mut packed = Vec::new();
    a.by_name("resources/sink.fmu")
        .unwrap()
        .read_to_end(&mut packed)
        .unwrap();
    assert_eq!(packed, std::fs::read(b.path("fmu/sink.fmu")).unwrap());
}

#[test]
fn an_imported_package_is_the_exported_system() {
    let b = Bench::new();
    let (out, _) = exported(&b, "jacobi");
    let f = ssp_import::load(&out, &b.cache).unwrap();
    assert_eq!(f.name.as_deref(), Some("round"));
    let instances: Vec<(&str, &str)> = f
        .instances
        .iter()
        .map(|i| (i.name.as_str(), i.fmu.as_str()))
        .collect();
    assert_eq!(
        instances,
        [
            ("int", "integrator"),
            ("g", "gain"),
            ("src", "source"),
            ("snk", "sink")
        ]
    );
    // Port maps are resolved: the package names the FMUs' variables.
    let texts: Vec<&str> = f.connections.iter().map(|c| c.text.as_str()).collect();
    assert!(texts.contains(&"int.x -> g.u"), "{texts:?}");
    let gain = f
        .connections
        .iter()
        .find(|c| c.text == "src.y_rpm -> snk.w")
        .unwrap();
    assert_eq!((gain.scale, gain.offset), (Some(2.0), Some(0.5)));
    let p = |n: &str| f.parameters[n].clone();
    assert_eq!(p("int.u"), toml::Value::Float(0.5));
    assert_eq!(p("g.k"), toml::Value::Float(-3.0));
    assert_eq!(p("snk.level"), toml::Value::Integer(4));
    assert_eq!(p("snk.mode"), toml::Value::Integer(3));
    assert_eq!(p("snk.invert"), toml::Value::Boolean(true));
    assert_eq!(p("src.prefix"), toml::Value::String("lap ".into()));
    let e = &f.experiment;
    assert_eq!((e.start, e.step, e.max_time), (0.0, 0.125, 10.0));
    assert_eq!(e.stop, StopConfig::Word("int.steps >= 12".into()));
    assert_eq!(e.algorithm, Algorithm::Jacobi);
    assert_eq!(e.order, ["int", "g", "src", "snk"]);
    assert_eq!(e.report, ["g.y", "snk.n_out"]);
    assert_eq!(f.record.decimation, 2);
    assert_eq!(f.record.signals.len(), 11);
    assert_eq!(f.checks.len(), 1);
    assert_eq!(f.checks[0].equal, ["src.y_kmh", "src.y_rpm"]);
    assert_eq!(f.checks[0].relative_tolerance, 0.01);
    assert_eq!(f.checks[0].why.as_deref(), Some("speeds agree"));
}

#[test]
fn an_exported_package_runs_bit_for_bit_like_its_system_file() {
    let b = Bench::new();
    for algorithm in ["gauss-seidel", "jacobi"] {
        let (toml_sim, toml_summary) = b.run(&system(algorithm));
        let (out, _) = exported(&b, algorithm);
        let (ssp_sim, ssp_summary) = run(&b, &out);
        assert_eq!(toml_summary.steps, 12);
        assert_eq!(ssp_summary.steps, toml_summary.steps);
        assert_eq!(ssp_summary.reported, toml_summary.reported);
        assert_eq!(ssp_sim.recording().names(), toml_sim.recording().names());
        assert_eq!(ssp_sim.recording().units(), toml_sim.recording().units());
        assert_eq!(
            ssp_sim.recording().to_csv(),
            toml_sim.recording().to_csv(),
            "{algorithm}"
        );
    }
    // What the run computed, to know the round trip carried something: 72 km/h = 20 m/s,
    // 2·72 rpm + 0.5, 25 °C in K.
    let (sim, _) = b.run(&system("gauss-seidel"));
    support::assert_close(support::last(&sim, "snk.v_out"), 20.0, 1e-14);
    assert_eq!(support::last(&sim, "snk.w_out"), 144.5);
    support::assert_close(support::last(&sim, "snk.temp_out"), 298.15, 1e-12);
    assert_eq!(
        support::texts(&sim, "snk.text_out").last().unwrap(),
        "got:lap 12"
    );
}

#[test]
fn a_system_with_replays_has_no_ssp_equivalent() {
    let b = Bench::new();
    b.write("a.csv", "time,a\n0,0\n1,1\n");
    let plan = b
        .plan("connections = [\"r.a -> g.u\"]\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[[replay]]\nname = \"r\"\nfile = \"a.csv\"\nbasis = \"time\"\n[experiment]\nstep = 0.5\nstop = 1.0\n")
        .unwrap();
    let e = export(&plan, &b.path("r.ssp"), &ExportOptions::default()).unwrap_err();
    assert!(matches!(e, SspError::Unsupported(_)), "{e}");
    assert_contains(
        &e.to_string(),
        &[
            "replayed measurement channels (replay 'r',",
            "cannot be expressed in SSP 1.0",
        ],
    );
    assert!(!b.path("r.ssp").exists());
    // A stop time before the start is refused too.
    let plan = b.plan(&system("jacobi")).unwrap();
    let options = ExportOptions {
        stop_time: Some(-1.0),
    };
    let e = export(&plan, &b.path("r.ssp"), &options).unwrap_err();
    assert!(matches!(e, SspError::Unsupported(_)), "{e}");
    assert_contains(
        &e.to_string(),
        &["stop time -1 is not after the start time 0"],
    );
}

#[test]
fn packages_the_import_cannot_run_are_refused_naming_what_is_wrong() {
    let b = Bench::new();
    let (out, _) = exported(&b, "gauss-seidel");
    // No FMU for a component.
    let bad = b.path("nofmu.ssp");
    rewrite(&out, &bad, |n, bytes| {
        (n != "resources/gain.fmu").then_some(bytes)
    });
    let e = ssp_import::load(&bad, &b.cache).unwrap_err();
    assert!(
        matches!(&e, SspImportError::MissingFmu { ssp, component, fmu, available }
            if ssp.ends_with("nofmu.ssp") && component == "g" && fmu == "resources/gain.fmu"
                && available == "resources/integrator.fmu, resources/sink.fmu, resources/source.fmu"),
        "{e}"
    );
    // No SSD.
    let bad = b.path("nossd.ssp");
    rewrite(&out, &bad, |n, bytes| {
        (n != "SystemStructure.ssd").then_some(bytes)
    });
    let e = ssp_import::load(&bad, &b.cache).unwrap_err();
    assert!(matches!(e, SspImportError::Package { .. }), "{e}");
    assert_contains(
        &e.to_string(),
        &["nossd.ssp: the package has no SystemStructure.ssd"],
    );
    // A nested system, named with its line.
    let bad = b.path("nested.ssp");
    replace_in_ssd(
        &out,
        &bad,
        "    <ssd:Elements>\n",
        "    <ssd:Elements>\n<ssd:System name=\"inner\"/>\n",
    );
    let line = entry(&bad, "SystemStructure.ssd")
        .lines()
        .position(|l| l.contains("name=\"inner\""))
        .unwrap()
        + 1;
    let e = ssp_import::load(&bad, &b.cache).unwrap_err();
    assert!(
        matches!(&e, SspImportError::Unsupported { ssp, file, line: l, element, .. }
            if ssp.ends_with("nested.ssp") && file == "SystemStructure.ssd" && *l == line
                && element == "System"),
        "{e}"
    );
    assert_contains(&e.to_string(), &["nested systems"]);
    // Malformed XML.
    let bad = b.path("malformed.ssp");
    rewrite_ssd(&out, &bad, |ssd| ssd[..ssd.len() / 2].to_vec());
    let e = ssp_import::load(&bad, &b.cache).unwrap_err();
    assert!(
        matches!(&e, SspImportError::Xml { ssp, file, .. }
            if ssp.ends_with("malformed.ssp") && file == "SystemStructure.ssd"),
        "{e}"
    );
    // Not a zip at all.
    let bad = b.write("text.ssp", "not a package");
    let e = ssp_import::load(&bad, &b.cache).unwrap_err();
    assert!(
        matches!(&e, SspImportError::Archive(a)
            if matches!(&**a, FmuError::Archive { path, .. } if path.ends_with("text.ssp"))),
        "{e}"
    );
    assert_contains(&e.to_string(), &["not a valid zip archive"]);
    assert!(ssp_import::is_ssp(&bad) && !ssp_import::is_ssp(&b.path("system.toml")));
}

#[test]
fn a_parameter_of_a_package_must_name_a_variable_of_its_fmu() {
    let b = Bench::new();
    let (out, _) = exported(&b, "gauss-seidel");
    let bad = b.path("badparam.ssp");
    replace_in_ssd(
        &out,
        &bad,
        "<ssv:Parameter name=\"level\">",
        "<ssv:Parameter name=\"levle\">",
    );
    let e = b.load(&bad).err().expect("refused");
    assert!(
        matches!(&e, SystemError::Ssp(s)
            if matches!(&**s, SspImportError::Invalid { file, .. }
                if file == "SystemStructure.ssd")),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &[
            "badparam.ssp: SystemStructure.ssd, line ",
            "parameter 'levle' of component 'snk': the FMU resources/sink.fmu has no variable 'levle' (closest: level, limit, mode)",
        ],
    );
}

#[test]
fn a_fixed_stop_time_and_the_default_recording_round_trip() {
    let b = Bench::new();
    let text = "connections = [\"int.x -> g.u\"]\n[[instance]]\nname = \"int\"\nfmu = \"integrator\"\n[[instance]]\nname = \"g\"\nfmu = \"gain\"\n[parameters]\n\"int.u\" = 1.0\n[experiment]\nstart = 0.5\nstep = 0.25\nstop = 1.5\n";
    let plan = b.plan(text).unwrap();
    let out = b.path("plain.ssp");
    let summary = export(&plan, &out, &ExportOptions::default()).unwrap();
    assert_eq!((summary.start_time, summary.stop_time), (0.5, 1.5));
    let f = ssp_import::load(&out, &b.cache).unwrap();
    assert_eq!(f.experiment.stop, StopConfig::Time(1.5));
    assert_eq!(f.experiment.start, 0.5);
    assert_eq!(f.experiment.algorithm, Algorithm::GaussSeidel);
    assert!(f.record.signals.is_empty() && f.record.decimation == 1);
    assert!(f.checks.is_empty() && f.experiment.report.is_empty());
    let (toml_sim, _) = b.run(text);
    let (ssp_sim, summary) = run(&b, &out);
    assert_eq!(summary.steps, 4);
    assert_eq!(ssp_sim.recording().to_csv(), toml_sim.recording().to_csv());
    // x = 1·t from 0.5 to 1.5 and g.y = 2·x: exact.
    assert_eq!(
        support::column(&ssp_sim, "int.x"),
        [0.0, 0.25, 0.5, 0.75, 1.0]
    );
    assert_eq!(support::column(&ssp_sim, "g.y"), [0.0, 0.5, 1.0, 1.5, 2.0]);
}
