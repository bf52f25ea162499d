//! The fitted twin handed on: from a study's `result.json`, the files a bench or a
//! colleague loads without twinbench's study (`twinbench export-twin`).
//!
//! What is written into the output folder:
//! - `fmu/<instance>.fmu` (FMI 2.0) and `fmu/<instance>-fmi3.fmu` (FMI 3.0): per instance of
//!   one of twinbench's models, a copy of the FMU the study ran whose start values are the
//!   system's parameters and the study's answer ([`fmu_export::fitted`]: the library applies
//!   them at instantiation; the description says the same values), with its own GUID, a
//!   description naming the study, and a `twinbench` annotation with the provenance and each
//!   fitted value's interval. A file a parameter names (the track, the target speed) replaces
//!   the model's bundled one, so no host has to set a path. A supplier's FMU is copied as it
//!   is (its start values are its own: the fitted values for it are in the system file, the
//!   SSP and the table);
//! - `fitted_system.toml`: the study's system over those FMUs, with every value set;
//! - `fitted_twin.ssp` and `fitted_twin.ssv`: the same bench as an SSP package with its
//!   parameter set inline, and the parameter set alone (SSV);
//! - `parameters.csv` and `parameters.json`: a plain table for the real-time RLS: every value
//!   with its unit, and the fitted ones with their start, interval and standard error;
//! - `provenance.json`: the study, the result, the inputs' SHA-256, the date and the version.
//!
//! Every file is written atomically, and the folder is refused if it holds anything but a
//! previous export (nothing the user wrote is overwritten).

use crate::pack::FmiVersion;
use crate::registry::ModelSpec;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::Plan;
use tb_cosim::{ParamSlot, ParamValue};
use tb_fmi::FmuCache;
use tb_optimize::StudyResult;

/// What can go wrong, with the file or the name it concerns.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Result(Box<crate::validate::ValidateError>),
    #[error(transparent)]
    System(Box<tb_cosim::SystemError>),
    #[error(transparent)]
    Ssp(#[from] tb_cosim::ssp::SspError),
    #[error("{path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("{fmu}: {message}")]
    Fmu { fmu: PathBuf, message: String },
    #[error("{name}: {message}")]
    Parameter { name: String, message: String },
}

// Boxed: the wrapped errors are large, and every function here returns this one.
impl From<crate::validate::ValidateError> for ExportError {
    fn from(e: crate::validate::ValidateError) -> Self {
        ExportError::Result(Box::new(e))
    }
}

impl From<tb_cosim::SystemError> for ExportError {
    fn from(e: tb_cosim::SystemError) -> Self {
        ExportError::System(Box::new(e))
    }
}

fn io(path: &Path, e: impl std::fmt::Display) -> ExportError {
    ExportError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// The FMI versions to write the fitted FMUs in.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    pub versions: Vec<FmiVersion>,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions {
            versions: vec![FmiVersion::V2, FmiVersion::V3],
        }
    }
}

/// What was written.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Exported {
    pub folder: PathBuf,
    /// Every file written, relative to the folder.
    pub files: Vec<PathBuf>,
    /// Instances whose FMUs carry the fitted start values.
    pub fitted_instances: Vec<String>,
    /// Instances of a supplier's FMU, copied as they are.
    pub copied_instances: Vec<String>,
    pub parameters: usize,
    pub notes: Vec<String>,
}

/// One value of the fitted bench: the system's or the answer's.
#[derive(Clone, Debug)]
struct Value {
    /// `instance.variable` as the system names it.
    name: String,
    slot: ParamSlot,
    value: ParamValue,
    /// The answer's row for a fitted parameter.
    fitted: Option<tb_optimize::driver::ParameterChange>,
}

