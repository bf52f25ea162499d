//! What the tests of `tb-cosim` share: the test models ([`models`]), their FMUs written as
//! description-only archives (a `modelDescription.xml`, no binary: the models run natively),
//! and a scratch bench that writes system files next to them and compiles them.
#![allow(dead_code)]

pub mod kinds;
pub mod models;

use fmu_export::Model;
use models::{Gain, Integrator, Sink, Source};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::native::NativeModel;
use tb_cosim::{LoadOptions, Plan, RunSummary, Simulation, SystemError};
use tb_fmi::FmuCache;

/// Every test model, as the native backend links them.
pub fn native_models() -> Vec<NativeModel> {
    vec![
        NativeModel::of::<Gain>(),
        NativeModel::of::<Integrator>(),
        NativeModel::of::<Source>(),
        NativeModel::of::<Sink>(),
    ]
}

/// Every instance runs natively (the test FMUs have no binary to run otherwise).
pub fn options() -> LoadOptions {
    LoadOptions {
        native: true,
        native_models: native_models(),
        ..Default::default()
    }
}

/// A model's modelDescription.xml, rendered from its variable table as `pack` does.
pub fn description<M: Model>() -> String {
    fmu_export::description::render_model_description::<M>(
        include_str!("../../../../fmu-templates/modelDescription.xml"),
        "tb-cosim tests",
    )
}

/// The `<ScalarVariable>` element of `name` in `xml` (start and end offsets).
fn variable_element(xml: &str, name: &str) -> (usize, usize) {
    let start = xml
        .find(&format!("<ScalarVariable name=\"{name}\""))
        .unwrap_or_else(|| panic!("no variable {name}"));
    let end = start + xml[start..].find("</ScalarVariable>").unwrap();
    (start, end)
}

/// `xml` with the Integer variable `name` declared as an Enumeration of type `ty`.
pub fn as_enumeration(xml: &str, name: &str, ty: &str) -> String {
    let (start, end) = variable_element(xml, name);
    let element =
        xml[start..end].replace("<Integer", &format!("<Enumeration declaredType=\"{ty}\""));
    format!("{}{element}{}", &xml[..start], &xml[end..])
}

/// `xml` with `TypeDefinitions` holding Enumerations: (type, [(item, value)]).
pub fn with_enumerations(xml: &str, types: &[(&str, &[(&str, i32)])]) -> String {
    let mut defs = String::from("  <TypeDefinitions>\n");
    for (ty, items) in types {
        defs.push_str(&format!(
            "    <SimpleType name=\"{ty}\">\n      <Enumeration>\n"
        ));
        for (item, value) in *items {
            defs.push_str(&format!(
                "        <Item name=\"{item}\" value=\"{value}\"/>\n"
            ));
        }
        defs.push_str("      </Enumeration>\n    </SimpleType>\n");
    }
    defs.push_str("  </TypeDefinitions>\n");
    let at = xml
        .find("  <LogCategories>")
        .expect("a LogCategories element");
    format!("{}{defs}{}", &xml[..at], &xml[at..])
}

/// `xml` with further `<Unit>` elements (name, BaseUnit attributes) of the FMU's own.
pub fn with_units(xml: &str, units: &[(&str, &str)]) -> String {
    let mut defs = String::new();
    for (name, base) in units {
        defs.push_str(&format!(
            "    <Unit name=\"{name}\">\n      <BaseUnit {base}/>\n    </Unit>\n"
        ));
    }
    let at = xml
        .find("  </UnitDefinitions>")
        .expect("a UnitDefinitions element");
    format!("{}{defs}{}", &xml[..at], &xml[at..])
}

/// The 1-based index of the variable `name` in `xml` (as `<Unknown index=..>` counts).
fn variable_index(xml: &str, name: &str) -> usize {
    let names: Vec<&str> = xml
        .match_indices("<ScalarVariable name=\"")
        .map(|(i, m)| {
            let rest = &xml[i + m.len()..];
            &rest[..rest.find('"').unwrap()]
        })
        .collect();
    names.iter().position(|n| *n == name).unwrap() + 1
}

/// Where `unknown` (the head of an `<Unknown>` element) starts within `<Outputs>`.
fn output_entry(xml: &str, unknown: &str) -> usize {
    let outputs = xml.find("<Outputs>").unwrap();
    outputs + xml[outputs..].find(unknown).unwrap()
}

