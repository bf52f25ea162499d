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

use crate::config::{InstanceConfig, SystemFile};
use std::collections::BTreeMap;
use std::path::Path;
use tb_fmi::FmuCache;

mod components;
mod connections;
mod error;
mod experiment;
mod importer;
mod parameters;
mod xml;

use components::*;
use connections::*;
pub use error::SspImportError;
use experiment::*;
use importer::*;
use parameters::*;
use xml::*;
pub use xml::{NS_SSC, NS_SSD, NS_SSV};

/// Whether a system path names an SSP package (by its extension, as SSP tools do).
pub fn is_ssp(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ssp"))
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
