//! modelDescription.xml reader for FMI 3.0, into the same [`ModelDescription`] as FMI 2.0
//! so that everything after loading (plan, units, recording) is version-blind.
//!
//! How FMI 3.0 maps:
//! - Float64 and Float32 are Real; Int8 … Int32, UInt8 and UInt16 are Integer; UInt32, Int64
//!   and UInt64 travel as Real (f64), and a value an f64 cannot carry exactly is an error; Boolean, String and Enumeration keep their
//!   kind; each variable keeps its exact type in [`Fmi3Slot`] for the C calls.
//! - An array becomes one variable per element, `name[i]` or `name[i,j]` (1-based, row-major
//!   as FMI 3.0 stores them). A scalar keeps its declared value reference; an element gets
//!   an internal one among the values no variable declares (the whole `u32` range is the
//!   FMU's, up to 4294967295), and keeps the array's own in [`Fmi3Slot`], which is what the
//!   C calls and `info` use. A zero-size array has no element and no column. Dimensions come
//!   from `start` or from the structural parameter's start value.
//! - `instantiationToken` is kept as the GUID; `ModelStructure` outputs and initial unknowns
//!   become 1-based indices as in FMI 2.0.
//! - Binary is exchanged as text: its bytes in hexadecimal (as FMI 3.0 writes Binary start
//!   values), so it is set, connected and recorded like a String; clocks and Scheduled
//!   Execution are listed in `unsupported` (the archive check refuses such an FMU before
//!   anything runs).

use super::error::DescriptionError;
use super::model::{check_names_and_aliases, ModelDescription, ScalarVariable, Unknown};
pub use super::model::{Fmi3Slot, Fmi3Type};
use super::reader::{num, read, Attrs, Element, Shared, Version, Visit};
use crate::schema::{Causality, Initial, ScalarType, Variability};
use std::collections::HashMap;

/// A variable as declared, before arrays are expanded.
struct Declared {
    var: ScalarVariable,
    ty: Fmi3Type,
    structural: bool,
    /// Each dimension: a fixed size, or the value reference of a structural parameter.
    dims: Vec<Dim>,
    /// `<Start value=…>` children (String), in order.
    starts: Vec<String>,
    /// `<Alias name=…>` children: other names of the same variable.
    aliases: Vec<String>,
}

enum Dim {
    Fixed(u64),
    Parameter(u32),
}

/// An FMI 3.0 Unknown before value references become indices.
struct Unknown3 {
    vr: u32,
    dependencies: Option<Vec<u32>>,
}

fn unknown3(m: &Attrs, what: &str) -> Result<Unknown3, DescriptionError> {
    let vr = m
        .get("valueReference")
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| DescriptionError::EntryValueReference {
            element: what.to_string(),
        })?;
    let dependencies = match m.get("dependencies") {
        None => None,
        Some(s) => Some(
            s.split_whitespace()
                .map(|d| {
                    d.parse().map_err(|_| DescriptionError::EntryDependency {
                        dependency: d.to_string(),
                        element: what.to_string(),
                    })
                })
                .collect::<Result<Vec<u32>, DescriptionError>>()?,
        ),
    };
    Ok(Unknown3 { vr, dependencies })
}

/// Parse an FMI 3.0 modelDescription.xml.
pub fn parse(xml: &str) -> Result<ModelDescription, DescriptionError> {
    read(xml, Reader3::finish)
}

/// The FMI 3.0 reader: the shared elements, then the typed variables (with their
/// dimensions, start values and aliases) and the model structure by value reference.
#[derive(Default)]
struct Reader3 {
    md: ModelDescription,
    shared: Shared,
    declared: Vec<Declared>,
    current: Option<Declared>,
    outputs: Vec<Unknown3>,
    initial_unknowns: Vec<Unknown3>,
    derivatives: Vec<Unknown3>,
    event_indicators: Vec<Unknown3>,
    /// Variables without a column (Clock): the ModelStructure may list them.
    skipped_vrs: Vec<u32>,
}

