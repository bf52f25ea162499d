//! SSP 1.0 import: an `.ssp` package becomes a [`SystemFile`], so that the rest of the
//! pipeline ([`crate::Plan::compile`], the masters, the recordings) is the same as for a
//! TOML system file. [`crate::Plan::load_with`] takes either.
//!
//! The package is checked and unpacked like an FMU ([`FmuCache::unpack_package`]: no path
//! outside the archive, no symbolic links, bounded sizes) into the run's cache folder (a
//! temporary cache is removed with the run). Then `SystemStructure.ssd` maps as follows:
//! - `ssd:Component` (`type` application/x-fmu-sharedlibrary, `source` an FMU inside the
//!   package): an instance named as the component;
//! - `ssd:Connection` between two components: a connection; the connector units (their
//!   `ssc:Real/@unit`, defined by the SSD's `ssd:Units`, the FMU's units or twinbench's
//!   table) are converted unless `suppressUnitConversion="true"`, then an
//!   `ssc:LinearTransformation` applies (`target = factor·source + offset`);
//! - `ssd:ParameterBindings` of a component or of the system, inline
//!   (`ssd:ParameterValues/ssv:ParameterSet`) or in an `.ssv` file of the package
//!   (`source`), with `prefix` prepended to the names: Real (converted from its `unit`),
//!   Integer, Boolean, String and Enumeration (by item name) values;
//! - `ssd:DefaultExperiment` start and stop times; twinbench's annotation
//!   (`org.twinbench.experiment`: step, algorithm, stepping order, stop condition, recorded
//!   signals, reported values, checks), else the Open Simulation Platform's `baseStepSize`.
//!
//! Everything else of the standard that changes a run (signal dictionaries, nested systems,
//! parameter mappings, mapping transformations, the system's own connectors in connections,
//! Binary values) is refused with a [`SspImportError`] naming the package, the file, the line
//! and what is supported; graphical elements and annotations of other tools are ignored.

use crate::config::CheckConfig;
use crate::config::{
    Algorithm, ConnectionConfig, ExperimentConfig, InstanceConfig, RecordConfig, StopConfig,
    SystemFile,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tb_fmi::units::UnitDef;
use tb_fmi::{FmuCache, FmuError, ModelDescription, ScalarType};

/// Why an SSP package cannot be run. Every message names the package; those about its XML
/// also name the file inside it and the line.
#[derive(Debug, thiserror::Error)]
pub enum SspImportError {
    /// The package as an archive (not a zip, an entry escaping it, a link, too large).
    #[error(transparent)]
    Archive(Box<FmuError>),
    /// A file the package must hold is not there, or cannot be read.
    #[error("{ssp}: {message}")]
    Package { ssp: PathBuf, message: String },
    #[error("{ssp}: {file}, line {line}: malformed XML: {message}")]
    Xml {
        ssp: PathBuf,
        file: String,
        line: usize,
        message: String,
    },
    #[error("{ssp}: {file}, line {line}: <{element}> is not supported by twinbench's SSP 1.0 import: {supported}")]
    Unsupported {
        ssp: PathBuf,
        file: String,
        line: usize,
        element: String,
        supported: String,
    },
    #[error("{ssp}: component '{component}': its FMU '{fmu}' is not in the package (FMUs in it: {available})")]
    MissingFmu {
        ssp: PathBuf,
        component: String,
        fmu: String,
        available: String,
    },
    #[error("{ssp}: {entry}: {error}")]
    Fmu {
        ssp: PathBuf,
        entry: String,
        error: Box<FmuError>,
    },
    #[error("{ssp}: {file}, line {line}: {message}")]
    Invalid {
        ssp: PathBuf,
        file: String,
        line: usize,
        message: String,
    },
}

/// Whether a system path names an SSP package (by its extension, as SSP tools do).
pub fn is_ssp(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ssp"))
}

pub const NS_SSD: &str = crate::ssp::NS_SSD;
pub const NS_SSC: &str = crate::ssp::NS_SSC;
pub const NS_SSV: &str = crate::ssp::NS_SSV;
const NS_OSP: &str = "http://opensimulationplatform.com/SSP/OSPAnnotations";
const NS_TB: &str = "https://github.com/twinbench/ssp";
const SSD: &str = "SystemStructure.ssd";
/// The deepest element nesting read (an SSD needs about ten levels; the tree is dropped
/// recursively).
const MAX_DEPTH: usize = 256;
/// The largest SSD or SSV read (as for a modelDescription.xml).
const MAX_XML_BYTES: u64 = tb_fmi::import::archive::MAX_DESCRIPTION_BYTES;

/// One XML element: namespace, local name, attributes (unprefixed), children, line.
#[derive(Debug)]
struct Node {
    ns: String,
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Node>,
    line: usize,
}

impl Node {
    fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
    fn is_ssp(&self) -> bool {
        self.ns == NS_SSD || self.ns == NS_SSC || self.ns == NS_SSV
    }
}

/// Line numbers of positions in a text, counted on from the last position asked for:
/// positions come in order while parsing, so the whole count stays linear in the text's
/// size (counting from the start each time made a file of many small elements quadratic).
struct Lines<'t> {
    text: &'t [u8],
    pos: usize,
    line: usize,
    /// Bytes looked at so far (the work done: the text's size when asked in order).
    scanned: usize,
}

impl<'t> Lines<'t> {
    fn new(text: &'t str) -> Self {
        Lines {
            text: text.as_bytes(),
            pos: 0,
            line: 1,
            scanned: 0,
        }
    }

    fn at(&mut self, pos: u64) -> usize {
        let pos = (pos as usize).min(self.text.len());
        if pos < self.pos {
            // Backwards (an error position before the last element): count afresh.
            self.pos = 0;
            self.line = 1;
        }
        self.line += self.text[self.pos..pos]
            .iter()
            .filter(|&&b| b == b'\n')
            .count();
        self.scanned += pos - self.pos;
        self.pos = pos;
        self.line
    }
}

