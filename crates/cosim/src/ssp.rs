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

fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&apos;"),
            c => o.push(c),
        }
    }
    o
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
        sv: &tb_fmi::description::ScalarVariable,
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

struct Conn {
    kind: &'static str,
    ty: ScalarType,
    unit: Option<String>,
    enumeration: Option<String>,
}

/// Build the SystemStructure.ssd text and the list of (archive name, FMU file) to pack.
pub fn system_structure(
    system: &Plan,
    options: &ExportOptions,
) -> Result<SystemStructure, SspError> {
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
    let file = &system.file;
    let exp = &file.experiment;
    let mut notes = Vec::new();
    if !file.preload.is_empty() {
        notes.push(format!(
            "the system preloads {} (needed by its FMUs); an SSP importer must do the same",
            file.preload
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    // FMU variable name of a system-file name `instance.variable`.
    let fmu_var = |full: &str| -> Result<(usize, String), SspError> {
        let (u, v) = split_name(full)
            .ok_or_else(|| SspError::Unsupported(format!("'{full}' is not instance.variable")))?;
        let k = system
            .instances
            .iter()
            .position(|i| i.name == u)
            .ok_or_else(|| SspError::Unsupported(format!("'{full}': not an FMU instance")))?;
        let sv = system.instances[k]
            .variable(v, "ssp export")
            .map_err(|e| SspError::Unsupported(e.to_string()))?;
        Ok((k, sv.name.clone()))
    };
    // Connectors per instance.
    let mut connectors: Vec<BTreeMap<String, Conn>> = (0..system.instances.len())
        .map(|_| BTreeMap::new())
        .collect();
    let mut units_used: BTreeSet<String> = BTreeSet::new();
    let mut enumerations = Enumerations::default();
    for (k, inst) in system.instances.iter().enumerate() {
        let md = inst.description();
        for v in md
            .variables
            .iter()
            .filter(|v| v.causality == Causality::Output)
        {
            let unit = md.unit_of(v).map(str::to_string);
            connectors[k].insert(
                v.name.clone(),
                Conn {
                    kind: "output",
                    ty: v.ty,
                    unit,
                    enumeration: enumerations.name_of(&inst.name, md, v),
                },
            );
        }
    }
    let mut connections = Vec::new();
    for c in &system.connections {
        let Endpoint::Fmu { unit: from_k, .. } = c.from else {
            unreachable!("replays are refused above")
        };
        let (_, from_var) = fmu_var(&c.from_name)?;
        let (to_k, to_var) = fmu_var(&c.to_name)?;
        let md = system.instances[to_k].description();
        let sv = md.variable(&to_var).expect("resolved");
        connectors[to_k].insert(
            to_var.clone(),
            Conn {
                kind: "input",
                ty: sv.ty,
                unit: md.unit_of(sv).map(str::to_string),
                enumeration: enumerations.name_of(&system.instances[to_k].name, md, sv),
            },
        );
        connections.push((from_k, from_var, to_k, to_var, c.scale, c.offset));
    }
    // Parameters per instance (FMU names), typed values.
    let mut params: Vec<Vec<(String, String)>> = vec![Vec::new(); system.instances.len()];
    for (name, value) in &file.parameters {
        let (k, var) = fmu_var(name)?;
        let md = system.instances[k].description();
        let sv = md.variable(&var).expect("resolved");
        let unit = md.unit_of(sv).map(str::to_string);
        let num = value
            .as_float()
            .or_else(|| value.as_integer().map(|i| i as f64));
        let elem = match sv.ty {
            ScalarType::Real => {
                let u = unit
                    .as_deref()
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
            // SSV gives an Enumeration by its item's name (checked against the items).
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
        };
        params[k].push((var.clone(), elem));
        if sv.causality == Causality::Parameter {
            connectors[k].insert(
                var.clone(),
                Conn {
                    kind: "parameter",
                    ty: sv.ty,
                    unit,
                    enumeration: enumerations.name_of(&system.instances[k].name, md, sv),
                },
            );
        } else {
            notes.push(format!(
                "'{name}' is an input set as a start value: it has no connector, so that an importer does not overwrite it with an unconnected connector's value"
            ));
        }
    }
    for cs in &connectors {
        for c in cs.values() {
            if let Some(u) = &c.unit {
                units_used.insert(u.clone());
            }
        }
    }
    // FMU files: one per [fmus] key that an instance uses.
    let mut fmu_files: Vec<(String, std::path::PathBuf)> = Vec::new();
    let mut source_of: Vec<String> = Vec::new();
    for inst_cfg in &file.instances {
        let name = format!("resources/{}.fmu", inst_cfg.fmu);
        if !fmu_files.iter().any(|(n, _)| *n == name) {
            fmu_files.push((name.clone(), file.fmus[&inst_cfg.fmu].clone()));
        }
        source_of.push(name);
    }
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
    // The document.
    let mut x = String::new();
    let sys_name = file.name.clone().unwrap_or_else(|| {
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
    x.push_str("    <ssd:Elements>\n");
    let mut n_connectors = 0;
    for (k, inst) in system.instances.iter().enumerate() {
        x.push_str(&format!(
            "      <ssd:Component name=\"{}\" type=\"application/x-fmu-sharedlibrary\" source=\"{}\">\n",
            esc(&inst.name),
            esc(&source_of[k])
        ));
        if !connectors[k].is_empty() {
            x.push_str("        <ssd:Connectors>\n");
            // Inputs, outputs, parameters, each by name.
            for kind in ["input", "output", "parameter"] {
                for (name, c) in connectors[k].iter().filter(|(_, c)| c.kind == kind) {
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
        if !params[k].is_empty() {
            x.push_str("        <ssd:ParameterBindings>\n          <ssd:ParameterBinding>\n            <ssd:ParameterValues>\n");
            x.push_str(&format!(
                "              <ssv:ParameterSet version=\"1.0\" name=\"{}\">\n                <ssv:Parameters>\n",
                esc(&inst.name)
            ));
            for (name, elem) in &params[k] {
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
    if !connections.is_empty() {
        x.push_str("    <ssd:Connections>\n");
        for (fk, fv, tk, tv, scale, offset) in &connections {
            let attrs = format!(
                "startElement=\"{}\" startConnector=\"{}\" endElement=\"{}\" endConnector=\"{}\"",
                esc(&system.instances[*fk].name),
                esc(fv),
                esc(&system.instances[*tk].name),
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
    // OMSimulator decides the system's kind from its own annotation and cannot open a
    // system without one: a weakly coupled system with its fixed-step master.
    x.push_str(&format!(
        "    <ssd:Annotations>\n      <ssc:Annotation type=\"org.openmodelica\"><oms:Annotations><oms:SimulationInformation><oms:FixedStepMaster description=\"oms-ma\" stepSize=\"{}\" relativeTolerance=\"0.0001\"/></oms:SimulationInformation></oms:Annotations></ssc:Annotation>\n    </ssd:Annotations>\n",
        real(system.file.experiment.step)
    ));
    x.push_str("  </ssd:System>\n");
    if !enumerations.0.is_empty() {
        x.push_str("  <ssd:Enumerations>\n");
        for (name, items) in &enumerations.0 {
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
    // Units with their base units.
    let mut unit_xml = String::new();
    for u in &units_used {
        let def = system
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
            None => notes.push(format!("unit '{u}' has no definition; left out of <Units>")),
        }
    }
    if !unit_xml.is_empty() {
        x.push_str("  <ssd:Units>\n");
        x.push_str(&unit_xml);
        x.push_str("  </ssd:Units>\n");
    }
    let order: Vec<&str> = system.order.iter().map(|&k| system.unit_name(k)).collect();
    let algorithm = exp.algorithm.name();
    // Signals by the FMU's names (port maps resolved), as the connectors are named.
    let ssp_name = |full: &str| -> Result<String, SspError> {
        let (k, var) = fmu_var(full)?;
        Ok(format!("{}.{var}", system.instances[k].name))
    };
    let lap = match &system.stop {
        crate::Stop::When {
            condition,
            max_time,
        } => format!(
            " stop=\"{}\" maxTime=\"{}\"",
            esc(&format!(
                "{} {} {}",
                ssp_name(&condition.signal)?,
                condition.op.symbol(),
                condition.threshold
            )),
            real(*max_time)
        ),
        crate::Stop::Time(t) => format!(" stop=\"{}\"", real(*t)),
    };
    // What a twinbench import needs to reproduce the run (other tools ignore it): the
    // recorded signals and decimation, the reported values, the checks.
    let signal_list = |names: &[String]| -> Result<String, SspError> {
        names
            .iter()
            .map(|n| Ok(format!("<tb:Signal name=\"{}\"/>", esc(&ssp_name(n)?))))
            .collect()
    };
    let mut tb_children = String::new();
    if !file.record.signals.is_empty() || file.record.decimation != 1 {
        tb_children.push_str(&format!(
            "<tb:Record decimation=\"{}\">{}</tb:Record>",
            file.record.decimation,
            signal_list(&file.record.signals)?
        ));
    }
    if !exp.report.is_empty() {
        tb_children.push_str(&format!(
            "<tb:Report>{}</tb:Report>",
            signal_list(&exp.report)?
        ));
    }
    for c in &file.checks {
        tb_children.push_str(&format!(
            "<tb:Check relativeTolerance=\"{}\"{}>{}</tb:Check>",
            real(c.relative_tolerance),
            c.why
                .as_deref()
                .map(|w| format!(" why=\"{}\"", esc(w)))
                .unwrap_or_default(),
            signal_list(&c.equal)?
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
        "      <ssc:Annotation type=\"org.twinbench.experiment\"><tb:Experiment stepSize=\"{}\" algorithm=\"{algorithm}\" order=\"{}\"{lap}{}</ssc:Annotation>\n",
        real(exp.step),
        esc(&order.join(" ")),
        if tb_children.is_empty() {
            "/>".to_string()
        } else {
            format!(">{tb_children}</tb:Experiment>")
        }
    ));
    x.push_str("    </ssd:Annotations>\n  </ssd:DefaultExperiment>\n");
    x.push_str("</ssd:SystemStructureDescription>\n");
    let summary = ExportSummary {
        components: system.instances.len(),
        connectors: n_connectors,
        connections: connections.len(),
        parameters: params.iter().map(Vec::len).sum(),
        fmus: fmu_files.iter().map(|f| f.0.clone()).collect(),
        start_time: start,
        stop_time: stop,
        step: exp.step,
        notes,
    };
    Ok((x, fmu_files, summary))
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