/// Writes the fitted twin of `result` into `out` (see the module's documentation).
pub fn export_twin(
    result_path: &Path,
    out: &Path,
    options: &ExportOptions,
) -> Result<Exported, ExportError> {
    let result = crate::validate::read_result(result_path)?;
    let cache = Arc::new(FmuCache::temporary(false).map_err(|e| io(out, e))?);
    let plan = Plan::load(&result.system, cache)?;
    let values = bench_values(&plan, &result)?;
    let provenance = Provenance::of(result_path, &result, &plan)?;
    prepare_folder(out)?;
    let mut ex = Exported {
        folder: out.to_path_buf(),
        files: Vec::new(),
        fitted_instances: Vec::new(),
        copied_instances: Vec::new(),
        parameters: values.len(),
        notes: Vec::new(),
    };
    let specs = crate::pack::models();
    let mut fmu_of: BTreeMap<String, PathBuf> = BTreeMap::new();
    for inst in &plan.instances {
        let mine: Vec<&Value> = values
            .iter()
            .filter(|v| plan.instances[v.slot.unit].name == inst.name)
            .collect();
        let written = match spec_of(&specs, inst)? {
            Some(spec) => {
                ex.fitted_instances.push(inst.name.clone());
                fitted_fmus(spec, inst, &mine, &provenance, out, options)?
            }
            None => {
                ex.copied_instances.push(inst.name.clone());
                ex.notes.push(format!(
                    "{}: {} is not one of twinbench's models: copied as it is (its start values are its own; the fitted system, the SSP and the table carry the values for it)",
                    inst.name,
                    inst.fmu.source.display()
                ));
                vec![copy_fmu(inst, out)?]
            }
        };
        fmu_of.insert(inst.name.clone(), written[0].clone());
        ex.files.extend(written);
    }
    let system = fitted_system(&plan, &values, &fmu_of, out)?;
    ex.files.extend(system.files);
    let ssp_plan = Plan::load(
        &out.join(SYSTEM_FILE),
        Arc::new(FmuCache::temporary(false).map_err(|e| io(out, e))?),
    )?;
    let ssp = tb_cosim::ssp::export(&ssp_plan, &out.join("fitted_twin.ssp"), &Default::default())?;
    ex.notes.extend(ssp.notes);
    ex.files.push("fitted_twin.ssp".into());
    let ssv = tb_cosim::ssp::parameter_set(&ssp_plan, "fitted twin")?;
    write(out, "fitted_twin.ssv", ssv.as_bytes(), &mut ex.files)?;
    let (csv, json) = parameter_table(&values);
    write(out, "parameters.csv", csv.as_bytes(), &mut ex.files)?;
    write(out, "parameters.json", json.as_bytes(), &mut ex.files)?;
    let p = serde_json::to_vec_pretty(&provenance).expect("serialises");
    write(out, "provenance.json", &p, &mut ex.files)?;
    Ok(ex)
}

const SYSTEM_FILE: &str = "fitted_system.toml";
/// Written last: a folder with it holds a complete export, which a new one may replace.
const MARKER: &str = "provenance.json";

/// The output folder: created, or one holding a previous export (its `provenance.json`
/// says so); a folder holding anything else is refused.
fn prepare_folder(out: &Path) -> Result<(), ExportError> {
    if out.exists() {
        let mut entries = std::fs::read_dir(out).map_err(|e| io(out, e))?;
        if entries.next().is_some() && !out.join(MARKER).is_file() {
            return Err(io(
                out,
                "the folder exists and is not an earlier export-twin output (no provenance.json): name a new folder",
            ));
        }
    }
    for sub in ["", "fmu", "files"] {
        std::fs::create_dir_all(out.join(sub)).map_err(|e| io(&out.join(sub), e))?;
    }
    Ok(())
}

fn write(
    out: &Path,
    name: &str,
    bytes: &[u8],
    files: &mut Vec<PathBuf>,
) -> Result<(), ExportError> {
    let path = out.join(name);
    tb_table::write_atomic(&path, bytes).map_err(|e| io(&path, e))?;
    files.push(name.into());
    Ok(())
}