/// A resolved namespace (empty: none), or the undeclared prefix.
fn ns_uri(ns: quick_xml::name::ResolveResult<'_>) -> Result<String, String> {
    use quick_xml::name::ResolveResult;
    match ns {
        ResolveResult::Bound(n) => Ok(String::from_utf8_lossy(n.as_ref()).into_owned()),
        ResolveResult::Unbound => Ok(String::new()),
        ResolveResult::Unknown(p) => Err(String::from_utf8_lossy(&p).into_owned()),
    }
}

/// Parse an XML document into a tree (namespaces resolved).
fn parse_xml(text: &str, ssp: &Path, file: &str) -> Result<Node, SspImportError> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::NsReader::from_str(text);
    let xml_err = |line: usize, message: String| SspImportError::Xml {
        ssp: ssp.to_path_buf(),
        file: file.to_string(),
        line,
        message,
    };
    let mut stack: Vec<Node> = Vec::new();
    let mut root: Option<Node> = None;
    let mut lines = Lines::new(text);
    loop {
        let start = reader.buffer_position();
        let (ns, ev) = match reader.read_resolved_event() {
            Ok((ns, ev)) => (ns_uri(ns), ev),
            Err(e) => {
                let message = e.to_string();
                return Err(xml_err(lines.at(reader.error_position()), message));
            }
        };
        let (e, empty) = match ev {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(_) => {
                let Some(node) = stack.pop() else {
                    return Err(xml_err(
                        lines.at(start),
                        "an end tag without its start".into(),
                    ));
                };
                match stack.last_mut() {
                    Some(parent) => parent.children.push(node),
                    None => root = Some(node),
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let line = lines.at(start);
        if root.is_some() && stack.is_empty() {
            return Err(xml_err(line, "content after the root element".into()));
        }
        let ns =
            ns.map_err(|p| xml_err(line, format!("namespace prefix '{p}' is not declared")))?;
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let mut attrs = Vec::new();
        for a in e.attributes() {
            let a = a.map_err(|err| xml_err(line, err.to_string()))?;
            let key = a.key;
            if key.as_namespace_binding().is_some() {
                continue;
            }
            let value = a
                .decode_and_unescape_value(reader.decoder())
                .map_err(|err| xml_err(line, err.to_string()))?
                .into_owned();
            attrs.push((
                String::from_utf8_lossy(key.local_name().as_ref()).into_owned(),
                value,
            ));
        }
        let node = Node {
            ns,
            name,
            attrs,
            children: Vec::new(),
            line,
        };
        if empty {
            match stack.last_mut() {
                Some(parent) => parent.children.push(node),
                None => root = Some(node),
            }
        } else {
            if stack.len() >= MAX_DEPTH {
                return Err(xml_err(
                    line,
                    format!("elements nested deeper than {MAX_DEPTH} levels"),
                ));
            }
            stack.push(node);
        }
    }
    if let Some(open) = stack.last() {
        return Err(xml_err(
            lines.at(text.len() as u64),
            format!(
                "unexpected end of the file: <{}> (line {}) is not closed",
                open.name, open.line
            ),
        ));
    }
    root.ok_or_else(|| xml_err(1, "no root element".into()))
}

/// What the import understands of the SSD, then turns into a [`SystemFile`].
struct Importer<'a> {
    ssp: &'a Path,
    dir: PathBuf,
    cache: &'a FmuCache,
    /// SSD `Units`.
    units: Vec<(String, UnitDef)>,
}

/// A component: its FMU (archive entry and loaded description) and declared connectors.
struct Component {
    name: String,
    fmu_key: String,
    entry: String,
    md: ModelDescription,
    /// `implementation="CoSimulation"` or `"ModelExchange"` (None: "any").
    interface: Option<tb_fmi::Interface>,
    /// Connector name -> (declared unit, line).
    connectors: BTreeMap<String, (Option<String>, usize)>,
}

/// The components' names, for a message naming a missing one.
fn component_names(components: &[Component]) -> String {
    components
        .iter()
        .map(|c| c.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

impl Importer<'_> {
    fn invalid(&self, file: &str, line: usize, message: impl Into<String>) -> SspImportError {
        SspImportError::Invalid {
            ssp: self.ssp.to_path_buf(),
            file: file.to_string(),
            line,
            message: message.into(),
        }
    }

    fn unsupported(&self, file: &str, node: &Node, supported: &str) -> SspImportError {
        SspImportError::Unsupported {
            ssp: self.ssp.to_path_buf(),
            file: file.to_string(),
            line: node.line,
            element: node.name.clone(),
            supported: supported.to_string(),
        }
    }

    /// The children of `node`, each one of `allowed` (in an SSP namespace) or `ignored`
    /// (graphical, without effect on a run); `Annotations` are always allowed. Anything else
    /// is refused, naming what `node` may contain.
    fn children<'n>(
        &self,
        file: &str,
        node: &'n Node,
        allowed: &[&str],
        ignored: &[&str],
    ) -> Result<Vec<&'n Node>, SspImportError> {
        let mut out = Vec::new();
        for c in &node.children {
            if c.is_ssp() && (c.name == "Annotations" || ignored.contains(&c.name.as_str())) {
                continue;
            }
            if c.is_ssp() && allowed.contains(&c.name.as_str()) {
                out.push(c);
                continue;
            }
            return Err(self.unsupported(
                file,
                c,
                &format!(
                    "<{}> may contain {}",
                    node.name,
                    if allowed.is_empty() {
                        "annotations only".to_string()
                    } else {
                        allowed
                            .iter()
                            .map(|a| format!("<{a}>"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    }
                ),
            ));
        }
        Ok(out)
    }

    /// An XML file of the package by its relative URI (no scheme, inside the package).
    fn read_entry(&self, from: &str, line: usize, uri: &str) -> Result<PathBuf, SspImportError> {
        let rel = uri.strip_prefix("./").unwrap_or(uri);
        if rel.is_empty()
            || rel.contains(':')
            || rel.starts_with('/')
            || rel.split(['/', '\\']).any(|c| c == "..")
        {
            return Err(self.invalid(
                from,
                line,
                format!(
                    "'{uri}' is not a relative path inside the package (URIs with a scheme, absolute paths and '..' are not supported)"
                ),
            ));
        }
        Ok(self.dir.join(rel))
    }

    fn read_xml(&self, file: &str, path: &Path) -> Result<Node, SspImportError> {
        let package = |message: String| SspImportError::Package {
            ssp: self.ssp.to_path_buf(),
            message,
        };
        let meta =
            std::fs::metadata(path).map_err(|_| package(format!("the package has no {file}")))?;
        if !meta.is_file() || meta.len() > MAX_XML_BYTES {
            return Err(package(format!(
                "{file} is not a regular file of at most {} MiB",
                MAX_XML_BYTES >> 20
            )));
        }
        let bytes = std::fs::read(path).map_err(|e| package(format!("cannot read {file}: {e}")))?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let valid = e.utf8_error().valid_up_to();
            SspImportError::Xml {
                ssp: self.ssp.to_path_buf(),
                file: file.to_string(),
                line: 1 + e.as_bytes()[..valid]
                    .iter()
                    .filter(|&&b| b == b'\n')
                    .count(),
                message: format!("not UTF-8 (byte {valid})"),
            }
        })?;
        parse_xml(&text, self.ssp, file)
    }

    /// A unit's definition: the SSD's `Units`, then the FMU's, then twinbench's table.
    fn unit_md(&self, md: &ModelDescription) -> ModelDescription {
        ModelDescription {
            units: self
                .units
                .iter()
                .cloned()
                .chain(md.units.iter().cloned())
                .collect(),
            ..Default::default()
        }
    }

    fn f64_attr(&self, file: &str, node: &Node, name: &str) -> Result<Option<f64>, SspImportError> {
        node.attr(name)
            .map(|v| {
                parse_double(v).ok_or_else(|| {
                    self.invalid(
                        file,
                        node.line,
                        format!("<{}> {name}=\"{v}\" is not a number", node.name),
                    )
                })
            })
            .transpose()
    }
}

