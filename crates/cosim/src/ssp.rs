//! SSP 1.0 export of a system (System Structure and Parameterization, Modelica Association):
//! a zip with `SystemStructure.ssd` and the FMUs under `resources/`.
//!
//! What is written:
//! - one `Component` per instance (`source="resources/<fmu key>.fmu"`), with connectors for
//!   every output, every connected input and every parameter the system sets; names are
//!   the FMU's own variable names (port maps are resolved);
//! - one `Connection` per system connection; a unit conversion becomes a
//!   `LinearTransformation` with `suppressUnitConversion="true"` (the factor and offset are
//!   exactly twinbench's);
//! - parameter values inline (`ParameterBindings/ParameterValues/ssv:ParameterSet`) per
//!   component, names relative to the component;
//! - `Units` with their SI base units, `DefaultExperiment` (start, stop), and annotations:
//!   twinbench's experiment (step, algorithm, stepping order, lap condition, recorded
//!   signals and decimation, reported values, checks: what `twinbench run X.ssp` needs to
//!   repeat the run, see [`crate::ssp_import`]) and the Open Simulation Platform's
//!   fixed-step algorithm (libcosim reads its `baseStepSize`).
//!
//! Replayed measurement channels have no SSP 1.0 equivalent and are refused.

use crate::{split_name, Endpoint, Plan, StopConfig};
use std::collections::{BTreeMap, BTreeSet};
use std::io::Write;
use std::path::Path;
use tb_fmi::import::description::ScalarVariable;
use tb_fmi::{Causality, ScalarType};

#[derive(Debug, thiserror::Error)]
pub enum SspError {
    #[error("{0}")]
    Unsupported(String),
    #[error("{path}: {message}")]
    Io { path: String, message: String },
}

/// Choices of the export.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// `DefaultExperiment/@stopTime`; default: the fixed stop time, or `max_time` for a lap.
    pub stop_time: Option<f64>,
}

/// What was written.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ExportSummary {
    pub components: usize,
    pub connectors: usize,
    pub connections: usize,
    pub parameters: usize,
    pub fmus: Vec<String>,
    pub start_time: f64,
    pub stop_time: f64,
    pub step: f64,
    pub notes: Vec<String>,
}

pub const NS_SSD: &str = "http://ssp-standard.org/SSP1/SystemStructureDescription";
pub const NS_SSC: &str = "http://ssp-standard.org/SSP1/SystemStructureCommon";
pub const NS_SSV: &str = "http://ssp-standard.org/SSP1/SystemStructureParameterValues";
const NS_OSP: &str = "http://opensimulationplatform.com/SSP/OSPAnnotations";
/// OMSimulator's annotation namespace (its importer matches the `oms:` prefix literally).
const NS_OMS: &str =
    "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd";
const NS_TB: &str = "https://github.com/twinbench/ssp";

use tb_files::markup::xml_escape as esc;

/// The instance (its index) and the FMU variable of a system-file name `instance.variable`
/// (`context`: the export that looks it up, for the message).
fn instance_variable<'a>(
    system: &'a Plan,
    full: &str,
    context: &str,
) -> Result<(usize, &'a ScalarVariable), SspError> {
    let (u, v) = split_name(full)
        .ok_or_else(|| SspError::Unsupported(format!("'{full}' is not instance.variable")))?;
    let k = system
        .instances
        .iter()
        .position(|i| i.name == u)
        .ok_or_else(|| SspError::Unsupported(format!("'{full}': not an FMU instance")))?;
    let sv = system.instances[k]
        .variable(v, context)
        .map_err(|e| SspError::Unsupported(e.to_string()))?;
    Ok((k, sv))
}

/// xs:double text that reads back to the same f64.
fn real(x: f64) -> String {
    if x.is_nan() {
        "NaN".into()
    } else if x.is_infinite() {
        if x > 0.0 { "INF" } else { "-INF" }.into()
    } else {
        format!("{x:?}")
    }
}