impl Visit for Reader3 {
    const VERSION: Version = Version::V3;

    fn shared(&mut self) -> (&mut ModelDescription, &mut Shared) {
        (&mut self.md, &mut self.shared)
    }

    fn start(&mut self, stack: &[String], e: Element) -> Result<(), DescriptionError> {
        // A child of a variable element (Dimension, Start, Alias).
        let in_variable = stack.len() >= 2 && stack[stack.len() - 2] == "ModelVariables";
        match (e.parent, e.name) {
            ("fmiModelDescription", "ScheduledExecution") => self
                .md
                .unsupported
                .push("Scheduled Execution (<ScheduledExecution>)".into()),
            ("ModelVariables", t) => {
                if let Some(d) = self.variable(t, e.attrs)? {
                    match e.empty {
                        true => self.declared.push(d),
                        false => self.current = Some(d),
                    }
                }
            }
            (_, "Dimension") if in_variable => {
                if let Some(d) = self.current.as_mut() {
                    d.dims.push(dimension(e.attrs, &d.var.name)?);
                }
            }
            (_, "Start") if in_variable => {
                if let Some(d) = self.current.as_mut() {
                    d.starts
                        .push(e.attrs.get("value").cloned().unwrap_or_default());
                }
            }
            (_, "Alias") if in_variable => {
                if let Some(d) = self.current.as_mut() {
                    let a = e.attrs.get("name").cloned().ok_or_else(|| {
                        DescriptionError::UnnamedAlias {
                            variable: d.var.name.clone(),
                        }
                    })?;
                    d.aliases.push(a);
                }
            }
            ("ModelStructure", "Output") => self.outputs.push(unknown3(e.attrs, "Output")?),
            ("ModelStructure", "InitialUnknown") => self
                .initial_unknowns
                .push(unknown3(e.attrs, "InitialUnknown")?),
            ("ModelStructure", "ContinuousStateDerivative") => self
                .derivatives
                .push(unknown3(e.attrs, "ContinuousStateDerivative")?),
            ("ModelStructure", "EventIndicator") => self
                .event_indicators
                .push(unknown3(e.attrs, "EventIndicator")?),
            _ => {}
        }
        Ok(())
    }

    fn end(&mut self, stack: &[String], _name: &str) {
        if stack.last().map(String::as_str) == Some("ModelVariables") {
            self.declared.extend(self.current.take());
        }
    }
}

impl Reader3 {
    /// A variable element of `<ModelVariables>` (None: a Clock, which has no column).
    fn variable(&mut self, t: &str, m: &Attrs) -> Result<Option<Declared>, DescriptionError> {
        let vname = m
            .get("name")
            .cloned()
            .ok_or_else(|| DescriptionError::Unnamed {
                element: t.to_string(),
            })?;
        let vr: u32 = m
            .get("valueReference")
            .and_then(|s| s.trim().parse().ok())
            .ok_or_else(|| DescriptionError::ValueReference {
                variable: vname.clone(),
            })?;
        if t == "Clock" {
            self.md
                .unsupported
                .push(format!("clocks (variable '{vname}' is a Clock)"));
        }
        if let Some(c) = m.get("clocks") {
            self.md.unsupported.push(format!(
                "clocks (variable '{vname}' is clocked by {})",
                c.trim()
            ));
        }
        let Some(ty) = Fmi3Type::parse(t) else {
            if t != "Clock" {
                return Err(DescriptionError::NotAVariable {
                    element: t.to_string(),
                });
            }
            self.skipped_vrs.push(vr);
            return Ok(None);
        };
        Ok(Some(declared(vname, vr, ty, m)?))
    }