/// xs:double text (INF, -INF, NaN as the schema writes them).
fn parse_double(s: &str) -> Option<f64> {
    match s.trim() {
        "INF" => Some(f64::INFINITY),
        "-INF" => Some(f64::NEG_INFINITY),
        "NaN" => Some(f64::NAN),
        t if t.eq_ignore_ascii_case("inf") || t.eq_ignore_ascii_case("nan") => None,
        t => t.parse().ok(),
    }
}

fn parse_bool(s: &str) -> Option<bool> {
    match s.trim() {
        "true" | "1" => Some(true),
        "false" | "0" => Some(false),
        _ => None,
    }
}

/// Unpack an SSP package into `cache` and read it as a system file. FMU paths point into the
/// unpacked folder, which lives as long as the cache.
pub fn load(ssp: &Path, cache: &FmuCache) -> Result<SystemFile, SspImportError> {
    let dir = cache
        .unpack_package(ssp)
        .map_err(|e| SspImportError::Archive(Box::new(e)))?;
    let imp = Importer {
        ssp,
        dir: dir.clone(),
        cache,
        units: Vec::new(),
    };
    let root = imp.read_xml(SSD, &dir.join(SSD))?;
    imp_system(imp, &root)
}

fn imp_system(mut imp: Importer<'_>, root: &Node) -> Result<SystemFile, SspImportError> {
    let f = SSD;
    check_root(&imp, root)?;
    let top = imp.children(
        f,
        root,
        &["System", "Enumerations", "Units", "DefaultExperiment"],
        &["MetaData"],
    )?;
    // Units first: connectors and parameters use them.
    imp.units = read_units(&imp, &top)?;
    let Some(system) = top.iter().find(|n| n.name == "System") else {
        return Err(imp.invalid(f, root.line, "no <ssd:System>"));
    };
    let parts = system_parts(&imp, system)?;
    let (components, fmus, mut bindings) = read_components(&imp, &parts)?;
    for p in parts.iter().filter(|n| n.name == "ParameterBindings") {
        bindings.push((None, p));
    }
    for p in parts.iter().filter(|n| n.name == "Connectors") {
        // The system's own connectors are harmless unless connected (refused below).
        imp.children(f, p, &["Connector"], &[])?;
    }
    // Parameter bindings (component or system level).
    let mut parameters = BTreeMap::new();
    for (k, pb) in bindings {
        for b in imp.children(f, pb, &["ParameterBinding"], &[])? {
            bind(&imp, &components, k, b, &mut parameters)?;
        }
    }
    let mut connections = Vec::new();
    for cs in parts.iter().filter(|n| n.name == "Connections") {
        for c in imp.children(f, cs, &["Connection"], &[])? {
            connections.push(connection(&imp, &components, c)?);
        }
    }
    let (experiment, record, checks, tolerances) = read_experiment(&imp, &top, root)?;
    let instances = components
        .iter()
        .map(|c| InstanceConfig {
            name: c.name.clone(),
            fmu: c.fmu_key.clone(),
            ports: BTreeMap::new(),
            logging: false,
            isolate: false,
            watchdog: None,
            interface: c.interface,
            tolerance: tolerances.get(&c.name).copied(),
        })
        .collect();
    if let Some(name) = tolerances
        .keys()
        .find(|n| !components.iter().any(|c| &c.name == *n))
    {
        return Err(imp.invalid(
            SSD,
            root.line,
            format!("twinbench's experiment annotation gives a tolerance for '{name}', which is not a component of the system"),
        ));
    }
    Ok(SystemFile {
        name: root
            .attr("name")
            .or_else(|| system.attr("name"))
            .map(str::to_string),
        fmus,
        instances,
        connections,
        parameters,
        experiment,
        record,
        replay: Vec::new(),
        preload: Vec::new(),
        checks,
        package: Some(imp.dir.clone()),
    })
}

/// The root is an SSP 1.0 `<ssd:SystemStructureDescription>`.
fn check_root(imp: &Importer<'_>, root: &Node) -> Result<(), SspImportError> {
    let f = SSD;
    if root.ns != NS_SSD || root.name != "SystemStructureDescription" {
        return Err(imp.invalid(
            f,
            root.line,
            format!(
                "the root element is <{}> ({}), not an SSP 1.0 <ssd:SystemStructureDescription>",
                root.name,
                if root.ns.is_empty() {
                    "no namespace"
                } else {
                    &root.ns
                }
            ),
        ));
    }
    if let Some(v) = root.attr("version") {
        if v != "1.0" {
            return Err(imp.invalid(
                f,
                root.line,
                format!("version=\"{v}\": twinbench imports SSP 1.0"),
            ));
        }
    }
    Ok(())
}

