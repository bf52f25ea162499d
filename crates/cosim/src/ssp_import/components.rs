//! Units, components, their FMUs and connectors.

use super::error::SspImportError;
use super::importer::*;
use super::xml::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tb_fmi::units::UnitDef;

/// The SSD's `<ssd:Units>`: each name with its SI base units, factor and offset.
pub(super) fn read_units(
    imp: &Importer<'_>,
    top: &[&Node],
) -> Result<Vec<(String, UnitDef)>, SspImportError> {
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
pub(super) fn system_parts<'n>(
    imp: &Importer<'_>,
    system: &'n Node,
) -> Result<Vec<&'n Node>, SspImportError> {
    imp.children(
        SSD,
        system,
        &["Connectors", "ParameterBindings", "Elements", "Connections"],
        &["ElementGeometry", "SystemGeometry", "GraphicalElements"],
    )
    .map_err(|e| {
        e.explained(
            |element| element == "SignalDictionaries",
            |supported| format!("signal dictionaries have no twinbench equivalent; connect the components directly ({supported})"),
        )
    })
}

/// A component's parameter bindings: which component (None: the system's) and the node.
pub(super) type Bindings<'n> = Vec<(Option<usize>, &'n Node)>;

/// The components, the FMUs by `[fmus]` key, and the parameter bindings.
pub(super) type Elements<'n> = (Vec<Component>, BTreeMap<String, PathBuf>, Bindings<'n>);

/// The components of `<ssd:Elements>` with their FMUs (one `[fmus]` key per FMU entry of
/// the package) and their parameter bindings.
pub(super) fn read_components<'n>(
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
pub(super) fn fmu_key(entry: &str, fmus: &BTreeMap<String, PathBuf>) -> String {
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
pub(super) fn component_fmu(
    imp: &Importer<'_>,
    c: &Node,
) -> Result<(String, PathBuf), SspImportError> {
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
pub(super) fn read_connectors(
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

/// The FMUs in an unpacked package, for a message.
pub(super) fn fmus_in(dir: &Path) -> String {
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