fn type_element(ty: ScalarType, unit: Option<&str>, enumeration: Option<&str>) -> String {
    match (ty, unit, enumeration) {
        (ScalarType::Real, Some(u), _) => format!("<ssc:Real unit=\"{}\"/>", esc(u)),
        (ScalarType::Real, None, _) => "<ssc:Real/>".into(),
        (ScalarType::Integer, ..) => "<ssc:Integer/>".into(),
        (ScalarType::Boolean, ..) => "<ssc:Boolean/>".into(),
        (ScalarType::String, ..) => "<ssc:String/>".into(),
        // An Enumeration names its type in the SSD's <Enumerations>.
        (ScalarType::Enumeration, _, Some(e)) => format!("<ssc:Enumeration name=\"{}\"/>", esc(e)),
        (ScalarType::Enumeration, _, None) => "<ssc:Integer/>".into(),
    }
}

/// The Enumeration types the SSD declares: name in the SSD, items (name, value).
#[derive(Default)]
struct Enumerations(Vec<(String, Vec<(String, i64)>)>);

impl Enumerations {
    /// The SSD name of a variable's enumeration type (declared on first use; a type of the
    /// same name with other items gets the instance's name as a prefix).
    fn name_of(
        &mut self,
        instance: &str,
        md: &tb_fmi::ModelDescription,
        sv: &tb_fmi::import::description::ScalarVariable,
    ) -> Option<String> {
        let items = md.enumeration_items(sv)?;
        let ty = sv.declared_type.as_deref()?;
        for candidate in [ty.to_string(), format!("{instance}.{ty}")] {
            match self.0.iter().find(|(n, _)| *n == candidate) {
                Some((n, i)) if i.as_slice() == items => return Some(n.clone()),
                Some(_) => continue,
                None => {
                    self.0.push((candidate.clone(), items.to_vec()));
                    return Some(candidate);
                }
            }
        }
        None
    }
}

/// The SSD text, the FMU files to pack (archive name, source path), and the summary.
pub type SystemStructure = (String, Vec<(String, std::path::PathBuf)>, ExportSummary);

/// A connector of a component: its kind (`input`, `output`, `parameter`) and type.
struct Conn {
    kind: &'static str,
    ty: ScalarType,
    unit: Option<String>,
    enumeration: Option<String>,
}

/// A connection by the FMUs' names: (from instance, its variable, to instance, its
/// variable, scale, offset).
type SspConnection = (usize, String, usize, String, f64, f64);

/// What the export gathers from the plan before it writes the document.
struct Exporter<'a> {
    system: &'a Plan,
    /// Connectors per instance, by the FMU's variable name.
    connectors: Vec<BTreeMap<String, Conn>>,
    enumerations: Enumerations,
    connections: Vec<SspConnection>,
    /// Parameter values per instance: (FMU variable name, `<ssv:...>` element).
    params: Vec<Vec<(String, String)>>,
    /// Files of path parameters packed with the FMUs: (archive name, source).
    files: Vec<(String, std::path::PathBuf)>,
    notes: Vec<String>,
}

/// Build the SystemStructure.ssd text and the list of (archive name, FMU file) to pack.
pub fn system_structure(
    system: &Plan,
    options: &ExportOptions,
) -> Result<SystemStructure, SspError> {
    let mut ex = Exporter::new(system)?;
    ex.outputs();
    ex.connections()?;
    ex.parameters()?;
    let (mut fmu_files, source_of) = fmu_files(&system.file);
    fmu_files.append(&mut ex.files);
    let (start, stop) = time_span(system, options)?;
    let mut x = String::new();
    let sys_name = system.file.name.clone().unwrap_or_else(|| {
        system
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "system".into())
    });
    x.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    x.push_str(&format!(
        "<ssd:SystemStructureDescription xmlns:ssd=\"{NS_SSD}\" xmlns:ssc=\"{NS_SSC}\" xmlns:ssv=\"{NS_SSV}\" xmlns:osp=\"{NS_OSP}\" xmlns:oms=\"{NS_OMS}\" xmlns:tb=\"{NS_TB}\" version=\"1.0\" name=\"{}\" generationTool=\"twinbench {}\">\n",
        esc(&sys_name),
        env!("CARGO_PKG_VERSION")
    ));
    x.push_str(&format!(
        "  <ssd:System name=\"{}\" description=\"exported by twinbench from {}\">\n",
        esc(&sys_name),
        esc(&system
            .path
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default())
    ));
    let n_connectors = ex.write_elements(&mut x, &source_of);
    ex.write_connections(&mut x);
    // OMSimulator decides the system's kind from its own annotation and cannot open a
    // system without one: a weakly coupled system with its fixed-step master.
    x.push_str(&format!(
        "    <ssd:Annotations>\n      <ssc:Annotation type=\"org.openmodelica\"><oms:Annotations><oms:SimulationInformation><oms:FixedStepMaster description=\"oms-ma\" stepSize=\"{}\" relativeTolerance=\"{}\"/></oms:SimulationInformation></oms:Annotations></ssc:Annotation>\n    </ssd:Annotations>\n",
        real(system.file.experiment.step),
        real(system.file.experiment.tolerance.unwrap_or(1e-4))
    ));
    x.push_str("  </ssd:System>\n");
    ex.write_enumerations(&mut x);
    ex.write_units(&mut x);
    ex.write_default_experiment(&mut x, start, stop)?;
    x.push_str("</ssd:SystemStructureDescription>\n");
    let summary = ExportSummary {
        components: system.instances.len(),
        connectors: n_connectors,
        connections: ex.connections.len(),
        parameters: ex.params.iter().map(Vec::len).sum(),
        fmus: fmu_files
            .iter()
            .filter(|f| f.0.ends_with(".fmu"))
            .map(|f| f.0.clone())
            .collect(),
        start_time: start,
        stop_time: stop,
        step: system.file.experiment.step,
        notes: ex.notes,
    };
    Ok((x, fmu_files, summary))
}