/// The SSD's `<ssd:Units>`: each name with its SI base units, factor and offset.
fn read_units(imp: &Importer<'_>, top: &[&Node]) -> Result<Vec<(String, UnitDef)>, SspImportError> {
    let f = SSD;
    let mut units = Vec::new();
    for u in top.iter().filter(|n| n.name == "Units") {
        for unit in imp.children(f, u, &["Unit"], &[])? {
            let name = unit.attr("name").unwrap_or_default().to_string();
            let base = imp.children(f, unit, &["BaseUnit"], &[])?;
            let mut def = UnitDef::DIMENSIONLESS;
            if let Some(b) = base.first() {
                let exp = |key: &str| -> Result<i32, SspImportError> {
                    b.attr(key).map_or(Ok(0), |v| {
                        v.trim().parse().map_err(|_| {
                            imp.invalid(
                                f,
                                b.line,
                                format!("<BaseUnit> {key}=\"{v}\" is not an integer"),
                            )
                        })
                    })
                };
                def.kg = exp("kg")?;
                def.m = exp("m")?;
                def.s = exp("s")?;
                def.a = exp("A")?;
                def.k = exp("K")?;
                def.mol = exp("mol")?;
                def.cd = exp("cd")?;
                def.rad = exp("rad")?;
                def.factor = imp.f64_attr(f, b, "factor")?.unwrap_or(1.0);
                def.offset = imp.f64_attr(f, b, "offset")?.unwrap_or(0.0);
                // A factor of 0 maps every value to the offset (N29: a start value silently
                // zeroed); an infinite one is no unit either.
                if !(def.factor.is_finite() && def.factor != 0.0 && def.offset.is_finite()) {
                    return Err(imp.invalid(
                        f,
                        b.line,
                        format!(
                            "unit '{name}': factor {:?} and offset {:?} do not define a unit (a finite, non-zero factor)",
                            def.factor, def.offset
                        ),
                    ));
                }
            }
            units.push((name, def));
        }
    }
    Ok(units)
}

/// The parts of `<ssd:System>` twinbench runs; signal dictionaries refused with the reason.
fn system_parts<'n>(imp: &Importer<'_>, system: &'n Node) -> Result<Vec<&'n Node>, SspImportError> {
    imp.children(
        SSD,
        system,
        &["Connectors", "ParameterBindings", "Elements", "Connections"],
        &["ElementGeometry", "SystemGeometry", "GraphicalElements"],
    )
    .map_err(|e| match e {
        SspImportError::Unsupported {
            ssp,
            file,
            line,
            element,
            supported,
        } if element == "SignalDictionaries" => SspImportError::Unsupported {
            ssp,
            file,
            line,
            element,
            supported: format!("signal dictionaries have no twinbench equivalent; connect the components directly ({supported})"),
        },
        other => other,
    })
}

/// A component's parameter bindings: which component (None: the system's) and the node.
type Bindings<'n> = Vec<(Option<usize>, &'n Node)>;

/// The components, the FMUs by `[fmus]` key, and the parameter bindings.
type Elements<'n> = (Vec<Component>, BTreeMap<String, PathBuf>, Bindings<'n>);

/// The components of `<ssd:Elements>` with their FMUs (one `[fmus]` key per FMU entry of
/// the package) and their parameter bindings.
fn read_components<'n>(
    imp: &Importer<'_>,
    parts: &[&'n Node],
) -> Result<Elements<'n>, SspImportError> {
    let mut components: Vec<Component> = Vec::new();
    let mut fmus: BTreeMap<String, PathBuf> = BTreeMap::new();
    let mut keys: BTreeMap<String, String> = BTreeMap::new(); // entry -> key
    let mut bindings = Vec::new();
    for el in parts.iter().filter(|n| n.name == "Elements") {
        for c in &el.children {
            let (entry, path) = component_fmu(imp, c)?;
            let key = match keys.get(&entry) {
                Some(k) => k.clone(),
                None => {
                    let key = fmu_key(&entry, &fmus);
                    fmus.insert(key.clone(), path.clone());
                    keys.insert(entry.clone(), key.clone());
                    key
                }
            };
            let loaded = imp.cache.load(&path).map_err(|error| SspImportError::Fmu {
                ssp: imp.ssp.to_path_buf(),
                entry: entry.clone(),
                error: Box::new(error),
            })?;
            let mut comp = Component {
                name: c.attr("name").unwrap_or_default().to_string(),
                fmu_key: key,
                entry,
                md: loaded.description.clone(),
                interface: match c.attr("implementation") {
                    Some("ModelExchange") => Some(tb_fmi::Interface::ModelExchange),
                    Some("CoSimulation") => Some(tb_fmi::Interface::CoSimulation),
                    _ => None,
                },
                connectors: BTreeMap::new(),
            };
            let k = components.len();
            for part in imp.children(
                SSD,
                c,
                &["Connectors", "ParameterBindings"],
                &["ElementGeometry"],
            )? {
                match part.name.as_str() {
                    "Connectors" => read_connectors(imp, part, &mut comp)?,
                    _ => bindings.push((Some(k), part)),
                }
            }
            components.push(comp);
        }
    }
    Ok((components, fmus, bindings))
}

/// A `[fmus]` key for an FMU entry of the package: its file stem, numbered when taken.
fn fmu_key(entry: &str, fmus: &BTreeMap<String, PathBuf>) -> String {
    let stem = Path::new(entry)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "fmu".into());
    let mut key = stem.clone();
    let mut n = 2;
    while fmus.contains_key(&key) {
        key = format!("{stem}_{n}");
        n += 1;
    }
    key
}