    /// Arrays expanded, value references of the model structure turned into indices, names
    /// and aliases checked.
    fn finish(mut self) -> Result<ModelDescription, DescriptionError> {
        self.shared.finish(&mut self.md)?;
        let mut md = self.md;
        // Every declared value reference, a zero-size array's too (it has no element).
        let mut indices: HashMap<u32, Vec<usize>> = self
            .declared
            .iter()
            .map(|d| (d.var.value_reference, Vec::new()))
            .collect();
        expand(&mut md, self.declared)?;
        // Value references become 1-based indices (every element of an array).
        for (i, v) in md.variables.iter().enumerate() {
            let vr = v.declared_value_reference();
            indices.entry(vr).or_default().push(i + 1);
        }
        let skipped = &self.skipped_vrs;
        md.outputs = to_unknowns(self.outputs, "Output", &indices, skipped)?;
        md.initial_unknowns =
            to_unknowns(self.initial_unknowns, "InitialUnknown", &indices, skipped)?;
        // The state vector and the event indicators: an array's elements in its order
        // (FMI 3.0 §2.4.8: the states are the derivatives' elements, row-major), each value
        // once (an alias is the same value under another name).
        let distinct = |list: Vec<Unknown>, md: &ModelDescription| {
            let mut seen = std::collections::HashSet::new();
            list.into_iter()
                .filter(|u| seen.insert(md.variables[u.index - 1].value_reference))
                .collect::<Vec<Unknown>>()
        };
        md.derivatives = distinct(
            to_unknowns(
                self.derivatives,
                "ContinuousStateDerivative",
                &indices,
                skipped,
            )?,
            &md,
        );
        md.number_of_event_indicators = distinct(
            to_unknowns(self.event_indicators, "EventIndicator", &indices, skipped)?,
            &md,
        )
        .len();
        check_names_and_aliases(&md)?;
        Ok(md)
    }
}

/// A declared variable's attributes (FMI 3.0: variables other than Float32/Float64 are
/// discrete by default; a structural parameter is a parameter twinbench never changes).
fn declared(vname: String, vr: u32, ty: Fmi3Type, m: &Attrs) -> Result<Declared, DescriptionError> {
    let ctx = |source| DescriptionError::Schema {
        variable: vname.clone(),
        source,
    };
    let structural = m.get("causality").map(String::as_str) == Some("structuralParameter");
    let causality = match m.get("causality").map(String::as_str) {
        Some("structuralParameter") => Causality::Parameter,
        Some(c) => Causality::parse(c).map_err(ctx)?,
        None => Causality::DEFAULT,
    };
    let variability = match m.get("variability") {
        Some(v) => Variability::parse(v).map_err(ctx)?,
        None if matches!(ty, Fmi3Type::Float32 | Fmi3Type::Float64) => Variability::Continuous,
        None => Variability::Discrete,
    };
    let initial = match m.get("initial") {
        Some(i) => Some(Initial::parse(i).map_err(ctx)?),
        None => None,
    };
    let at = format!("variable '{vname}'");
    let bound = |key: &str| -> Result<Option<f64>, DescriptionError> {
        match ty.kind() == ScalarType::Real {
            true => num(m, key, &at),
            false => Ok(m.get(key).and_then(|s| s.trim().parse().ok())),
        }
    };
    let var = ScalarVariable {
        name: vname.clone(),
        value_reference: vr,
        description: m.get("description").cloned().unwrap_or_default(),
        causality,
        variability,
        initial,
        ty: ty.kind(),
        declared_type: m.get("declaredType").cloned(),
        unit: m.get("unit").cloned(),
        start: m.get("start").cloned(),
        min: bound("min")?,
        max: bound("max")?,
        nominal: num(m, "nominal", &at)?,
        fmi3: None,
    };
    Ok(Declared {
        var,
        ty,
        structural,
        dims: Vec::new(),
        starts: Vec::new(),
        aliases: Vec::new(),
    })
}