/// Every value the fitted bench sets: the system file's, then the answer's over them.
fn bench_values(plan: &Plan, result: &StudyResult) -> Result<Vec<Value>, ExportError> {
    let mut values: Vec<Value> = plan
        .parameters
        .iter()
        .map(|(slot, value)| Value {
            name: slot.name.clone(),
            slot: slot.clone(),
            value: value.clone(),
            fitted: None,
        })
        .collect();
    let rows = result
        .joint
        .as_ref()
        .map(|j| j.parameters.clone())
        .unwrap_or_default();
    for (name, x) in &result.parameters_final {
        let slot = plan.parameter(name)?;
        let value =
            slot.value_from_toml(&toml::Value::Float(*x), &format!("the answer's {name}"))?;
        let fitted = rows.iter().find(|r| r.name == *name).cloned();
        match values
            .iter_mut()
            .find(|v| v.slot.key() == slot.key() && v.slot.unit == slot.unit)
        {
            Some(v) => {
                v.value = value;
                v.fitted = fitted;
            }
            None => values.push(Value {
                name: name.clone(),
                slot,
                value,
                fitted,
            }),
        }
    }
    Ok(values)
}

/// The registered model an instance's FMU is, if it is one of twinbench's: its description
/// byte for byte what this twinbench writes for the model (else the fitted copy would not
/// be the FMU the study ran).
fn spec_of<'a>(
    specs: &'a [ModelSpec],
    inst: &tb_cosim::InstanceDef,
) -> Result<Option<&'a ModelSpec>, ExportError> {
    let md = inst.description();
    let Some(spec) = specs.iter().find(|s| s.info.name == md.model_name) else {
        return Ok(None);
    };
    if !md.generation_tool.starts_with("twinbench") {
        return Ok(None);
    }
    let text = zip_entry(&inst.fmu.source, "modelDescription.xml")?;
    let ours = if md.fmi_version.starts_with('3') {
        (spec.model_description3)()
    } else {
        (spec.model_description)()
    };
    if text != ours.as_bytes() {
        return Err(ExportError::Fmu {
            fmu: inst.fmu.source.clone(),
            message: format!(
                "model '{}' was packed by another twinbench build (its description differs from this build's): pack it again with `twinbench pack` and run the study again, so that the fitted FMU is the one the study ran",
                md.model_name
            ),
        });
    }
    Ok(Some(spec))
}

/// One entry of a zip archive.
fn zip_entry(archive: &Path, name: &str) -> Result<Vec<u8>, ExportError> {
    let bad = |e: &dyn std::fmt::Display| ExportError::Fmu {
        fmu: archive.to_path_buf(),
        message: format!("{name}: {e}"),
    };
    let f = std::fs::File::open(archive).map_err(|e| io(archive, e))?;
    let mut z = zip::ZipArchive::new(f).map_err(|e| bad(&e))?;
    let mut entry = z.by_name(name).map_err(|e| bad(&e))?;
    let mut bytes = Vec::new();
    entry.read_to_end(&mut bytes).map_err(|e| bad(&e))?;
    Ok(bytes)
}

/// The model's library for the fitted FMU: this build's, which reads the fitted start
/// values, and which must be byte for byte the one the study ran (else the fitted FMU would
/// not give the study's lap).
fn library_of(inst: &tb_cosim::InstanceDef, spec: &ModelSpec) -> Result<Vec<u8>, ExportError> {
    let id = spec.info.identifier;
    let ran = zip_entry(&inst.fmu.source, &format!("binaries/linux64/{id}.so"))
        .or_else(|_| zip_entry(&inst.fmu.source, &format!("binaries/x86_64-linux/{id}.so")))?;
    if ran != spec.library {
        return Err(ExportError::Fmu {
            fmu: inst.fmu.source.clone(),
            message: format!(
                "the library of model '{}' is not this twinbench build's (the study ran an FMU packed by another build): pack the FMUs again with `twinbench pack`, run the study again, then export it",
                spec.info.name
            ),
        });
    }
    Ok(spec.library.to_vec())
}