/// A component element that twinbench runs (a Co-Simulation FMU in the package): its
/// FMU's entry in the package and unpacked path.
fn component_fmu(imp: &Importer<'_>, c: &Node) -> Result<(String, PathBuf), SspImportError> {
    let f = SSD;
    if !c.is_ssp() || c.name != "Component" {
        let why = match c.name.as_str() {
            "System" => "nested systems (an <ssd:System> inside <ssd:Elements>) are not supported; flatten the system into one level of components",
            "SignalDictionaryReference" => "signal dictionaries are not supported; connect the components directly",
            _ => "<ssd:Elements> may contain <ssd:Component> (FMUs) only",
        };
        return Err(imp.unsupported(f, c, why));
    }
    let name = c.attr("name").unwrap_or_default().to_string();
    if let Some(t) = c.attr("type") {
        if t != "application/x-fmu-sharedlibrary" {
            return Err(imp.unsupported(
                f,
                c,
                &format!(
                    "component '{name}' has type=\"{t}\"; components are FMUs (application/x-fmu-sharedlibrary)"
                ),
            ));
        }
    }
    if let Some(i) = c.attr("implementation") {
        if !matches!(i, "CoSimulation" | "ModelExchange" | "any") {
            return Err(imp.unsupported(
                f,
                c,
                &format!(
                    "component '{name}' asks for implementation=\"{i}\"; twinbench runs FMUs through Co-Simulation or Model Exchange (CoSimulation, ModelExchange or any)"
                ),
            ));
        }
    }
    let source = c
        .attr("source")
        .ok_or_else(|| imp.invalid(f, c.line, format!("component '{name}' has no source")))?;
    let path = imp.read_entry(f, c.line, source)?;
    let entry = source.strip_prefix("./").unwrap_or(source).to_string();
    if !path.is_file() {
        return Err(SspImportError::MissingFmu {
            ssp: imp.ssp.to_path_buf(),
            component: name,
            fmu: entry,
            available: fmus_in(&imp.dir),
        });
    }
    Ok((entry, path))
}

/// A component's `<ssd:Connectors>`: each names a variable of its FMU, with a unit some
/// table defines.
fn read_connectors(
    imp: &Importer<'_>,
    part: &Node,
    comp: &mut Component,
) -> Result<(), SspImportError> {
    let f = SSD;
    let name = &comp.name;
    for con in imp.children(f, part, &["Connector"], &[])? {
        let cname = con.attr("name").unwrap_or_default().to_string();
        if comp.md.variable(&cname).is_none() {
            return Err(imp.invalid(
                f,
                con.line,
                format!(
                    "connector '{name}.{cname}': the FMU {} has no variable '{cname}' (closest: {})",
                    comp.entry,
                    comp.md.closest_names(&cname, 3).join(", ")
                ),
            ));
        }
        let mut unit = None;
        for ty in imp.children(
            f,
            con,
            &["Real", "Integer", "Boolean", "String", "Enumeration"],
            &["ConnectorGeometry", "Description"],
        )? {
            if ty.name == "Real" {
                unit = ty.attr("unit").map(str::to_string);
            }
        }
        if let Some(u) = &unit {
            let md = imp.unit_md(&comp.md);
            if crate::plan::units::definition(&md, u).is_none() {
                return Err(imp.invalid(
                    f,
                    con.line,
                    format!("connector '{name}.{cname}': unit '{u}' is defined neither in the SSD's <Units>, nor by the FMU, nor in twinbench's unit table"),
                ));
            }
        }
        comp.connectors.insert(cname, (unit, con.line));
    }
    Ok(())
}

/// What `<ssd:DefaultExperiment>` gives: the experiment, the recording, the checks and the
/// instances' own tolerances.
type Experiment = (
    ExperimentConfig,
    RecordConfig,
    Vec<CheckConfig>,
    BTreeMap<String, f64>,
);

/// `<ssd:DefaultExperiment>`: start and stop, the step (twinbench's annotation, else the
/// Open Simulation Platform's), and what twinbench's annotation adds (record, report,
/// checks, a stop condition).
fn read_experiment(
    imp: &Importer<'_>,
    top: &[&Node],
    root: &Node,
) -> Result<Experiment, SspImportError> {
    let f = SSD;
    let mut tolerances = BTreeMap::new();
    let mut experiment = ExperimentConfig {
        start: 0.0,
        step: f64::NAN,
        stop: StopConfig::Time(f64::NAN),
        lap_signal: None,
        lap_count: 1.0,
        max_time: 600.0,
        report: Vec::new(),
        algorithm: Algorithm::GaussSeidel,
        order: Vec::new(),
        tolerance: None,
        step_convention: Default::default(),
    };
    let mut record = RecordConfig::default();
    let mut checks = Vec::new();
    let mut stop_time = None;
    let mut tb_stop: Option<(String, usize)> = None;
    let mut osp_step = None;
    let mut exp_line = root.line;
    for de in top.iter().filter(|n| n.name == "DefaultExperiment") {
        exp_line = de.line;
        imp.children(f, de, &[], &[])?;
        if let Some(t) = imp.f64_attr(f, de, "startTime")? {
            experiment.start = t;
        }
        stop_time = imp.f64_attr(f, de, "stopTime")?;
        for anns in de.children.iter().filter(|n| n.name == "Annotations") {
            for x in anns.children.iter().flat_map(|ann| &ann.children) {
                if x.ns == NS_OSP {
                    if let Some(fixed) = x.children.iter().find(|n| n.name == "FixedStepAlgorithm")
                    {
                        osp_step = imp.f64_attr(f, fixed, "baseStepSize")?;
                    }
                }
                if x.ns == NS_TB && x.name == "Experiment" {
                    tb_experiment(
                        imp,
                        x,
                        &mut experiment,
                        &mut record,
                        &mut checks,
                        &mut tb_stop,
                        &mut tolerances,
                    )?;
                }
            }
        }
    }
    if experiment.step.is_nan() {
        experiment.step = osp_step.ok_or_else(|| {
            imp.invalid(
                f,
                exp_line,
                "no step size: twinbench needs its own annotation (org.twinbench.experiment, stepSize) or the Open Simulation Platform's <osp:FixedStepAlgorithm baseStepSize> in <ssd:DefaultExperiment>",
            )
        })?;
    }
    experiment.stop = match (stop_time, tb_stop) {
        // A condition (a lap) is twinbench's; a time is the standard's stopTime.
        (_, Some((s, _))) if parse_double(&s).is_none() => StopConfig::Word(s),
        (Some(t), _) => StopConfig::Time(t),
        (None, Some((s, line))) => StopConfig::Time(
            parse_double(&s)
                .ok_or_else(|| imp.invalid(f, line, format!("stop=\"{s}\" is not a time")))?,
        ),
        (None, None) => {
            return Err(imp.invalid(
                f,
                exp_line,
                "no stop time: <ssd:DefaultExperiment stopTime=...> (or twinbench's annotation) is needed",
            ))
        }
    };
    Ok((experiment, record, checks, tolerances))
}