/// A `<Dimension>`: a fixed size, or a structural parameter's value reference.
fn dimension(m: &Attrs, variable: &str) -> Result<Dim, DescriptionError> {
    let variable = variable.to_string();
    if m.contains_key("start") && m.contains_key("valueReference") {
        return Err(DescriptionError::DimensionBoth { variable });
    }
    if let Some(s) = m.get("start") {
        return Ok(Dim::Fixed(s.trim().parse().map_err(|_| {
            DescriptionError::DimensionStart {
                variable,
                found: s.clone(),
            }
        })?));
    }
    if let Some(r) = m.get("valueReference") {
        return Ok(Dim::Parameter(r.trim().parse().map_err(|_| {
            DescriptionError::DimensionValueReference {
                variable,
                found: r.clone(),
            }
        })?));
    }
    Err(DescriptionError::DimensionNeither { variable })
}

/// Model-structure entries by value reference → by 1-based index (an array's entry for
/// each of its elements); entries of Clocks are left out.
fn to_unknowns(
    list: Vec<Unknown3>,
    what: &str,
    indices: &HashMap<u32, Vec<usize>>,
    skipped: &[u32],
) -> Result<Vec<Unknown>, DescriptionError> {
    let mut out = Vec::new();
    for u in list {
        if skipped.contains(&u.vr) {
            continue;
        }
        let idx = indices
            .get(&u.vr)
            .ok_or_else(|| DescriptionError::EntryNoVariable {
                element: what.to_string(),
                value_reference: u.vr,
            })?;
        let deps = match u.dependencies {
            None => None,
            Some(ds) => {
                let mut v = Vec::new();
                for d in ds.into_iter().filter(|d| !skipped.contains(d)) {
                    v.extend(indices.get(&d).ok_or_else(|| {
                        DescriptionError::DependencyNoVariable {
                            dependency: d,
                            element: what.to_string(),
                            value_reference: u.vr,
                        }
                    })?);
                }
                Some(v)
            }
        };
        out.extend(idx.iter().map(|&index| Unknown {
            index,
            dependencies: deps.clone(),
        }));
    }
    Ok(out)
}

/// The largest array twinbench expands into columns.
const MAX_ELEMENTS: u64 = 100_000;
/// The most values all variables may expand into together (elements and their aliases): a
/// small file declaring many large arrays must not exhaust memory before anything runs.
const MAX_TOTAL_ELEMENTS: u64 = 1_000_000;

/// Value references are unique among the declared variables (FMI 3.0 §2.4.7: one value
/// reference names one variable; other names of it are `<Alias>`es).
fn unique_value_references(declared: &[Declared]) -> Result<(), DescriptionError> {
    let mut seen: HashMap<u32, &str> = HashMap::with_capacity(declared.len());
    for d in declared {
        if let Some(first) = seen.insert(d.var.value_reference, &d.var.name) {
            return Err(DescriptionError::DuplicateValueReference {
                value_reference: d.var.value_reference,
                first: first.to_string(),
                second: d.var.name.clone(),
            });
        }
    }
    Ok(())
}

/// Declared variables → one [`ScalarVariable`] per value (arrays element by element).
fn expand(md: &mut ModelDescription, declared: Vec<Declared>) -> Result<(), DescriptionError> {
    unique_value_references(&declared)?;
    let structural_start: HashMap<u32, (String, Option<String>)> = declared
        .iter()
        .filter(|d| d.structural)
        .map(|d| {
            (
                d.var.value_reference,
                (d.var.name.clone(), d.var.start.clone()),
            )
        })
        .collect();
    let mut free = FreeValueReferences::new(declared.iter().map(|d| d.var.value_reference));
    // The total first, before a single element is made.
    check_total(&declared, &structural_start)?;
    for mut d in declared {
        // String and Binary starts are <Start value> children.
        if d.var.start.is_none() && !d.starts.is_empty() {
            d.var.start = Some(d.starts[0].clone());
        }
        if d.dims.is_empty() {
            push_scalar(md, d);
            continue;
        }
        push_array(md, d, &structural_start, &mut free)?;
    }
    Ok(())
}

