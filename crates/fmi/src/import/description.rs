//! modelDescription.xml reader (FMI 2.0). Tolerant as the standard asks: unknown
//! attributes and elements (vendor annotations, tool extensions) are ignored.

pub use crate::schema::{Causality, Initial, ScalarType, Variability};
use crate::units::UnitDef;
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::collections::HashMap;

#[derive(Clone, Debug, PartialEq)]
pub struct ScalarVariable {
    pub name: String,
    pub value_reference: u32,
    pub description: String,
    pub causality: Causality,
    pub variability: Variability,
    pub initial: Option<Initial>,
    pub ty: ScalarType,
    pub declared_type: Option<String>,
    pub unit: Option<String>,
    pub start: Option<String>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub nominal: Option<f64>,
    /// FMI 3.0: the variable's own type and, for an array element, where it sits.
    pub fmi3: Option<crate::description3::Fmi3Slot>,
}

impl ScalarVariable {
    pub fn start_f64(&self) -> Option<f64> {
        let s = self.start.as_deref()?;
        match s {
            "true" => Some(1.0),
            "false" => Some(0.0),
            _ => s.trim().parse().ok(),
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct CoSimulation {
    pub model_identifier: String,
    pub needs_execution_tool: bool,
    pub can_handle_variable_communication_step_size: bool,
    pub can_be_instantiated_only_once_per_process: bool,
    pub can_get_and_set_fmu_state: bool,
    pub can_serialize_fmu_state: bool,
    pub can_interpolate_inputs: bool,
    pub provides_directional_derivative: bool,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Unknown {
    /// 1-based index into the ScalarVariable list.
    pub index: usize,
    /// `None`: attribute absent (depends on everything).
    pub dependencies: Option<Vec<usize>>,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: Option<f64>,
    pub stop_time: Option<f64>,
    pub step_size: Option<f64>,
    pub tolerance: Option<f64>,
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelDescription {
    pub fmi_version: String,
    pub model_name: String,
    pub guid: String,
    pub description: String,
    pub generation_tool: String,
    pub co_simulation: Option<CoSimulation>,
    pub has_model_exchange: bool,
    /// `<Unit>` name and its base-unit definition (the definition's own name is unused).
    pub units: Vec<(String, UnitDef)>,
    /// SimpleType name -> its unit.
    pub type_units: HashMap<String, String>,
    /// Enumeration SimpleType name -> its items (name, value), in declaration order.
    pub enumerations: HashMap<String, Vec<(String, i64)>>,
    pub log_categories: Vec<String>,
    pub default_experiment: Option<DefaultExperiment>,
    pub variables: Vec<ScalarVariable>,
    pub outputs: Vec<Unknown>,
    pub initial_unknowns: Vec<Unknown>,
    /// FMI 3.0: what the description has that twinbench cannot run (clocks, Scheduled
    /// Execution), each named; the archive check refuses the FMU with them.
    pub unsupported: Vec<String>,
}

impl ModelDescription {
    pub fn variable(&self, name: &str) -> Option<&ScalarVariable> {
        self.variables.iter().find(|v| v.name == name)
    }

    /// The unit of a variable: its own, or its declared type's.
    pub fn unit_of<'a>(&'a self, v: &'a ScalarVariable) -> Option<&'a str> {
        v.unit.as_deref().or_else(|| {
            v.declared_type
                .as_ref()
                .and_then(|t| self.type_units.get(t))
                .map(String::as_str)
        })
    }

    /// What the ModelStructure leaves out that the standard requires: outputs missing from
    /// `<Outputs>`, and outputs or calculated parameters computed at initialisation
    /// (`initial` approx or calculated, explicitly or by default) missing from
    /// `<InitialUnknowns>`. Some exporters omit these; twinbench then assumes such a
    /// variable depends on every input, but other importers may reject the FMU.
    pub fn model_structure_gaps(&self) -> Vec<String> {
        let listed = |list: &[Unknown], i: usize| list.iter().any(|u| u.index == i + 1);
        let names = |pick: &dyn Fn(usize, &ScalarVariable) -> bool| -> Vec<&str> {
            self.variables
                .iter()
                .enumerate()
                .filter(|(i, v)| pick(*i, v))
                .map(|(_, v)| v.name.as_str())
                .collect()
        };
        let computed_at_init = |v: &ScalarVariable| match v.causality {
            Causality::Output => {
                v.variability != Variability::Constant && v.initial != Some(Initial::Exact)
            }
            Causality::CalculatedParameter => v.initial != Some(Initial::Exact),
            _ => false,
        };
        let mut gaps = Vec::new();
        let outputs = names(&|i, v| v.causality == Causality::Output && !listed(&self.outputs, i));
        let initial = names(&|i, v| computed_at_init(v) && !listed(&self.initial_unknowns, i));
        let show = |v: &[&str]| {
            let mut s = v.iter().take(5).copied().collect::<Vec<_>>().join(", ");
            if v.len() > 5 {
                s.push_str(&format!(" and {} more", v.len() - 5));
            }
            s
        };
        if !outputs.is_empty() {
            gaps.push(format!(
                "ModelStructure/Outputs does not list {} output(s): {}",
                outputs.len(),
                show(&outputs)
            ));
        }
        if !initial.is_empty() {
            gaps.push(format!(
                "ModelStructure/InitialUnknowns {} {} variable(s) computed at initialisation: {}",
                if self.initial_unknowns.is_empty() {
                    "is missing; it must list"
                } else {
                    "does not list"
                },
                initial.len(),
                show(&initial)
            ));
        }
        gaps
    }

    /// The items of an Enumeration variable's declared type.
    pub fn enumeration_items(&self, v: &ScalarVariable) -> Option<&[(String, i64)]> {
        (v.ty == ScalarType::Enumeration)
            .then_some(v.declared_type.as_ref())
            .flatten()
            .and_then(|t| self.enumerations.get(t))
            .map(Vec::as_slice)
    }

    pub fn unit_def(&self, name: &str) -> Option<&UnitDef> {
        self.units.iter().find(|u| u.0 == name).map(|u| &u.1)
    }

    /// Up to `n` variable names closest to `name` (for "did you mean" messages).
    pub fn closest_names(&self, name: &str, n: usize) -> Vec<&str> {
        closest(name, self.variables.iter().map(|v| v.name.as_str()), n)
    }
}

/// Up to `n` of `candidates` closest to `name` by [`edit_distance`], closest first (for
/// "closest names" in messages).
pub fn closest<'a>(
    name: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    n: usize,
) -> Vec<&'a str> {
    let mut scored: Vec<(usize, &str)> = candidates
        .into_iter()
        .map(|c| (edit_distance(name, c), c))
        .collect();
    scored.sort();
    scored.into_iter().take(n).map(|(_, s)| s).collect()
}

/// Edit distance, case-insensitive: insertions, deletions, substitutions and swaps of two
/// neighbouring characters (the commonest typo, `Fz_lr` for `Fz_rl`) cost one each (the
/// optimal string alignment distance).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let a: Vec<char> = a.to_lowercase().chars().collect();
    let b: Vec<char> = b.to_lowercase().chars().collect();
    let mut before: Vec<usize> = Vec::new();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for i in 1..=a.len() {
        let mut cur = vec![i; b.len() + 1];
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            cur[j] = (prev[j] + 1).min(cur[j - 1] + 1).min(prev[j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                cur[j] = cur[j].min(before[j - 2] + 1);
            }
        }
        before = std::mem::replace(&mut prev, cur);
    }
    prev[b.len()]
}

pub(crate) fn attrs(e: &BytesStart) -> Result<HashMap<String, String>, String> {
    let mut m = HashMap::new();
    for a in e.attributes() {
        let a = a.map_err(|e| format!("bad attribute: {e}"))?;
        let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
        let val = a
            .unescape_value()
            .map_err(|e| format!("bad attribute value of '{key}': {e}"))?;
        m.insert(key, val.into_owned());
    }
    Ok(m)
}

pub(crate) fn num(
    m: &HashMap<String, String>,
    key: &str,
    ctx: &str,
) -> Result<Option<f64>, String> {
    match m.get(key) {
        None => Ok(None),
        Some(s) => s
            .trim()
            .parse()
            .map(Some)
            .map_err(|_| format!("{ctx}: attribute {key}=\"{s}\" is not a number")),
    }
}

/// `<BaseUnit>` (the same in FMI 2.0 and 3.0) into `u`.
pub(crate) fn base_unit(m: &HashMap<String, String>, u: &mut UnitDef) -> Result<(), String> {
    u.kg = int_attr(m, "kg");
    u.m = int_attr(m, "m");
    u.s = int_attr(m, "s");
    u.a = int_attr(m, "A");
    u.k = int_attr(m, "K");
    u.mol = int_attr(m, "mol");
    u.cd = int_attr(m, "cd");
    u.rad = int_attr(m, "rad");
    u.factor = num(m, "factor", "BaseUnit")?.unwrap_or(1.0);
    u.offset = num(m, "offset", "BaseUnit")?.unwrap_or(0.0);
    Ok(())
}

/// `<DefaultExperiment>` (the same in FMI 2.0 and 3.0).
pub(crate) fn default_experiment(m: &HashMap<String, String>) -> Result<DefaultExperiment, String> {
    Ok(DefaultExperiment {
        start_time: num(m, "startTime", "DefaultExperiment")?,
        stop_time: num(m, "stopTime", "DefaultExperiment")?,
        step_size: num(m, "stepSize", "DefaultExperiment")?,
        tolerance: num(m, "tolerance", "DefaultExperiment")?,
    })
}

/// An enumeration `<Item name value>` of type `ty`: (name, value).
pub(crate) fn enumeration_item(
    m: &HashMap<String, String>,
    ty: &str,
) -> Result<(String, i64), String> {
    let item = m.get("name").cloned().unwrap_or_default();
    let value = m
        .get("value")
        .and_then(|v| v.trim().parse::<i64>().ok())
        .ok_or_else(|| format!("Enumeration '{ty}': item '{item}' has no integer value"))?;
    Ok((item, value))
}

/// A `<DisplayUnit name factor offset>` of `unit` as a unit definition of its own:
/// display = factor·value + offset, so SI = base.factor·(display − offset)/factor +
/// base.offset. An FMI 3.0 `inverse` display unit is not linear and is left out.
pub(crate) fn display_unit(
    m: &HashMap<String, String>,
    unit: &(String, UnitDef),
) -> Result<Option<(String, UnitDef)>, String> {
    let Some(name) = m.get("name") else {
        return Err(format!("unit '{}': <DisplayUnit> without a name", unit.0));
    };
    if flag(m, "inverse") {
        return Ok(None);
    }
    let ctx = format!("unit '{}': DisplayUnit '{name}'", unit.0);
    let factor = num(m, "factor", &ctx)?.unwrap_or(1.0);
    let offset = num(m, "offset", &ctx)?.unwrap_or(0.0);
    if factor == 0.0 || !factor.is_finite() || !offset.is_finite() {
        return Err(format!(
            "{ctx}: factor {factor} and offset {offset} do not define a unit"
        ));
    }
    let base = &unit.1;
    Ok(Some((
        name.clone(),
        UnitDef {
            factor: base.factor / factor,
            offset: base.offset - base.factor * offset / factor,
            ..*base
        },
    )))
}

/// The `<fmiModelDescription>` attributes both versions share; `token` names the GUID's
/// attribute (`guid` in 2.0, `instantiationToken` in 3.0).
pub(crate) fn root_attributes(md: &mut ModelDescription, m: &HashMap<String, String>, token: &str) {
    let get = |key: &str| m.get(key).cloned().unwrap_or_default();
    md.fmi_version = get("fmiVersion");
    md.model_name = get("modelName");
    md.guid = get(token);
    md.description = get("description");
    md.generation_tool = get("generationTool");
}

pub(crate) fn int_attr(m: &HashMap<String, String>, key: &str) -> i32 {
    m.get(key).and_then(|s| s.trim().parse().ok()).unwrap_or(0)
}

pub(crate) fn flag(m: &HashMap<String, String>, key: &str) -> bool {
    m.get(key).is_some_and(|s| s == "true" || s == "1")
}

fn unknown(m: &HashMap<String, String>) -> Result<Unknown, String> {
    let index = m
        .get("index")
        .and_then(|s| s.trim().parse().ok())
        .ok_or("ModelStructure: <Unknown> without a valid index")?;
    let dependencies = match m.get("dependencies") {
        None => None,
        Some(s) => Some(
            s.split_whitespace()
                .map(|d| {
                    d.parse()
                        .map_err(|_| format!("ModelStructure: bad dependency '{d}'"))
                })
                .collect::<Result<Vec<usize>, String>>()?,
        ),
    };
    Ok(Unknown {
        index,
        dependencies,
    })
}

/// Parse modelDescription.xml text (FMI 2.0, or 3.0 by its `fmiVersion`). Errors say what
/// is wrong; the caller adds the file.
pub fn parse(xml: &str) -> Result<ModelDescription, String> {
    if crate::archive::sniff_fmi_version(xml).is_some_and(|v| v.starts_with("3.")) {
        return crate::description3::parse(xml);
    }
    parse2(xml)
}

fn parse2(xml: &str) -> Result<ModelDescription, String> {
    let mut reader = Reader::from_str(xml);
    let mut md = ModelDescription::default();
    let mut stack: Vec<String> = Vec::new();
    let mut current: Option<ScalarVariable> = None;
    let mut current_unit: Option<(String, UnitDef)> = None;
    // Display units become units of their own (after the FMU's own, which win a name).
    let mut display_units: Vec<(String, UnitDef)> = Vec::new();
    let mut current_type: Option<String> = None;
    let mut saw_root = false;
    loop {
        let ev = reader
            .read_event()
            .map_err(|e| format!("XML error at byte {}: {e}", reader.buffer_position()))?;
        let (e, empty) = match &ev {
            Event::Start(e) => (e.clone(), false),
            Event::Empty(e) => (e.clone(), true),
            Event::End(_) => {
                let name = stack.pop().unwrap_or_default();
                match name.as_str() {
                    "ScalarVariable" => {
                        if let Some(v) = current.take() {
                            md.variables.push(v);
                        }
                    }
                    "Unit" => {
                        if let Some(u) = current_unit.take() {
                            md.units.push(u);
                        }
                    }
                    "SimpleType" => current_type = None,
                    _ => {}
                }
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let m = attrs(&e)?;
        let parent = stack.last().map(String::as_str).unwrap_or("");
        match (parent, name.as_str()) {
            ("", "fmiModelDescription") => {
                saw_root = true;
                root_attributes(&mut md, &m, "guid");
            }
            ("", other) => {
                return Err(format!(
                    "root element is <{other}>, expected <fmiModelDescription>"
                ))
            }
            ("fmiModelDescription", "CoSimulation") => {
                md.co_simulation = Some(CoSimulation {
                    model_identifier: m
                        .get("modelIdentifier")
                        .cloned()
                        .ok_or("<CoSimulation> has no modelIdentifier")?,
                    needs_execution_tool: flag(&m, "needsExecutionTool"),
                    can_handle_variable_communication_step_size: flag(
                        &m,
                        "canHandleVariableCommunicationStepSize",
                    ),
                    can_be_instantiated_only_once_per_process: flag(
                        &m,
                        "canBeInstantiatedOnlyOncePerProcess",
                    ),
                    can_get_and_set_fmu_state: flag(&m, "canGetAndSetFMUstate"),
                    can_serialize_fmu_state: flag(&m, "canSerializeFMUstate"),
                    can_interpolate_inputs: flag(&m, "canInterpolateInputs"),
                    provides_directional_derivative: flag(&m, "providesDirectionalDerivative"),
                })
            }
            ("fmiModelDescription", "ModelExchange") => md.has_model_exchange = true,
            ("fmiModelDescription", "DefaultExperiment") => {
                md.default_experiment = Some(crate::description::default_experiment(&m)?)
            }
            ("UnitDefinitions", "Unit") => {
                let uname = m.get("name").cloned().ok_or("<Unit> without a name")?;
                current_unit = Some((uname, UnitDef::DIMENSIONLESS));
                if empty {
                    md.units.push(current_unit.take().unwrap());
                }
            }
            ("Unit", "DisplayUnit") => {
                if let Some(u) = &current_unit {
                    if let Some(d) = crate::description::display_unit(&m, u)? {
                        display_units.push(d);
                    }
                }
            }
            ("Unit", "BaseUnit") => {
                if let Some((_, u)) = current_unit.as_mut() {
                    crate::description::base_unit(&m, u)?;
                }
            }
            ("TypeDefinitions", "SimpleType") => current_type = m.get("name").cloned(),
            ("SimpleType", "Real") => {
                if let (Some(t), Some(u)) = (&current_type, m.get("unit")) {
                    md.type_units.insert(t.clone(), u.clone());
                }
            }
            ("Enumeration", "Item") => {
                if let Some(t) = &current_type {
                    let item = crate::description::enumeration_item(&m, t)?;
                    md.enumerations.entry(t.clone()).or_default().push(item);
                }
            }
            ("LogCategories", "Category") => {
                if let Some(n) = m.get("name") {
                    md.log_categories.push(n.clone());
                }
            }
            ("ModelVariables", "ScalarVariable") => {
                let vname = m
                    .get("name")
                    .cloned()
                    .ok_or("<ScalarVariable> without a name")?;
                let vr = m
                    .get("valueReference")
                    .and_then(|s| s.trim().parse().ok())
                    .ok_or_else(|| format!("variable '{vname}': missing or bad valueReference"))?;
                let ctx = |e: crate::schema::UnknownName| format!("variable '{vname}': {e}");
                let causality = match m.get("causality") {
                    Some(c) => Causality::parse(c).map_err(ctx)?,
                    None => Causality::DEFAULT,
                };
                let variability = match m.get("variability") {
                    Some(v) => Variability::parse(v).map_err(ctx)?,
                    None => Variability::DEFAULT,
                };
                let initial = match m.get("initial") {
                    Some(i) => Some(Initial::parse(i).map_err(ctx)?),
                    None => None,
                };
                current = Some(ScalarVariable {
                    name: vname,
                    value_reference: vr,
                    description: m.get("description").cloned().unwrap_or_default(),
                    causality,
                    variability,
                    initial,
                    ty: ScalarType::Real,
                    declared_type: None,
                    unit: None,
                    start: None,
                    min: None,
                    max: None,
                    nominal: None,
                    fmi3: None,
                });
                if empty {
                    return Err(format!(
                        "variable '{}' has no type element",
                        current.unwrap().name
                    ));
                }
            }
            ("ScalarVariable", t @ ("Real" | "Integer" | "Boolean" | "String" | "Enumeration")) => {
                if let Some(v) = current.as_mut() {
                    let ctx = format!("variable '{}'", v.name);
                    v.ty = ScalarType::parse(t).expect("matched above");
                    v.declared_type = m.get("declaredType").cloned();
                    v.unit = m.get("unit").cloned();
                    v.start = m.get("start").cloned();
                    v.min = num(&m, "min", &ctx)?;
                    v.max = num(&m, "max", &ctx)?;
                    v.nominal = num(&m, "nominal", &ctx)?;
                }
            }
            ("Outputs", "Unknown") => md.outputs.push(unknown(&m)?),
            ("InitialUnknowns", "Unknown") => md.initial_unknowns.push(unknown(&m)?),
            _ => {}
        }
        if !empty {
            stack.push(name);
        }
    }
    if !saw_root {
        return Err("no <fmiModelDescription> element".into());
    }
    for d in display_units {
        if md.unit_def(&d.0).is_none() {
            md.units.push(d);
        }
    }
    check_names_and_aliases(&md)?;
    let n = md.variables.len();
    for u in md.outputs.iter().chain(&md.initial_unknowns) {
        if u.index == 0 || u.index > n {
            return Err(format!(
                "ModelStructure refers to variable index {} of {n}",
                u.index
            ));
        }
        if let Some(d) = u.dependencies.iter().flatten().find(|&&d| d == 0 || d > n) {
            return Err(format!(
                "ModelStructure: dependency index {d} of variable {} is not in 1..={n}",
                u.index
            ));
        }
    }
    Ok(md)
}

/// Variable names are unique; a value reference shared by several variables (an alias) is
/// allowed among variables of one type, but never for an input or a parameter (a set would
/// write the other variable too: the FMU's interface would not be what it says).
pub(crate) fn check_names_and_aliases(md: &ModelDescription) -> Result<(), String> {
    let mut by_name: HashMap<&str, u32> = HashMap::new();
    let mut by_vr: HashMap<(u32, ScalarType), &ScalarVariable> = HashMap::new();
    for v in &md.variables {
        if let Some(vr) = by_name.insert(&v.name, v.value_reference) {
            return Err(format!(
                "variable name '{}' appears twice (value references {vr} and {})",
                v.name, v.value_reference
            ));
        }
        if let Some(first) = by_vr.insert((v.value_reference, v.ty), v) {
            let settable =
                |x: &ScalarVariable| matches!(x.causality, Causality::Input | Causality::Parameter);
            // FMI 3.0 declares aliases explicitly (`<Alias>`): the same variable by design.
            let declared_alias = md.fmi_version.starts_with("3.");
            if !declared_alias && (settable(first) || settable(v)) {
                return Err(format!(
                    "value reference {} of {} is shared by '{}' ({}) and '{}' ({}): an input or a parameter cannot be an alias",
                    v.value_reference,
                    v.ty,
                    first.name,
                    first.causality,
                    v.name,
                    v.causality
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{g}" vendorTool:extra="x" xmlns:vendorTool="urn:v" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="m" canGetAndSetFMUstate="true" vendorFlag="7"><SourceFiles><File name="a.c"/></SourceFiles></CoSimulation>
  <UnitDefinitions><Unit name="rpm"><BaseUnit s="-1" rad="1" factor="0.10471975511965977"/></Unit><Unit name="1"/></UnitDefinitions>
  <TypeDefinitions><SimpleType name="Speed"><Real unit="rpm"/></SimpleType></TypeDefinitions>
  <VendorAnnotations><Tool name="t"><anything/></Tool></VendorAnnotations>
  <ModelVariables>
    <ScalarVariable name="n" valueReference="3" causality="output" myAttr="1">
      <Real declaredType="Speed" min="0" max="2e4"/>
      <Annotations><Tool name="x"/></Annotations>
    </ScalarVariable>
    <ScalarVariable name="p" valueReference="4" causality="parameter" variability="fixed"><Integer start="2"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs><InitialUnknowns><Unknown index="1"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn display_units_are_units_of_their_own() {
        let xml = XML.replace(
            "<Unit name=\"1\"/>",
            "<Unit name=\"K\"><BaseUnit K=\"1\"/><DisplayUnit name=\"degC\" offset=\"-273.15\"/></Unit><Unit name=\"m\"><BaseUnit m=\"1\"/><DisplayUnit name=\"ft\" factor=\"3.280839895\"/></Unit>",
        );
        let md = parse(&xml).unwrap();
        let c = md.unit_def("degC").unwrap();
        // 20 degC = 293.15 K.
        assert!((c.factor * 20.0 + c.offset - 293.15).abs() < 1e-12);
        assert_eq!(c.k, 1);
        let ft = md.unit_def("ft").unwrap();
        assert!((ft.factor * 3.280839895 - 1.0).abs() < 1e-15);
        assert_eq!(ft.m, 1);
    }

    #[test]
    fn model_structure_gaps_name_what_the_standard_requires() {
        let md = parse(XML).unwrap();
        assert!(md.model_structure_gaps().is_empty());
        let none = XML.replace(
            "<InitialUnknowns><Unknown index=\"1\"/></InitialUnknowns>",
            "",
        );
        let gaps = parse(&none).unwrap().model_structure_gaps();
        assert_eq!(gaps.len(), 1, "{gaps:?}");
        assert!(gaps[0].contains("InitialUnknowns is missing") && gaps[0].contains(": n"));
        // An output declared exact needs no entry; it must still be an Output.
        let exact = none.replace(
            "causality=\"output\" myAttr",
            "causality=\"output\" initial=\"exact\" myAttr",
        );
        assert!(parse(&exact).unwrap().model_structure_gaps().is_empty());
        let no_outputs = exact.replace(
            "<Outputs><Unknown index=\"1\" dependencies=\"\"/></Outputs>",
            "",
        );
        let gaps = parse(&no_outputs).unwrap().model_structure_gaps();
        assert!(
            gaps.len() == 1 && gaps[0].contains("Outputs does not list 1 output(s): n"),
            "{gaps:?}"
        );
    }

    #[test]
    fn reads_tolerantly_and_keeps_units() {
        let md = parse(XML).unwrap();
        assert_eq!(md.fmi_version, "2.0");
        assert!(md.co_simulation.as_ref().unwrap().can_get_and_set_fmu_state);
        assert_eq!(md.variables.len(), 2);
        let n = md.variable("n").unwrap();
        assert_eq!(md.unit_of(n), Some("rpm"));
        assert_eq!(n.max, Some(2e4));
        let rpm = md.unit_def("rpm").unwrap();
        assert!((rpm.factor - std::f64::consts::PI / 30.0).abs() < 1e-15);
        assert_eq!((rpm.s, rpm.rad), (-1, 1));
        assert_eq!(md.variable("p").unwrap().ty, ScalarType::Integer);
        assert_eq!(md.outputs[0].dependencies, Some(vec![]));
        assert_eq!(md.initial_unknowns[0].dependencies, None);
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        assert!(parse("<foo/>")
            .unwrap_err()
            .contains("expected <fmiModelDescription>"));
        let bad = XML.replace("valueReference=\"3\"", "valueReference=\"x\"");
        assert!(parse(&bad)
            .unwrap_err()
            .contains("variable 'n': missing or bad valueReference"));
        let bad = XML.replace("max=\"2e4\"", "max=\"lots\"");
        assert!(parse(&bad)
            .unwrap_err()
            .contains("max=\"lots\" is not a number"));
        assert!(parse("<fmiModelDescription><broken").is_err());
    }

    #[test]
    fn duplicate_names_and_aliased_inputs_are_refused() {
        let two = XML.replace("name=\"p\"", "name=\"n\"");
        assert!(parse(&two)
            .unwrap_err()
            .contains("variable name 'n' appears twice (value references 3 and 4)"));
        let input = r#"<ScalarVariable name="u" valueReference="3" causality="input"><Real start="0"/></ScalarVariable>"#;
        let aliased = XML.replace(
            "<ScalarVariable name=\"p\"",
            &format!("{input}\n    <ScalarVariable name=\"p\""),
        );
        let e = parse(&aliased).unwrap_err();
        assert!(
            e.contains("value reference 3 of Real is shared by 'n' (output) and 'u' (input)"),
            "{e}"
        );
    }

    #[test]
    fn suggests_close_names() {
        let md = parse(XML).unwrap();
        assert_eq!(md.closest_names("N", 1), vec!["n"]);
        assert_eq!(edit_distance("omega_rl", "omega_rr"), 1);
        assert_eq!(edit_distance("Fz_lr", "Fz_rl"), 1, "a swap is one edit");
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("abc", "ca"), 3);
    }
}