/// FMU files: one per `[fmus]` key that an instance uses, and each instance's source.
fn fmu_files(file: &crate::SystemFile) -> (Vec<(String, std::path::PathBuf)>, Vec<String>) {
    let mut fmu_files: Vec<(String, std::path::PathBuf)> = Vec::new();
    let mut source_of: Vec<String> = Vec::new();
    for inst_cfg in &file.instances {
        let name = format!("resources/{}.fmu", inst_cfg.fmu);
        if !fmu_files.iter().any(|(n, _)| *n == name) {
            fmu_files.push((name.clone(), file.fmus[&inst_cfg.fmu].clone()));
        }
        source_of.push(name);
    }
    (fmu_files, source_of)
}

/// `DefaultExperiment`'s start and stop: the fixed stop time, or the start plus `max_time`
/// for a run that stops on a condition (or the option's).
fn time_span(system: &Plan, options: &ExportOptions) -> Result<(f64, f64), SspError> {
    let exp = &system.file.experiment;
    let start = exp.start;
    let stop = options.stop_time.unwrap_or(match &exp.stop {
        StopConfig::Time(t) => *t,
        StopConfig::Word(_) => start + exp.max_time,
    });
    if stop <= start || stop.is_nan() {
        return Err(SspError::Unsupported(format!(
            "stop time {stop} is not after the start time {start}"
        )));
    }
    Ok((start, stop))
}