/// All declared variables expand into at most [`MAX_TOTAL_ELEMENTS`] values (elements and
/// their aliases).
fn check_total(
    declared: &[Declared],
    structural_start: &HashMap<u32, (String, Option<String>)>,
) -> Result<(), DescriptionError> {
    let mut expanded = 0u64;
    for d in declared {
        let total = element_count(d, structural_start)?;
        expanded = expanded.saturating_add(total.saturating_mul(1 + d.aliases.len() as u64));
        if expanded > MAX_TOTAL_ELEMENTS {
            return Err(DescriptionError::TooManyValues {
                variable: d.var.name.clone(),
                limit: MAX_TOTAL_ELEMENTS,
            });
        }
    }
    Ok(())
}

/// A scalar: the variable with its [`Fmi3Slot`], then its aliases (the same variable under
/// other names).
fn push_scalar(md: &mut ModelDescription, mut d: Declared) {
    d.var.fmi3 = Some(Fmi3Slot {
        ty: d.ty,
        vr: d.var.value_reference,
        index: 0,
        len: 1,
        element: false,
        structural: d.structural,
    });
    let aliases: Vec<ScalarVariable> = d
        .aliases
        .iter()
        .map(|a| ScalarVariable {
            name: a.clone(),
            ..d.var.clone()
        })
        .collect();
    md.variables.push(d.var);
    md.variables.extend(aliases);
}

/// An array: one variable per element, `name[i]` or `name[i,j]` (1-based subscripts of
/// its row-major position), each with its start value (one for all, or one each) and an
/// internal value reference of its own, which the aliases' elements share.
fn push_array(
    md: &mut ModelDescription,
    d: Declared,
    structural_start: &HashMap<u32, (String, Option<String>)>,
    free: &mut FreeValueReferences,
) -> Result<(), DescriptionError> {
    let name = d.var.name.clone();
    let sizes = dimension_sizes(&d, structural_start)?;
    let total = element_count(&d, structural_start)?;
    let starts: Vec<String> = if !d.starts.is_empty() {
        d.starts.clone()
    } else {
        d.var
            .start
            .as_deref()
            .map(|s| s.split_whitespace().map(str::to_string).collect())
            .unwrap_or_default()
    };
    if !starts.is_empty() && starts.len() as u64 != total && starts.len() != 1 {
        return Err(DescriptionError::StartValues {
            variable: name,
            starts: starts.len(),
            elements: total,
        });
    }
    // The elements' internal value references, shared by the aliases' elements.
    let element_vrs = (0..total)
        .map(|_| free.next())
        .collect::<Option<Vec<u32>>>()
        .ok_or_else(|| DescriptionError::NoValueReferenceLeft {
            variable: name.clone(),
        })?;
    // An alias's elements share the original's value references.
    for base in std::iter::once(&name).chain(d.aliases.iter()) {
        for k in 0..total {
            // Row-major position → 1-based subscripts.
            let mut rest = k;
            let mut subs = vec![0u64; sizes.len()];
            for (j, &n) in sizes.iter().enumerate().rev() {
                subs[j] = rest % n + 1;
                rest /= n;
            }
            let subs: Vec<String> = subs.iter().map(u64::to_string).collect();
            let mut v = d.var.clone();
            v.name = format!("{base}[{}]", subs.join(","));
            v.start = match starts.len() {
                0 => None,
                1 => Some(starts[0].clone()),
                _ => Some(starts[k as usize].clone()),
            };
            v.value_reference = element_vrs[k as usize];
            v.fmi3 = Some(Fmi3Slot {
                ty: d.ty,
                vr: d.var.value_reference,
                index: k as u32,
                len: total as u32,
                element: true,
                structural: d.structural,
            });
            md.variables.push(v);
        }
    }
    Ok(())
}