/// `xml` without the output `name`'s entry in `<Outputs>` (an FMU whose ModelStructure
/// leaves an output out: it may depend on every input).
pub fn unlisted_output(xml: &str, name: &str) -> String {
    let index = variable_index(xml, name);
    let unknown = format!("<Unknown index=\"{index}\"");
    let at = output_entry(xml, &unknown);
    let end = at + xml[at..].find("/>").unwrap() + 2;
    format!("{}{}", &xml[..at], &xml[end..])
}

/// `xml` without the `dependencies` attribute of the output `name` in `<Outputs>`: "may
/// depend on every input", as the standard reads it.
pub fn without_dependencies(xml: &str, name: &str) -> String {
    let index = variable_index(xml, name);
    let unknown = format!("<Unknown index=\"{index}\" dependencies=\"");
    let at = output_entry(xml, &unknown);
    let end = at + unknown.len() + xml[at + unknown.len()..].find('"').unwrap() + 1;
    format!("{}<Unknown index=\"{index}\"{}", &xml[..at], &xml[end..])
}

/// `xml` with `unit="..."` on the type element of each named Real variable (units the
/// variable table cannot declare: the FMU's own).
pub fn with_variable_units(xml: &str, units: &[(&str, &str)]) -> String {
    let mut xml = xml.to_string();
    for (name, unit) in units {
        let head = format!("<ScalarVariable name=\"{name}\"");
        let at = xml
            .find(&head)
            .unwrap_or_else(|| panic!("no variable {name}"));
        let real = at + xml[at..].find("<Real").expect("a Real variable") + "<Real".len();
        xml.insert_str(real, &format!(" unit=\"{unit}\""));
    }
    xml
}

const GEARS: &[(&str, i32)] = &[("first", 1), ("second", 2), ("third", 3)];
const MODES: &[(&str, i32)] = &[("eco", 1), ("normal", 2), ("sport", 3)];
/// Units the FMUs define themselves (not in twinbench's table).
const OWN_UNITS: &[(&str, &str)] = &[("degC", "K=\"1\" offset=\"273.15\""), ("K", "K=\"1\"")];

/// The test FMUs' descriptions by file stem: the four models, `gain_nodeps` (a gain whose
/// output declares no dependencies) and `gain_unlisted` (one whose output is missing from
/// the ModelStructure).
pub fn descriptions() -> Vec<(&'static str, String)> {
    let source = as_enumeration(&description::<Source>(), "gear", "Gear");
    let source = with_units(&with_enumerations(&source, &[("Gear", GEARS)]), OWN_UNITS);
    let source = with_variable_units(&source, &[("temp", "degC")]);
    let sink = as_enumeration(&description::<Sink>(), "gear_in", "Gear");
    let sink = as_enumeration(&as_enumeration(&sink, "gear_out", "Gear"), "mode", "Mode");
    let sink = with_enumerations(&sink, &[("Gear", GEARS), ("Mode", MODES)]);
    let sink = with_units(&sink, OWN_UNITS);
    let sink = with_variable_units(&sink, &[("temp_k", "K"), ("temp_out", "K")]);
    vec![
        ("gain", description::<Gain>()),
        (
            "gain_nodeps",
            without_dependencies(&description::<Gain>(), "y"),
        ),
        (
            "gain_unlisted",
            unlisted_output(&description::<Gain>(), "y"),
        ),
        ("integrator", description::<Integrator>()),
        ("source", source),
        ("sink", sink),
    ]
}

/// An FMU archive holding only `modelDescription.xml` (and `extra` entries).
pub fn write_fmu(path: &Path, xml: &str, extra: &[(&str, &[u8])]) {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let opts = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("modelDescription.xml", opts).unwrap();
    zip.write_all(xml.as_bytes()).unwrap();
    for (name, bytes) in extra {
        zip.start_file(*name, opts).unwrap();
        zip.write_all(bytes).unwrap();
    }
    let bytes = zip.finish().unwrap().into_inner();
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, bytes).unwrap();
}

/// A scratch folder with the test FMUs in `fmu/`, a cache that accepts description-only
/// FMUs, and the system files the test writes. Removed when dropped.
pub struct Bench {
    pub dir: tempfile::TempDir,
    pub cache: Arc<FmuCache>,
}

impl Bench {
    pub fn new() -> Bench {
        let dir = tb_testkit::scratch("cosim");
        for (stem, xml) in descriptions() {
            write_fmu(&dir.path().join(format!("fmu/{stem}.fmu")), &xml, &[]);
        }
        let cache = FmuCache::persistent(&dir.path().join("cache"))
            .unwrap()
            .description_only();
        Bench {
            dir,
            cache: Arc::new(cache),
        }
    }