/// The fitted FMUs of one instance, one per version asked for.
fn fitted_fmus(
    spec: &ModelSpec,
    inst: &tb_cosim::InstanceDef,
    values: &[&Value],
    provenance: &Provenance,
    out: &Path,
    options: &ExportOptions,
) -> Result<Vec<PathBuf>, ExportError> {
    let library = library_of(inst, spec)?;
    let mut starts: Vec<(String, String)> = Vec::new();
    let mut start_file = String::new();
    let mut replaced: Vec<(&'static str, Vec<u8>)> = Vec::new();
    for v in values {
        let var = fmu_name(inst, &v.name);
        if v.slot.is_path {
            replaced.push(bundled_file(spec, inst, v, &var)?);
            continue;
        }
        starts.push((var.clone(), xml_text(&v.value)));
        start_file.push_str(&format!("{} = {}\n", toml_key(&var), toml_value(&v.value)));
    }
    let mut written = Vec::new();
    for &version in &options.versions {
        let canonical = match version {
            FmiVersion::V2 => (spec.guid)(),
            FmiVersion::V3 => format!("fmi3|{}", (spec.guid)()),
        };
        let token = fmu_export::description::guid_of(&format!(
            "{canonical}|fitted|{start_file}|{}",
            replaced
                .iter()
                .map(|(n, b)| format!("{n}:{}", sha256(b)))
                .collect::<Vec<_>>()
                .join(",")
        ));
        let fitting = fmu_export::description::Fitting {
            starts: starts.clone(),
            token: Some(token.clone()),
            description: Some(format!(
                "{} (the fitted twin of study '{}', instance '{}', by twinbench export-twin)",
                spec.info.description, provenance.study, inst.name
            )),
            annotation: Some(provenance.annotation(values)),
        };
        let file = format!(
            "# The fitted twin's start values (twinbench export-twin): applied by the model at\n# instantiation and at reset; the description's start attributes say the same.\ntoken = \"{token}\"\n\n[start]\n{start_file}"
        );
        let mut resources: Vec<(String, Vec<u8>)> = vec![(
            fmu_export::fitted::START_FILE.to_string(),
            file.into_bytes(),
        )];
        resources.extend(replaced.iter().map(|(n, b)| (n.to_string(), b.clone())));
        let bytes = crate::pack::fitted_archive(spec, &library, version, &fitting, &resources)
            .map_err(|e| io(out, e))?;
        let name = match version {
            FmiVersion::V2 => format!("fmu/{}.fmu", inst.name),
            FmiVersion::V3 => format!("fmu/{}-fmi3.fmu", inst.name),
        };
        let path = out.join(&name);
        tb_table::write_atomic(&path, &bytes).map_err(|e| io(&path, e))?;
        written.push(PathBuf::from(name));
    }
    if written.is_empty() {
        return Err(io(out, "no FMI version asked for (--fmi 2, 3 or 2,3)"));
    }
    Ok(written)
}

/// The FMU's own name of a system name `instance.variable` (through the port map).
fn fmu_name(inst: &tb_cosim::InstanceDef, name: &str) -> String {
    let var = name
        .strip_prefix(&format!("{}.", inst.name))
        .unwrap_or(name);
    inst.ports
        .get(var)
        .cloned()
        .unwrap_or_else(|| var.to_string())
}

/// A path parameter's file, as the bundled resource it stands for: an empty path means
/// that resource to the model, so the fitted FMU needs no path.
fn bundled_file(
    spec: &ModelSpec,
    inst: &tb_cosim::InstanceDef,
    v: &Value,
    var: &str,
) -> Result<(&'static str, Vec<u8>), ExportError> {
    let ParamValue::String(path) = &v.value else {
        unreachable!("a path parameter is a String");
    };
    let Some(resource) = spec
        .info
        .resources
        .iter()
        .find(|r| r.default_of == Some(var))
    else {
        return Err(ExportError::Parameter {
            name: v.name.clone(),
            message: format!(
                "names a file ({path}) that model '{}' has no bundled resource for: a fitted FMU cannot carry it",
                spec.info.name
            ),
        });
    };
    if path.is_empty() {
        return Ok((resource.name, resource.content.to_vec()));
    }
    let bytes = std::fs::read(path).map_err(|e| ExportError::Parameter {
        name: format!("{}.{var}", inst.name),
        message: format!("cannot read {path}: {e}"),
    })?;
    Ok((resource.name, bytes))
}

/// A supplier's FMU, copied as it is.
fn copy_fmu(inst: &tb_cosim::InstanceDef, out: &Path) -> Result<PathBuf, ExportError> {
    let bytes = std::fs::read(&inst.fmu.source).map_err(|e| io(&inst.fmu.source, e))?;
    let name = PathBuf::from(format!("fmu/{}.fmu", inst.name));
    let path = out.join(&name);
    tb_table::write_atomic(&path, &bytes).map_err(|e| io(&path, e))?;
    Ok(name)
}

/// A value as the model description writes it (a Real's shortest text that reads back to
/// the same f64).
fn xml_text(v: &ParamValue) -> String {
    match v {
        ParamValue::Real(x) => tb_fmi::schema::format_real(*x),
        ParamValue::Integer(i) => i.to_string(),
        ParamValue::Boolean(b) => b.to_string(),
        ParamValue::String(s) => s.clone(),
    }
}

fn toml_value(v: &ParamValue) -> toml::Value {
    match v {
        ParamValue::Real(x) => toml::Value::Float(*x),
        ParamValue::Integer(i) => toml::Value::Integer(*i as i64),
        ParamValue::Boolean(b) => toml::Value::Boolean(*b),
        ParamValue::String(s) => toml::Value::String(s.clone()),
    }
}

/// A TOML key: bare where it may be, quoted otherwise (`der(x)`, `a.b`).
fn toml_key(k: &str) -> String {
    let bare = !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare {
        k.to_string()
    } else {
        toml::Value::String(k.to_string()).to_string()
    }
}

fn sha256(bytes: &[u8]) -> String {
    use sha2::Digest;
    format!("{:x}", sha2::Sha256::digest(bytes))
}

fn sha256_of(path: &Path) -> Result<String, ExportError> {
    Ok(sha256(&std::fs::read(path).map_err(|e| io(path, e))?))
}

/// Where the fitted twin comes from.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Provenance {
    pub study: String,
    pub result: PathBuf,
    pub result_sha256: String,
    pub system: PathBuf,
    pub system_sha256: String,
    pub measurement: PathBuf,
    /// None where the measurement is no longer where the study read it.
    pub measurement_sha256: Option<String>,
    pub date: String,
    pub twinbench_version: String,
}