/// The FMUs in an unpacked package, for a message.
fn fmus_in(dir: &Path) -> String {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x.eq_ignore_ascii_case("fmu")) {
                if let Ok(rel) = p.strip_prefix(dir) {
                    found.push(rel.display().to_string());
                }
            }
        }
    }
    found.sort();
    if found.is_empty() {
        "none".into()
    } else {
        found.join(", ")
    }
}

/// twinbench's experiment annotation.
fn tb_experiment(
    imp: &Importer<'_>,
    x: &Node,
    experiment: &mut ExperimentConfig,
    record: &mut RecordConfig,
    checks: &mut Vec<CheckConfig>,
    stop: &mut Option<(String, usize)>,
    tolerances: &mut BTreeMap<String, f64>,
) -> Result<(), SspImportError> {
    let f = SSD;
    if let Some(h) = imp.f64_attr(f, x, "stepSize")? {
        experiment.step = h;
    }
    experiment.tolerance = imp.f64_attr(f, x, "tolerance")?;
    if let Some(c) = x.attr("stepConvention") {
        experiment.step_convention =
            crate::config::StepConvention::from_name(c).map_err(|m| imp.invalid(f, x.line, m))?;
    }
    if let Some(a) = x.attr("algorithm") {
        experiment.algorithm = Algorithm::from_name(a).map_err(|m| imp.invalid(f, x.line, m))?;
    }
    if let Some(o) = x.attr("order") {
        experiment.order = o.split_whitespace().map(str::to_string).collect();
    }
    if let Some(s) = x.attr("stop") {
        *stop = Some((s.to_string(), x.line));
    }
    if let Some(m) = imp.f64_attr(f, x, "maxTime")? {
        experiment.max_time = m;
    }
    let names = |n: &Node| -> Vec<String> {
        n.children
            .iter()
            .filter(|s| s.ns == NS_TB && s.name == "Signal")
            .filter_map(|s| s.attr("name").map(str::to_string))
            .collect()
    };
    for c in x.children.iter().filter(|c| c.ns == NS_TB) {
        match c.name.as_str() {
            "Record" => {
                record.signals = names(c);
                if let Some(d) = c.attr("decimation") {
                    record.decimation = d.trim().parse().map_err(|_| {
                        imp.invalid(
                            f,
                            c.line,
                            format!("decimation=\"{d}\" is not a whole number"),
                        )
                    })?;
                }
            }
            "Report" => experiment.report.extend(names(c)),
            "Tolerance" => {
                let instance = c.attr("instance").unwrap_or_default().to_string();
                let value = imp
                    .f64_attr(f, c, "value")?
                    .ok_or_else(|| imp.invalid(f, c.line, "<tb:Tolerance> without a value"))?;
                tolerances.insert(instance, value);
            }
            "Check" => checks.push(CheckConfig {
                equal: names(c),
                relative_tolerance: imp.f64_attr(f, c, "relativeTolerance")?.unwrap_or(0.005),
                why: c.attr("why").map(str::to_string),
            }),
            _ => {}
        }
    }
    Ok(())
}

/// One `ParameterBinding`: its values into `parameters` (`instance.variable`).
fn bind(
    imp: &Importer<'_>,
    components: &[Component],
    component: Option<usize>,
    b: &Node,
    parameters: &mut BTreeMap<String, toml::Value>,
) -> Result<(), SspImportError> {
    let f = SSD;
    if let Some(t) = b.attr("type") {
        if t != "application/x-ssp-parameter-set" {
            return Err(imp.unsupported(
                f,
                b,
                &format!("type=\"{t}\": parameter values are SSV parameter sets (application/x-ssp-parameter-set)"),
            ));
        }
    }
    if b.attr("sourceBase").is_some_and(|s| s != "SSD") {
        return Err(imp.unsupported(
            f,
            b,
            "sourceBase=\"component\": an .ssv file is found relative to the SSD (sourceBase=\"SSD\", the default)",
        ));
    }
    let prefix = b.attr("prefix").unwrap_or_default();
    let inner = imp.children(f, b, &["ParameterValues"], &[]).map_err(|e| match e {
        SspImportError::Unsupported {
            ssp,
            file,
            line,
            element,
            ..
        } if element == "ParameterMapping" => SspImportError::Unsupported {
            ssp,
            file,
            line,
            element,
            supported: "parameter mappings are not supported: name the FMU's variables in the parameter set (prefix may prepend a common part)".into(),
        },
        other => other,
    })?;
    let target = Target {
        components,
        component,
        prefix,
    };
    // The parameter set: in an .ssv file of the package, or inline.
    match (b.attr("source"), inner.first()) {
        (Some(_), Some(v)) => Err(imp.invalid(
            f,
            v.line,
            "a ParameterBinding has either a source or inline ParameterValues, not both",
        )),
        (Some(src), None) => {
            let path = imp.read_entry(f, b.line, src)?;
            let name = src.strip_prefix("./").unwrap_or(src).to_string();
            if !path.is_file() {
                return Err(imp.invalid(
                    f,
                    b.line,
                    format!("ParameterBinding source '{name}' is not in the package"),
                ));
            }
            let set = imp.read_xml(&name, &path)?;
            bind_set(imp, &target, &name, &set, parameters)
        }
        (None, Some(v)) => match imp.children(f, v, &["ParameterSet"], &[])?.first() {
            Some(set) => bind_set(imp, &target, f, set, parameters),
            None => Ok(()),
        },
        (None, None) => Err(imp.invalid(
            f,
            b.line,
            "a ParameterBinding without a source or ParameterValues",
        )),
    }
}

/// Whose parameters a set holds: one component's (names relative to it) or the system's
/// (`element.variable`), each name after `prefix`.
struct Target<'a> {
    components: &'a [Component],
    component: Option<usize>,
    prefix: &'a str,
}