/// The value references no declared variable uses, smallest first: the internal ones of
/// array elements. The declared ones may lie anywhere in `0..=u32::MAX`, and at most a
/// million values are expanded, so the range never runs dry in practice.
struct FreeValueReferences {
    /// The declared value references, sorted, and the first of them not yet passed.
    used: Vec<u32>,
    passed: usize,
    candidate: Option<u32>,
}

impl FreeValueReferences {
    fn new(used: impl Iterator<Item = u32>) -> Self {
        let mut used: Vec<u32> = used.collect();
        used.sort_unstable();
        used.dedup();
        FreeValueReferences {
            used,
            passed: 0,
            candidate: Some(0),
        }
    }

    fn next(&mut self) -> Option<u32> {
        loop {
            let c = self.candidate?;
            while self.passed < self.used.len() && self.used[self.passed] < c {
                self.passed += 1;
            }
            self.candidate = c.checked_add(1);
            if self.used.get(self.passed) != Some(&c) {
                return Some(c);
            }
        }
    }
}

/// The sizes of a declared array's dimensions (a structural parameter's by its start).
fn dimension_sizes(
    d: &Declared,
    structural_start: &HashMap<u32, (String, Option<String>)>,
) -> Result<Vec<u64>, DescriptionError> {
    let name = &d.var.name;
    let mut sizes = Vec::new();
    for dim in &d.dims {
        sizes.push(match dim {
            Dim::Fixed(n) => *n,
            Dim::Parameter(vr) => {
                let (pname, start) = structural_start.get(vr).ok_or_else(|| {
                    DescriptionError::DimensionNotStructural {
                        variable: name.clone(),
                        value_reference: *vr,
                    }
                })?;
                start
                    .as_deref()
                    .and_then(|s| s.trim().parse::<u64>().ok())
                    .ok_or_else(|| DescriptionError::DimensionNoStart {
                        variable: name.clone(),
                        parameter: pname.clone(),
                    })?
            }
        });
    }
    Ok(sizes)
}