impl Provenance {
    fn of(
        result_path: &Path,
        result: &StudyResult,
        plan: &Plan,
    ) -> Result<Provenance, ExportError> {
        Ok(Provenance {
            study: result.study.clone(),
            result: tb_files::absolute(result_path),
            result_sha256: sha256_of(result_path)?,
            system: result.system.clone(),
            system_sha256: sha256_of(&plan.path)?,
            measurement: result.measurement.clone(),
            measurement_sha256: sha256_of(&result.measurement).ok(),
            date: jiff::Timestamp::now()
                .round(jiff::Unit::Second)
                .map_or_else(|_| jiff::Timestamp::now().to_string(), |t| t.to_string()),
            twinbench_version: env!("CARGO_PKG_VERSION").to_string(),
        })
    }

    /// The `twinbench` annotation of a fitted FMU: this provenance and each fitted value's
    /// interval (a well-formed fragment, indented for the description).
    fn annotation(&self, values: &[&Value]) -> String {
        let e = fmu_export::description::xml_escape;
        let mut s = format!(
            "      <FittedTwin study=\"{}\" result=\"{}\" resultSha256=\"{}\" measurement=\"{}\" measurementSha256=\"{}\" date=\"{}\" twinbenchVersion=\"{}\">\n",
            e(&self.study),
            e(&self.result.display().to_string()),
            self.result_sha256,
            e(&self.measurement.display().to_string()),
            self.measurement_sha256.as_deref().unwrap_or("unavailable"),
            e(&self.date),
            e(&self.twinbench_version)
        );
        for v in values {
            let Some(f) = &v.fitted else { continue };
            let ends = |i: Option<(Option<f64>, Option<f64>)>| {
                i.map(|(lo, hi)| format!("{} {}", end(lo), end(hi)))
                    .unwrap_or_else(|| "none".into())
            };
            s.push_str(&format!(
                "        <Value name=\"{}\" value=\"{}\" start=\"{}\" interval=\"{}\" intervalWithModel=\"{}\" stdError=\"{}\"/>\n",
                e(v.name.split_once('.').map_or(&v.name, |p| p.1)),
                xml_text(&v.value),
                tb_fmi::schema::format_real(f.before),
                ends(f.interval),
                ends(f.interval_with_model),
                f.std_error.map_or("none".into(), tb_fmi::schema::format_real)
            ));
        }
        s.push_str("      </FittedTwin>\n");
        s
    }
}