impl<'a> Exporter<'a> {
    /// A system SSP 1.0 can express (no replays), and the notes on what it needs.
    fn new(system: &'a Plan) -> Result<Exporter<'a>, SspError> {
        if let Some(r) = system.replays.first() {
            return Err(SspError::Unsupported(format!(
                "{}: replayed measurement channels (replay '{}', {}) cannot be expressed in SSP 1.0 \
                 (it has no data-source element); export a system without [[replay]] (e.g. RLS/v), \
                 or replace the replay by an FMU that plays the measurement",
                system.path.display(),
                r.name,
                r.path.display()
            )));
        }
        let mut notes = Vec::new();
        let preload = &system.file.preload;
        if !preload.is_empty() {
            notes.push(format!(
                "the system preloads {} (needed by its FMUs); an SSP importer must do the same",
                preload
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        let n = system.instances.len();
        Ok(Exporter {
            system,
            connectors: (0..n).map(|_| BTreeMap::new()).collect(),
            enumerations: Enumerations::default(),
            connections: Vec::new(),
            params: vec![Vec::new(); n],
            files: Vec::new(),
            notes,
        })
    }

    /// The instance and FMU variable name of a system-file name `instance.variable`.
    fn fmu_var(&self, full: &str) -> Result<(usize, String), SspError> {
        let (k, sv) = instance_variable(self.system, full, "ssp export")?;
        Ok((k, sv.name.clone()))
    }

    /// A connector of instance `k` for its variable `sv`.
    fn connector(
        &mut self,
        k: usize,
        sv: &tb_fmi::import::description::ScalarVariable,
        kind: &'static str,
    ) {
        let inst = &self.system.instances[k];
        let md = inst.description();
        let conn = Conn {
            kind,
            ty: sv.ty,
            unit: md.unit_of(sv).map(str::to_string),
            enumeration: self.enumerations.name_of(&inst.name, md, sv),
        };
        self.connectors[k].insert(sv.name.clone(), conn);
    }

    /// Every output of every instance is a connector.
    fn outputs(&mut self) {
        let system = self.system;
        for (k, inst) in system.instances.iter().enumerate() {
            for v in inst.description().variables_of(Causality::Output) {
                self.connector(k, v, "output");
            }
        }
    }

    /// The system's connections, by the FMUs' names, with their connected inputs.
    fn connections(&mut self) -> Result<(), SspError> {
        let system = self.system;
        for c in &system.connections {
            let Endpoint::Fmu { unit: from_k, .. } = c.from else {
                unreachable!("replays are refused by Exporter::new")
            };
            let (_, from_var) = self.fmu_var(&c.from_name)?;
            let (to_k, to_var) = self.fmu_var(&c.to_name)?;
            let sv = system.instances[to_k]
                .description()
                .variable(&to_var)
                .expect("resolved");
            self.connector(to_k, sv, "input");
            self.connections
                .push((from_k, from_var, to_k, to_var, c.scale, c.offset));
        }
        Ok(())
    }

    /// Parameters per instance (FMU names), typed values; a set parameter is a connector,
    /// a set input is not (an importer would overwrite it with the unconnected connector's
    /// value).
    fn parameters(&mut self) -> Result<(), SspError> {
        let system = self.system;
        for (name, value) in &system.file.parameters {
            let (k, var) = self.fmu_var(name)?;
            let md = system.instances[k].description();
            let sv = md.variable(&var).expect("resolved");
            let value = self.packed_file(name, sv, value);
            let elem = parameter_value(md, sv, &value);
            self.params[k].push((var.clone(), elem));
            if sv.causality == Causality::Parameter {
                self.connector(k, sv, "parameter");
            } else {
                self.notes.push(format!(
                    "'{name}' is an input set as a start value: it has no connector, so that an importer does not overwrite it with an unconnected connector's value"
                ));
            }
        }
        Ok(())
    }

    /// A path parameter's file goes into the package (`resources/files/`) and the parameter
    /// names it there: an importer finds it inside the package, the only place a package's
    /// path parameters may point to. Other values as they are.
    fn packed_file(
        &mut self,
        name: &str,
        sv: &tb_fmi::import::description::ScalarVariable,
        value: &toml::Value,
    ) -> toml::Value {
        let Some(text) = value
            .as_str()
            .filter(|t| !t.is_empty() && !t.starts_with("file:"))
        else {
            return value.clone();
        };
        if !(sv.ty == ScalarType::String && sv.name.ends_with("_file")) {
            return value.clone();
        }
        let source = tb_files::resolve(&tb_files::folder_of(&self.system.path), Path::new(text));
        let file_name = source
            .file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_else(|| "file".into());
        let entry = format!("resources/files/{}_{file_name}", name.replace('.', "_"));
        self.files.push((entry.clone(), source));
        toml::Value::String(entry)
    }

    /// `<ssd:Elements>`: a component per instance with its connectors and parameter
    /// values; returns the number of connectors.
    fn write_elements(&self, x: &mut String, source_of: &[String]) -> usize {
        x.push_str("    <ssd:Elements>\n");
        let mut n_connectors = 0;
        for (k, inst) in self.system.instances.iter().enumerate() {
            // A Model Exchange instance says so (SSP 1.0's `implementation`); else "any".
            let implementation = match inst.interface {
                tb_fmi::Interface::ModelExchange => " implementation=\"ModelExchange\"",
                tb_fmi::Interface::CoSimulation => "",
            };
            x.push_str(&format!(
                "      <ssd:Component name=\"{}\" type=\"application/x-fmu-sharedlibrary\" source=\"{}\"{implementation}>\n",
                esc(&inst.name),
                esc(&source_of[k])
            ));
            if !self.connectors[k].is_empty() {
                x.push_str("        <ssd:Connectors>\n");
                // Inputs, outputs, parameters, each by name.
                for kind in ["input", "output", "parameter"] {
                    for (name, c) in self.connectors[k].iter().filter(|(_, c)| c.kind == kind) {
                        n_connectors += 1;
                        x.push_str(&format!(
                            "          <ssd:Connector name=\"{}\" kind=\"{kind}\">{}</ssd:Connector>\n",
                            esc(name),
                            type_element(c.ty, c.unit.as_deref(), c.enumeration.as_deref())
                        ));
                    }
                }
                x.push_str("        </ssd:Connectors>\n");
            }
            if !self.params[k].is_empty() {
                x.push_str("        <ssd:ParameterBindings>\n          <ssd:ParameterBinding>\n            <ssd:ParameterValues>\n");
                x.push_str(&format!(
                    "              <ssv:ParameterSet version=\"1.0\" name=\"{}\">\n                <ssv:Parameters>\n",
                    esc(&inst.name)
                ));
                for (name, elem) in &self.params[k] {
                    x.push_str(&format!(
                        "                  <ssv:Parameter name=\"{}\">{elem}</ssv:Parameter>\n",
                        esc(name)
                    ));
                }
                x.push_str("                </ssv:Parameters>\n              </ssv:ParameterSet>\n            </ssd:ParameterValues>\n          </ssd:ParameterBinding>\n        </ssd:ParameterBindings>\n");
            }
            x.push_str("      </ssd:Component>\n");
        }
        x.push_str("    </ssd:Elements>\n");
        n_connectors
    }

    /// `<ssd:Connections>`; a unit conversion as a `LinearTransformation` with the unit
    /// conversion suppressed (the factor and offset are exactly twinbench's).
    fn write_connections(&self, x: &mut String) {
        if self.connections.is_empty() {
            return;
        }
        let names = &self.system.instances;
        x.push_str("    <ssd:Connections>\n");
        for (fk, fv, tk, tv, scale, offset) in &self.connections {
            let attrs = format!(
                "startElement=\"{}\" startConnector=\"{}\" endElement=\"{}\" endConnector=\"{}\"",
                esc(&names[*fk].name),
                esc(fv),
                esc(&names[*tk].name),
                esc(tv)
            );
            if *scale == 1.0 && *offset == 0.0 {
                x.push_str(&format!("      <ssd:Connection {attrs}/>\n"));
            } else {
                x.push_str(&format!(
                    "      <ssd:Connection {attrs} suppressUnitConversion=\"true\"><ssc:LinearTransformation factor=\"{}\" offset=\"{}\"/></ssd:Connection>\n",
                    real(*scale),
                    real(*offset)
                ));
            }
        }
        x.push_str("    </ssd:Connections>\n");
    }

    /// `<ssd:Enumerations>`: the Enumeration types the connectors use.
    fn write_enumerations(&self, x: &mut String) {
        if self.enumerations.0.is_empty() {
            return;
        }
        x.push_str("  <ssd:Enumerations>\n");
        for (name, items) in &self.enumerations.0 {
            x.push_str(&format!("    <ssc:Enumeration name=\"{}\">\n", esc(name)));
            for (item, value) in items {
                x.push_str(&format!(
                    "      <ssc:Item name=\"{}\" value=\"{value}\"/>\n",
                    esc(item)
                ));
            }
            x.push_str("    </ssc:Enumeration>\n");
        }
        x.push_str("  </ssd:Enumerations>\n");
    }

    /// `<ssd:Units>`: the connectors' units with their base units.
    fn write_units(&mut self, x: &mut String) {
        let units_used: BTreeSet<String> = self
            .connectors
            .iter()
            .flat_map(|cs| cs.values().filter_map(|c| c.unit.clone()))
            .collect();
        let mut unit_xml = String::new();
        for u in &units_used {
            let def = self
                .system
                .instances
                .iter()
                .find_map(|i| i.description().unit_def(u).copied())
                .or_else(|| tb_fmi::units::lookup(u).copied());
            match def {
                Some(d) => unit_xml.push_str(&format!(
                    "    <ssc:Unit name=\"{}\"><ssc:BaseUnit{}/></ssc:Unit>\n",
                    esc(u),
                    d.base_unit_attributes()
                )),
                None => self
                    .notes
                    .push(format!("unit '{u}' has no definition; left out of <Units>")),
            }
        }
        if !unit_xml.is_empty() {
            x.push_str("  <ssd:Units>\n");
            x.push_str(&unit_xml);
            x.push_str("  </ssd:Units>\n");
        }
    }

    /// A system-file name as the SSP names it (by the FMU's variable name).
    fn ssp_name(&self, full: &str) -> Result<String, SspError> {
        let (k, var) = self.fmu_var(full)?;
        Ok(format!("{}.{var}", self.system.instances[k].name))
    }

    fn signal_list(&self, names: &[String]) -> Result<String, SspError> {
        names
            .iter()
            .map(|n| Ok(format!("<tb:Signal name=\"{}\"/>", esc(&self.ssp_name(n)?))))
            .collect()
    }

    /// `<ssd:DefaultExperiment>` with the Open Simulation Platform's fixed-step algorithm
    /// (libcosim reads its `baseStepSize`) and twinbench's own experiment: what a
    /// twinbench import needs to reproduce the run (other tools ignore it).
    fn write_default_experiment(
        &self,
        x: &mut String,
        start: f64,
        stop: f64,
    ) -> Result<(), SspError> {
        let system = self.system;
        let (file, exp) = (&system.file, &system.file.experiment);
        let order: Vec<&str> = system.order.iter().map(|&k| system.unit_name(k)).collect();
        let lap = match &system.stop {
            crate::Stop::When {
                condition,
                max_time,
            } => format!(
                " stop=\"{}\" maxTime=\"{}\"",
                esc(&format!(
                    "{} {} {}",
                    self.ssp_name(&condition.signal)?,
                    condition.op.symbol(),
                    condition.threshold
                )),
                real(*max_time)
            ),
            crate::Stop::Time(t) => format!(" stop=\"{}\"", real(*t)),
        };
        // The recorded signals and decimation, the reported values, the checks.
        let mut tb_children = String::new();
        if !file.record.signals.is_empty() || file.record.decimation != 1 {
            tb_children.push_str(&format!(
                "<tb:Record decimation=\"{}\">{}</tb:Record>",
                file.record.decimation,
                self.signal_list(&file.record.signals)?
            ));
        }
        if !exp.report.is_empty() {
            tb_children.push_str(&format!(
                "<tb:Report>{}</tb:Report>",
                self.signal_list(&exp.report)?
            ));
        }
        // Tolerances of FMUs with an internal solver: the experiment's (an attribute) and
        // each instance's own.
        for i in file.instances.iter() {
            if let Some(t) = i.tolerance {
                tb_children.push_str(&format!(
                    "<tb:Tolerance instance=\"{}\" value=\"{}\"/>",
                    esc(&i.name),
                    real(t)
                ));
            }
        }
        for c in &file.checks {
            tb_children.push_str(&format!(
                "<tb:Check relativeTolerance=\"{}\"{}>{}</tb:Check>",
                real(c.relative_tolerance),
                c.why
                    .as_deref()
                    .map(|w| format!(" why=\"{}\"", esc(w)))
                    .unwrap_or_default(),
                self.signal_list(&c.equal)?
            ));
        }
        x.push_str(&format!(
            "  <ssd:DefaultExperiment startTime=\"{}\" stopTime=\"{}\">\n    <ssd:Annotations>\n",
            real(start),
            real(stop)
        ));
        x.push_str(&format!(
            "      <ssc:Annotation type=\"com.opensimulationplatform\"><osp:Algorithm><osp:FixedStepAlgorithm baseStepSize=\"{}\"/></osp:Algorithm></ssc:Annotation>\n",
            real(exp.step)
        ));
        x.push_str(&format!(
            "      <ssc:Annotation type=\"org.twinbench.experiment\"><tb:Experiment stepSize=\"{}\" algorithm=\"{}\" order=\"{}\"{}{lap}{}</ssc:Annotation>\n",
            real(exp.step),
            exp.algorithm.name(),
            esc(&order.join(" ")),
            exp.tolerance
                .map(|t| format!(" tolerance=\"{}\"", real(t)))
                .unwrap_or_default()
                + &match exp.step_convention {
                    crate::config::StepConvention::H => String::new(),
                    c => format!(" stepConvention=\"{}\"", c.name()),
                },
            if tb_children.is_empty() {
                "/>".to_string()
            } else {
                format!(">{tb_children}</tb:Experiment>")
            }
        ));
        x.push_str("    </ssd:Annotations>\n  </ssd:DefaultExperiment>\n");
        Ok(())
    }
}

/// A parameter's value as its `<ssv:...>` element (SSV gives an Enumeration by its item's
/// name).
fn parameter_value(
    md: &tb_fmi::ModelDescription,
    sv: &tb_fmi::import::description::ScalarVariable,
    value: &toml::Value,
) -> String {
    let num = value
        .as_float()
        .or_else(|| value.as_integer().map(|i| i as f64));
    match sv.ty {
        ScalarType::Real => {
            let u = md
                .unit_of(sv)
                .map(|u| format!(" unit=\"{}\"", esc(u)))
                .unwrap_or_default();
            format!("<ssv:Real value=\"{}\"{u}/>", real(num.unwrap_or(0.0)))
        }
        ScalarType::Integer => {
            format!(
                "<ssv:Integer value=\"{}\"/>",
                value.as_integer().unwrap_or(0)
            )
        }
        ScalarType::Enumeration => {
            let i = value.as_integer().unwrap_or(0);
            match md
                .enumeration_items(sv)
                .and_then(|items| items.iter().find(|(_, v)| *v == i))
            {
                Some((item, _)) => format!("<ssv:Enumeration value=\"{}\"/>", esc(item)),
                None => format!("<ssv:Integer value=\"{i}\"/>"),
            }
        }
        ScalarType::Boolean => {
            format!(
                "<ssv:Boolean value=\"{}\"/>",
                value.as_bool().unwrap_or(false)
            )
        }
        ScalarType::String => format!(
            "<ssv:String value=\"{}\"/>",
            esc(value.as_str().unwrap_or(""))
        ),
    }
}

/// The system's parameter values as one SSV document (SSP 1.0's file of parameter values):
/// each named `component.connector` as a system-level binding names them, typed as in the
/// package. A path value is written as the system file gives it.
pub fn parameter_set(system: &Plan, name: &str) -> Result<String, SspError> {
    let mut x = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<ssv:ParameterSet xmlns:ssv=\"{NS_SSV}\" xmlns:ssc=\"{NS_SSC}\" version=\"1.0\" name=\"{}\">\n  <ssv:Parameters>\n",
        esc(name)
    );
    let mut units = BTreeSet::new();
    for (full, value) in &system.file.parameters {
        let (k, sv) = instance_variable(system, full, "ssv export")?;
        let inst = &system.instances[k];
        let (u, md) = (inst.name.as_str(), inst.description());
        if let Some(unit) = md.unit_of(sv) {
            units.insert(unit.to_string());
        }
        x.push_str(&format!(
            "    <ssv:Parameter name=\"{}.{}\">{}</ssv:Parameter>\n",
            esc(u),
            esc(&sv.name),
            parameter_value(md, sv, value)
        ));
    }
    x.push_str("  </ssv:Parameters>\n");
    if !units.is_empty() {
        x.push_str("  <ssv:Units>\n");
        for u in units {
            let Some(def) = system
                .instances
                .iter()
                .find_map(|i| i.description().unit_def(&u).copied())
                .or_else(|| tb_fmi::units::lookup(&u).copied())
            else {
                continue;
            };
            let base = def.base_unit_attributes();
            x.push_str(&format!(
                "    <ssc:Unit name=\"{}\"><ssc:BaseUnit{base}/></ssc:Unit>\n",
                esc(&u)
            ));
        }
        x.push_str("  </ssv:Units>\n");
    }
    x.push_str("</ssv:ParameterSet>\n");
    Ok(x)
}

/// Write the SSP archive (atomically).
pub fn export(
    system: &Plan,
    out: &Path,
    options: &ExportOptions,
) -> Result<ExportSummary, SspError> {
    let (ssd, fmus, summary) = system_structure(system, options)?;
    let io = |path: &Path, e: &dyn std::fmt::Display| SspError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let deflated = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .unix_permissions(0o644);
    let stored = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .unix_permissions(0o644);
    zip.start_file("SystemStructure.ssd", deflated)
        .map_err(|e| io(out, &e))?;
    zip.write_all(ssd.as_bytes()).map_err(|e| io(out, &e))?;
    for (name, path) in &fmus {
        let bytes = std::fs::read(path).map_err(|e| io(path, &e))?;
        // FMUs are zip archives already.
        zip.start_file(name.as_str(), stored)
            .map_err(|e| io(out, &e))?;
        zip.write_all(&bytes).map_err(|e| io(out, &e))?;
    }
    let bytes = zip.finish().map_err(|e| io(out, &e))?.into_inner();
    tb_table::write_atomic(out, &bytes).map_err(|e| io(out, &e))?;
    Ok(summary)
}