/// The values of one `<ssv:ParameterSet>` (in `file`) into `parameters`.
fn bind_set(
    imp: &Importer<'_>,
    target: &Target<'_>,
    file: &str,
    set: &Node,
    parameters: &mut BTreeMap<String, toml::Value>,
) -> Result<(), SspImportError> {
    if set.ns != NS_SSV || set.name != "ParameterSet" {
        return Err(imp.invalid(
            file,
            set.line,
            format!("<{}> is not an SSP 1.0 <ssv:ParameterSet>", set.name),
        ));
    }
    let mut params = Vec::new();
    for part in imp.children(
        file,
        set,
        &["Parameters", "Units", "Enumerations"],
        &["MetaData"],
    )? {
        match part.name.as_str() {
            "Parameters" => params.extend(imp.children(file, part, &["Parameter"], &[])?),
            "Units" => {
                if let Some(u) = imp.children(file, part, &["Unit"], &[])?.first() {
                    return Err(imp.unsupported(
                        file,
                        u,
                        "units of a parameter set are not supported: declare them in the SSD's <ssd:Units>",
                    ));
                }
            }
            _ => {}
        }
    }
    let mut set_here: Vec<(String, usize)> = Vec::new();
    for p in params {
        let (k, var) = parameter_target(imp, target, file, p)?;
        let comp = &target.components[k];
        let full = format!("{}.{var}", comp.name);
        // One value per parameter in a set (N29: a second silently won).
        if let Some((_, line)) = set_here.iter().find(|(n, _)| *n == full) {
            return Err(imp.invalid(
                file,
                p.line,
                format!(
                    "parameter '{full}' is set twice in this parameter set (first at line {line})"
                ),
            ));
        }
        set_here.push((full.clone(), p.line));
        let value = parameter_value(imp, comp, &var, &full, file, p)?;
        parameters.insert(full, value);
    }
    Ok(())
}

/// The component and FMU variable a `<ssv:Parameter>` sets.
fn parameter_target(
    imp: &Importer<'_>,
    target: &Target<'_>,
    file: &str,
    p: &Node,
) -> Result<(usize, String), SspImportError> {
    let pname = format!("{}{}", target.prefix, p.attr("name").unwrap_or_default());
    if let Some(k) = target.component {
        return Ok((k, pname));
    }
    let (e, v) = pname.split_once('.').ok_or_else(|| {
        imp.invalid(
            file,
            p.line,
            format!("parameter '{pname}' of the system is not element.variable"),
        )
    })?;
    let components = target.components;
    let k = components.iter().position(|c| c.name == e).ok_or_else(|| {
        imp.invalid(
            file,
            p.line,
            format!(
                "parameter '{pname}': no component '{e}' (components: {})",
                component_names(components)
            ),
        )
    })?;
    Ok((k, v.to_string()))
}