fn end(x: Option<f64>) -> String {
    x.map_or("open".into(), tb_fmi::schema::format_real)
}

/// The system file of the fitted bench: the study's, over the exported FMUs (one per
/// instance), with every value set, the files it names copied beside it.
struct FittedSystem {
    files: Vec<PathBuf>,
}

fn fitted_system(
    plan: &Plan,
    values: &[Value],
    fmu_of: &BTreeMap<String, PathBuf>,
    out: &Path,
) -> Result<FittedSystem, ExportError> {
    let text = std::fs::read_to_string(&plan.path).map_err(|e| io(&plan.path, e))?;
    let mut doc: toml_edit::DocumentMut = text.parse().map_err(|e| io(&plan.path, e))?;
    let mut files = Vec::new();
    let mut fmus = toml_edit::Table::new();
    for (inst, path) in fmu_of {
        fmus.insert(inst, toml_edit::value(path.display().to_string()));
    }
    doc["fmus"] = toml_edit::Item::Table(fmus);
    if let Some(instances) = doc
        .get_mut("instance")
        .and_then(|i| i.as_array_of_tables_mut())
    {
        for t in instances.iter_mut() {
            let name = t.get("name").and_then(|n| n.as_str()).map(str::to_string);
            if let Some(name) = name {
                t["fmu"] = toml_edit::value(name);
            }
        }
    }
    let mut params = toml_edit::Table::new();
    for v in values {
        let value = match &v.value {
            ParamValue::String(p) if v.slot.is_path && !p.is_empty() => {
                let file = Path::new(p)
                    .file_name()
                    .map(|f| f.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "file".into());
                let rel = format!("files/{}_{file}", v.name.replace('.', "_"));
                let bytes = std::fs::read(p).map_err(|e| io(Path::new(p), e))?;
                write(out, &rel, &bytes, &mut files)?;
                toml_edit::value(rel)
            }
            ParamValue::Real(x) => toml_edit::value(*x),
            ParamValue::Integer(i) => toml_edit::value(*i as i64),
            ParamValue::Boolean(b) => toml_edit::value(*b),
            ParamValue::String(s) => toml_edit::value(s.clone()),
        };
        params.insert(&v.name, value);
    }
    doc["parameters"] = toml_edit::Item::Table(params);
    absolute_paths(&mut doc, plan)?;
    let header = format!(
        "# The fitted twin's bench (twinbench export-twin): the study's system over the fitted\n# FMUs in fmu/, every value set. `twinbench run {SYSTEM_FILE}` runs the fitted lap.\n"
    );
    write(
        out,
        SYSTEM_FILE,
        format!("{header}{doc}").as_bytes(),
        &mut files,
    )?;
    Ok(FittedSystem { files })
}