    pub fn path(&self, relative: &str) -> PathBuf {
        self.dir.path().join(relative)
    }

    /// Write a file of the bench (folders created).
    pub fn write(&self, relative: &str, text: &str) -> PathBuf {
        let p = self.path(relative);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(&p, text).unwrap();
        p
    }

    /// `system.toml`: `body`, then `[fmus]` naming every test FMU relative to the file.
    pub fn system(&self, body: &str) -> PathBuf {
        self.system_named("system.toml", body)
    }

    pub fn system_named(&self, relative: &str, body: &str) -> PathBuf {
        let depth = relative.matches('/').count();
        let up = "../".repeat(depth);
        let mut text = format!("{body}\n\n[fmus]\n");
        for (stem, _) in descriptions() {
            text.push_str(&format!("{stem} = \"{up}fmu/{stem}.fmu\"\n"));
        }
        self.write(relative, &text)
    }

    /// The plan of a system file (natively run test models).
    pub fn load(&self, path: &Path) -> Result<Plan, SystemError> {
        Plan::load_with(path, self.cache.clone(), &options())
    }

    pub fn plan(&self, body: &str) -> Result<Plan, SystemError> {
        self.load(&self.system(body))
    }

    /// The plan's error, as the command line prints it.
    pub fn error(&self, body: &str) -> String {
        match self.plan(body) {
            Ok(_) => panic!("the system compiled:\n{body}"),
            Err(e) => e.to_string(),
        }
    }

    pub fn sim(&self, body: &str) -> Simulation {
        let plan = self.plan(body).unwrap_or_else(|e| panic!("{e}\n{body}"));
        quiet(Simulation::new(plan).unwrap())
    }

    /// Compile and run once.
    pub fn run(&self, body: &str) -> (Simulation, RunSummary) {
        let mut sim = self.sim(body);
        let summary = sim.run().unwrap_or_else(|e| panic!("{e}\n{body}"));
        (sim, summary)
    }

    /// Each case's system file, `system(case)`, is refused with an error that holds every
    /// part of `common` and the case's own (see [`assert_refusals`]).
    pub fn refuses(
        &self,
        cases: &[(&str, &str)],
        common: &[&str],
        system: impl Fn(&str) -> String,
    ) {
        assert_refusals(cases, common, |case| self.error(&system(case)));
    }
}

/// `[[instance]]` tables, one for each (name, FMU stem), each followed by a blank line.
pub fn instances(list: &[(&str, &str)]) -> String {
    list.iter()
        .map(|(name, fmu)| format!("[[instance]]\nname = \"{name}\"\nfmu = \"{fmu}\"\n\n"))
        .collect()
}

/// The `[[instance]]` tables of the chain `int` (integrator) -> `g1` -> `g2` (gains),
/// declared consumers first.
pub fn chain_instances() -> String {
    instances(&[("g2", "gain"), ("g1", "gain"), ("int", "integrator")])
}

/// Each case's error holds its expected text and every one of `common`: `error` gives the
/// error for a case's input, and a failure names the case.
#[track_caller]
pub fn assert_refusals(cases: &[(&str, &str)], common: &[&str], error: impl Fn(&str) -> String) {
    for (case, expected) in cases {
        let e = error(case);
        for part in common.iter().chain([expected]) {
            assert!(e.contains(part), "case {case}: {part:?} is not in:\n{e}");
        }
    }
}

/// A simulation that keeps the models' messages for error reports only.
pub fn quiet(mut sim: Simulation) -> Simulation {
    sim.echo_fmu_log = false;
    sim
}

/// A recorded numeric column.
pub fn column<'a>(sim: &'a Simulation, name: &str) -> &'a [f64] {
    sim.recording()
        .require(name)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// A recorded text column.
pub fn texts<'a>(sim: &'a Simulation, name: &str) -> &'a [String] {
    let k = sim
        .recording()
        .names()
        .iter()
        .position(|n| n == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    sim.recording().text_at(k).expect("a text column")
}

/// The last recorded value of a column.
pub fn last(sim: &Simulation, name: &str) -> f64 {
    *column(sim, name).last().expect("a recorded row")
}

/// `|a − b| ≤ tol`, with both in the message.
#[track_caller]
pub fn assert_close(a: f64, b: f64, tol: f64) {
    assert!(
        (a - b).abs() <= tol,
        "{a} differs from {b} by more than {tol}"
    );
}