/// How many elements a declared variable has (1 for a scalar), at most [`MAX_ELEMENTS`].
fn element_count(
    d: &Declared,
    structural_start: &HashMap<u32, (String, Option<String>)>,
) -> Result<u64, DescriptionError> {
    let sizes = dimension_sizes(d, structural_start)?;
    match sizes.iter().try_fold(1u64, |a, &n| a.checked_mul(n)) {
        Some(t) if t <= MAX_ELEMENTS => Ok(t),
        _ => Err(DescriptionError::ArrayTooLarge {
            variable: d.var.name.clone(),
            sizes,
            limit: MAX_ELEMENTS,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="{t}">
  <CoSimulation modelIdentifier="m" canGetAndSetFMUState="true"/>
  <UnitDefinitions><Unit name="rpm"><BaseUnit s="-1" rad="1" factor="0.10471975511965977"/></Unit></UnitDefinitions>
  <TypeDefinitions><Float64Type name="Speed" unit="rpm"/>
    <EnumerationType name="Mode"><Item name="a" value="1"/><Item name="b" value="2"/></EnumerationType></TypeDefinitions>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent"/>
    <UInt64 name="n" valueReference="1" causality="structuralParameter" variability="fixed" start="2"/>
    <Float64 name="y" valueReference="5" causality="output" declaredType="Speed"><Dimension valueReference="1"/><Dimension start="3"/></Float64>
    <Float32 name="u" valueReference="6" causality="input" start="1.5"/>
    <Int16 name="k" valueReference="7" causality="parameter" variability="fixed" start="-3"/>
    <Enumeration name="e" valueReference="8" causality="parameter" variability="fixed" declaredType="Mode" start="2"/>
    <String name="s" valueReference="9" causality="parameter" variability="fixed"><Start value="hi"/></String>
    <Binary name="b" valueReference="10" causality="output"/>
  </ModelVariables>
  <ModelStructure><Output valueReference="5" dependencies="6"/><Output valueReference="10"/><InitialUnknown valueReference="5"/></ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn arrays_become_elements_and_types_map_to_their_kinds() {
        let md = parse(XML).unwrap();
        assert_eq!(md.fmi_version, "3.0");
        assert_eq!(md.guid, "{t}");
        let names: Vec<&str> = md.variables.iter().map(|v| v.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "time", "n", "y[1,1]", "y[1,2]", "y[1,3]", "y[2,1]", "y[2,2]", "y[2,3]", "u", "k",
                "e", "s", "b"
            ]
        );
        let y23 = md.variable("y[2,3]").unwrap();
        assert_eq!(y23.fmi3.unwrap().vr, 5);
        assert_eq!(y23.fmi3.unwrap().index, 5);
        assert_eq!(y23.fmi3.unwrap().len, 6);
        assert_ne!(y23.value_reference, 5);
        assert_eq!(md.unit_of(y23), Some("rpm"));
        assert_eq!(md.variable("u").unwrap().ty, ScalarType::Real);
        assert_eq!(md.variable("k").unwrap().ty, ScalarType::Integer);
        assert_eq!(md.variable("k").unwrap().start.as_deref(), Some("-3"));
        assert_eq!(md.variable("s").unwrap().start.as_deref(), Some("hi"));
        assert_eq!(
            md.enumeration_items(md.variable("e").unwrap())
                .unwrap()
                .len(),
            2
        );
        assert!(md.variable("n").unwrap().fmi3.unwrap().structural);
        // Binary b is text (hexadecimal).
        assert_eq!(md.variable("b").unwrap().ty, ScalarType::String);
        // y's six elements are outputs depending on u (index 9), then b.
        assert_eq!(md.outputs.len(), 7);
        assert_eq!(md.outputs[0].dependencies, Some(vec![9]));
        assert!(md.unsupported.is_empty());
    }

    #[test]
    fn clocks_and_scheduled_execution_are_named() {
        let xml = XML
            .replace(
                "<CoSimulation modelIdentifier=\"m\" canGetAndSetFMUState=\"true\"/>",
                "<ScheduledExecution modelIdentifier=\"m\"/>",
            )
            .replace(
                "<Binary name=\"b\" valueReference=\"10\" causality=\"output\"/>",
                "<Clock name=\"tick\" valueReference=\"10\" causality=\"input\" intervalVariability=\"constant\"/>",
            );
        let md = parse(&xml).unwrap();
        assert!(md.co_simulation.is_none());
        assert_eq!(md.unsupported.len(), 2, "{:?}", md.unsupported);
        assert!(md.unsupported[0].contains("Scheduled Execution"));
        assert!(md.unsupported[1].contains("'tick' is a Clock"));
    }

    #[test]
    fn a_wrong_start_count_or_a_missing_dimension_is_named() {
        let xml = XML.replace(
            "<Float64 name=\"y\" valueReference=\"5\" causality=\"output\" declaredType=\"Speed\">",
            "<Float64 name=\"y\" valueReference=\"5\" causality=\"output\" start=\"1 2\">",
        );
        let e = parse(&xml).unwrap_err();
        assert!(
            matches!(&e, DescriptionError::StartValues { variable, starts: 2, elements: 6 } if variable == "y"),
            "{e}"
        );
        let xml = XML.replace(
            "<Dimension valueReference=\"1\"/>",
            "<Dimension valueReference=\"4\"/>",
        );
        let e = parse(&xml).unwrap_err();
        assert!(
            matches!(
                &e,
                DescriptionError::DimensionNotStructural {
                    value_reference: 4,
                    ..
                }
            ),
            "{e}"
        );
    }

    /// Red team N6: 1000 arrays of 100 000 elements each (an 11 KB file) made the reader
    /// allocate 6.7 GB.
    #[test]
    fn many_large_arrays_are_refused_by_their_total() {
        let mut vars = String::new();
        for k in 0..1000 {
            vars.push_str(&format!(
                "<Float64 name=\"a{k}\" valueReference=\"{}\" causality=\"output\"><Dimension start=\"100000\"/></Float64>\n",
                k + 1
            ));
        }
        let xml = format!(
            "<fmiModelDescription fmiVersion=\"3.0\" modelName=\"m\" instantiationToken=\"t\"><CoSimulation modelIdentifier=\"m\"/><ModelVariables>{vars}</ModelVariables><ModelStructure/></fmiModelDescription>"
        );
        let e = parse(&xml).unwrap_err();
        assert!(
            matches!(&e, DescriptionError::TooManyValues { variable, limit: 1_000_000 } if variable == "a10"),
            "{e}"
        );
    }

    /// Red team M16: the largest legal value reference made the FMU unloadable (elements
    /// were numbered past the largest declared one); elements showed made-up value
    /// references; a zero-size array was refused; a Dimension with both a size and a
    /// structural parameter was accepted.
    #[test]
    fn value_references_up_to_the_largest_zero_size_arrays_and_dimensions_of_one_kind() {
        let xml = XML.replace(
            "<Binary name=\"b\" valueReference=\"10\" causality=\"output\"/>",
            "<Binary name=\"b\" valueReference=\"10\" causality=\"output\"/>\n<Float64 name=\"h\" valueReference=\"4294967295\" causality=\"local\"/>\n<Float64 name=\"z\" valueReference=\"11\" causality=\"output\"><Dimension start=\"0\"/></Float64>",
        ).replace("<InitialUnknown valueReference=\"5\"/>", "<InitialUnknown valueReference=\"5\"/><Output valueReference=\"11\"/>");
        let md = parse(&xml).unwrap();
        assert_eq!(md.variable("h").unwrap().value_reference, u32::MAX);
        assert_eq!(
            md.variable("h").unwrap().declared_value_reference(),
            u32::MAX
        );
        assert_eq!(md.variable("h").unwrap().array_element(), None);
        // The elements' internal references are free values, distinct from every declared
        // one; what the FMU declares is the array's.
        let declared = [0u32, 1, 5, 6, 7, 8, 9, 10, u32::MAX];
        let mut internal = std::collections::HashSet::new();
        for k in 1..=6 {
            let (i, j) = ((k - 1) / 3 + 1, (k - 1) % 3 + 1);
            let v = md.variable(&format!("y[{i},{j}]")).unwrap();
            assert_eq!(v.declared_value_reference(), 5);
            assert_eq!(v.array_element(), Some(k));
            assert!(!declared.contains(&v.value_reference));
            assert!(internal.insert(v.value_reference));
        }
        // z has no element, no column and no output entry.
        assert!(md.variables.iter().all(|v| !v.name.starts_with('z')));
        assert_eq!(md.outputs.len(), 7);
        let xml = XML.replace(
            "<Dimension start=\"3\"/>",
            "<Dimension start=\"3\" valueReference=\"1\"/>",
        );
        let e = parse(&xml).unwrap_err();
        assert!(
            matches!(&e, DescriptionError::DimensionBoth { variable } if variable == "y"),
            "{e}"
        );
    }

    /// Red team N25: two FMI 3.0 inputs on one value reference were accepted.
    #[test]
    fn two_variables_on_one_value_reference_are_refused() {
        let xml = r#"<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="t">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables>
    <Float64 name="u1" valueReference="1" causality="input" start="0"/>
    <Float64 name="u2" valueReference="1" causality="input" start="0"/>
  </ModelVariables>
  <ModelStructure/>
</fmiModelDescription>"#;
        let e = parse(xml).unwrap_err();
        assert!(
            matches!(
                &e,
                DescriptionError::DuplicateValueReference { value_reference: 1, first, second }
                    if first == "u1" && second == "u2"
            ),
            "{e}"
        );
    }
}