/// Paths the system names besides its FMUs and parameters (replayed channels, preloaded
/// libraries), made absolute: the fitted system lives in another folder.
fn absolute_paths(doc: &mut toml_edit::DocumentMut, plan: &Plan) -> Result<(), ExportError> {
    let base = tb_files::folder_of(&plan.path);
    let fix = |item: &mut toml_edit::Item| {
        if let Some(s) = item.as_str() {
            let p = tb_files::resolve(&base, Path::new(s));
            *item = toml_edit::value(p.display().to_string());
        }
    };
    if let Some(list) = doc.get_mut("preload").and_then(|p| p.as_array_mut()) {
        for v in list.iter_mut() {
            if let Some(s) = v.as_str() {
                *v = tb_files::resolve(&base, Path::new(s))
                    .display()
                    .to_string()
                    .into();
            }
        }
    }
    if let Some(replays) = doc
        .get_mut("replay")
        .and_then(|r| r.as_array_of_tables_mut())
    {
        for t in replays.iter_mut() {
            if let Some(item) = t.get_mut("file") {
                fix(item);
            }
        }
    }
    Ok(())
}

/// The plain table for the real-time RLS: CSV and JSON.
fn parameter_table(values: &[Value]) -> (String, String) {
    let mut csv = String::from(
        "name,value,unit,fitted,start,interval_lo,interval_hi,interval_with_model_lo,interval_with_model_hi,std_error\n",
    );
    let mut rows = Vec::new();
    for v in values {
        let unit = v.slot.variable_unit.clone().unwrap_or_default();
        let f = v.fitted.as_ref();
        let pair = |i: Option<(Option<f64>, Option<f64>)>| i.unwrap_or((None, None));
        let (lo, hi) = pair(f.and_then(|f| f.interval));
        let (mlo, mhi) = pair(f.and_then(|f| f.interval_with_model));
        let num = |x: Option<f64>| x.map(tb_fmi::schema::format_real).unwrap_or_default();
        let value = match &v.value {
            ParamValue::String(s) => csv_field(s),
            other => xml_text(other),
        };
        csv.push_str(&format!(
            "{},{value},{},{},{},{},{},{},{},{}\n",
            csv_field(&v.name),
            csv_field(&unit),
            f.is_some(),
            num(f.map(|f| f.before)),
            num(lo),
            num(hi),
            num(mlo),
            num(mhi),
            num(f.and_then(|f| f.std_error)),
        ));
        rows.push(serde_json::json!({
            "name": v.name,
            "value": toml_json(&v.value),
            "unit": v.slot.variable_unit,
            "fitted": f.is_some(),
            "start": f.map(|f| f.before),
            "interval": f.and_then(|f| f.interval),
            "interval_with_model": f.and_then(|f| f.interval_with_model),
            "std_error": f.and_then(|f| f.std_error),
        }));
    }
    let json = serde_json::to_string_pretty(&serde_json::json!({ "parameters": rows }))
        .expect("serialises");
    (csv, json)
}

fn toml_json(v: &ParamValue) -> serde_json::Value {
    match v {
        ParamValue::Real(x) => serde_json::json!(x),
        ParamValue::Integer(i) => serde_json::json!(i),
        ParamValue::Boolean(b) => serde_json::json!(b),
        ParamValue::String(s) => serde_json::json!(s),
    }
}

/// A CSV field, quoted where it holds a comma, a quote or a line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}