/// A `<ssv:Parameter>`'s value for the FMU's variable `var`: a Real converted from its
/// unit, an Integer, a Boolean, a String, an Enumeration by item name.
fn parameter_value(
    imp: &Importer<'_>,
    comp: &Component,
    var: &str,
    full: &str,
    file: &str,
    p: &Node,
) -> Result<toml::Value, SspImportError> {
    let sv = comp.md.variable(var).ok_or_else(|| {
        let mut close = comp.md.closest_names(var, 3);
        close.retain(|c| !c.is_empty());
        imp.invalid(
            file,
            p.line,
            format!(
                "parameter '{var}' of component '{}': the FMU {} has no variable '{var}' (closest: {})",
                comp.name,
                comp.entry,
                close.join(", ")
            ),
        )
    })?;
    let vals = imp.children(
        file,
        p,
        &["Real", "Integer", "Boolean", "String", "Enumeration"],
        &["Description"],
    )?;
    let Some(v) = vals.first() else {
        return Err(imp.invalid(file, p.line, format!("parameter '{full}' has no value")));
    };
    let text = v.attr("value").ok_or_else(|| {
        imp.invalid(
            file,
            v.line,
            format!("parameter '{full}': no value attribute"),
        )
    })?;
    let bad = |what: &str| {
        imp.invalid(
            file,
            v.line,
            format!("parameter '{full}': value=\"{text}\" is not {what}"),
        )
    };
    Ok(match v.name.as_str() {
        "Real" => {
            let mut x = parse_double(text).ok_or_else(|| bad("a number"))?;
            // A value in a unit is converted to the variable's, also to a variable without
            // one (N29: 500 ms for a unitless variable was taken as 500).
            // A variable without a unit is dimensionless ("1"): a value in "%" is scaled,
            // one in "ms" refused.
            let fu = comp.md.unit_of(sv).unwrap_or("1");
            if let Some(u) = v.attr("unit").filter(|u| *u != fu) {
                let md = imp.unit_md(&comp.md);
                let c = crate::plan::units::unit_conversion((&md, Some(u)), (&md, Some(fu)))
                    .map_err(|m| imp.invalid(file, v.line, format!("parameter '{full}': {m}")))?;
                x = c.scale * x + c.offset;
            }
            toml::Value::Float(x)
        }
        "Integer" => toml::Value::Integer(text.trim().parse().map_err(|_| bad("an integer"))?),
        "Boolean" => toml::Value::Boolean(parse_bool(text).ok_or_else(|| bad("a boolean"))?),
        "String" => toml::Value::String(text.to_string()),
        _ => {
            // By item name, in the FMU's enumeration type.
            let items = comp.md.enumeration_items(sv).ok_or_else(|| {
                imp.invalid(
                    file,
                    v.line,
                    format!(
                        "parameter '{full}' is {}, not an Enumeration of the FMU",
                        sv.ty.name()
                    ),
                )
            })?;
            let (_, i) = items.iter().find(|(n, _)| n == text).ok_or_else(|| {
                imp.invalid(
                    file,
                    v.line,
                    format!(
                        "parameter '{full}': '{text}' is not an item of its Enumeration ({})",
                        items
                            .iter()
                            .map(|(n, _)| n.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
            toml::Value::Integer(*i)
        }
    })
}

/// One `Connection` between two components.
fn connection(
    imp: &Importer<'_>,
    components: &[Component],
    c: &Node,
) -> Result<ConnectionConfig, SspImportError> {
    let f = SSD;
    let transforms = imp
        .children(f, c, &["LinearTransformation"], &["ConnectionGeometry"])
        .map_err(|e| match e {
            SspImportError::Unsupported {
                ssp,
                file,
                line,
                element,
                ..
            } if element.ends_with("MappingTransformation") => SspImportError::Unsupported {
                ssp,
                file,
                line,
                element,
                supported: "mapping transformations (Boolean, Integer, Enumeration) are not supported; a connection may have an <ssc:LinearTransformation>".into(),
            },
            other => other,
        })?;
    let (fk, fv) = connection_end(imp, components, c, "startElement", "startConnector")?;
    let (tk, tv) = connection_end(imp, components, c, "endElement", "endConnector")?;
    let (from, to) = (&components[fk], &components[tk]);
    let text = format!("{}.{fv} -> {}.{tv}", from.name, to.name);
    let suppress = match c.attr("suppressUnitConversion") {
        None => false,
        Some(s) => parse_bool(s).ok_or_else(|| {
            imp.invalid(
                f,
                c.line,
                format!("suppressUnitConversion=\"{s}\" is not a boolean"),
            )
        })?,
    };
    let lt = match transforms.first() {
        Some(t) => Some((
            imp.f64_attr(f, t, "factor")?.unwrap_or(1.0),
            imp.f64_attr(f, t, "offset")?.unwrap_or(0.0),
        )),
        None => None,
    };
    let tsv = to.md.variable(&tv).expect("checked with the connectors");
    let plain = ConnectionConfig::from(text.as_str());
    if tsv.ty != ScalarType::Real {
        if lt.is_some() {
            return Err(imp.invalid(
                f,
                c.line,
                format!(
                    "connection \"{text}\": a LinearTransformation applies to Real connectors, '{}.{tv}' is {}",
                    to.name,
                    tsv.ty.name()
                ),
            ));
        }
        return Ok(plain);
    }
    let ends = ((from, fv.as_str()), (to, tv.as_str()));
    let Some((scale, offset)) = connection_gain(imp, ends, suppress, lt)
        .map_err(|m| imp.invalid(f, c.line, format!("connection \"{text}\": {m}")))?
    else {
        return Ok(plain);
    };
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(imp.invalid(
            f,
            c.line,
            format!("connection \"{text}\": factor {scale} and offset {offset} must be finite, the factor non-zero"),
        ));
    }
    Ok(ConnectionConfig {
        text,
        scale: Some(scale),
        offset: Some(offset),
        from_unit: None,
        to_unit: None,
    })
}

/// One end of a connection: a component and one of its declared connectors.
fn connection_end(
    imp: &Importer<'_>,
    components: &[Component],
    c: &Node,
    el: &str,
    con: &str,
) -> Result<(usize, String), SspImportError> {
    let f = SSD;
    let Some(e) = c.attr(el) else {
        return Err(imp.unsupported(
            f,
            c,
            &format!(
                "a connection without {el} uses the system's own connectors, which are not supported: connect components directly"
            ),
        ));
    };
    let k = components.iter().position(|x| x.name == e).ok_or_else(|| {
        imp.invalid(
            f,
            c.line,
            format!(
                "{el}=\"{e}\" is not a component (components: {})",
                component_names(components)
            ),
        )
    })?;
    let name = c.attr(con).unwrap_or_default().to_string();
    if !components[k].connectors.contains_key(&name) {
        return Err(imp.invalid(
            f,
            c.line,
            format!(
                "{con}=\"{name}\" is not a connector of component '{e}' (declared: {})",
                components[k]
                    .connectors
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    Ok((k, name))
}

/// The gain of a Real connection as `(scale, offset)`, or None where the plan's own unit
/// conversion of the FMUs' units is exactly what the SSD says: with the unit conversion
/// suppressed, the `LinearTransformation` alone (or none); else the connectors' units
/// converted, then the transformation applied.
fn connection_gain(
    imp: &Importer<'_>,
    ((from, fv), (to, tv)): ((&Component, &str), (&Component, &str)),
    suppress: bool,
    lt: Option<(f64, f64)>,
) -> Result<Option<(f64, f64)>, String> {
    let fsv = from.md.variable(fv).expect("checked with the connectors");
    let tsv = to.md.variable(tv).expect("checked with the connectors");
    let fmu_units = (from.md.unit_of(fsv), to.md.unit_of(tsv));
    let con_units = (
        from.connectors[fv].0.as_deref().or(fmu_units.0),
        to.connectors[tv].0.as_deref().or(fmu_units.1),
    );
    if suppress {
        return Ok(match lt {
            None if fmu_units.0 == fmu_units.1
                || fmu_units.0.is_none()
                || fmu_units.1.is_none() =>
            {
                None
            }
            None => Some((1.0, 0.0)),
            Some(t) => Some(t),
        });
    }
    if lt.is_none() && con_units == fmu_units {
        // The plan converts the FMUs' own units, exactly as the SSD says.
        return Ok(None);
    }
    let conv = crate::plan::units::unit_conversion(
        (&imp.unit_md(&from.md), con_units.0),
        (&imp.unit_md(&to.md), con_units.1),
    )?;
    Ok(Some(match lt {
        None => (conv.scale, conv.offset),
        Some((factor, off)) => (factor * conv.scale, factor * conv.offset + off),
    }))
}

#[cfg(test)]
mod lines_tests {
    use super::Lines;

    /// N10: 250,000 empty elements, their line numbers asked in order as the parser asks
    /// them: right, and each byte looked at once (counting from the start every time looked
    /// at 3·10^10 bytes and took 48 s).
    #[test]
    fn line_numbers_are_counted_on_in_linear_work() {
        let text = "<a/>\n".repeat(250_000);
        let mut lines = Lines::new(&text);
        for k in 0..250_000usize {
            assert_eq!(lines.at((k * 5) as u64), k + 1);
        }
        assert_eq!(lines.scanned, text.len() - 5);
        // Backwards (an error before the last position): counted afresh, still right.
        assert_eq!(lines.at(12), 3);
    }
}
