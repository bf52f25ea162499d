//! The model description: what twinbench knows of an FMU (FMI 2.0 and 3.0 alike), and the
//! FMI 2.0 reader of modelDescription.xml (FMI 3.0: [`super::description3`]; what both
//! share: [`super::reader`]). Tolerant as the standard asks: unknown attributes and elements
//! (vendor annotations, tool extensions) are ignored.

use super::reader::{num, walk, Attrs, Shared, Version, Visit};
pub use crate::schema::{Causality, Initial, ScalarType, Variability};
use crate::units::UnitDef;
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
    pub fmi3: Option<super::description3::Fmi3Slot>,
}

/// What identifies a variable's value in the FMU's C interface: its value space (base type)
/// and its value reference. Two variables with one key are aliases.
pub type VarKey = (ScalarType, u32);

impl ScalarVariable {
    /// Its [`VarKey`]: (value space, value reference).
    pub fn key(&self) -> VarKey {
        (self.ty.value_space(), self.value_reference)
    }

    /// Whether this variable is the one behind `key` (a variable of another base type on
    /// the same value reference is not).
    pub fn has_key(&self, key: VarKey) -> bool {
        self.value_reference == key.1 && self.ty.value_space() == key.0
    }

    /// The value reference the FMU declares: an FMI 3.0 array element's is its array's
    /// (`value_reference` is then an internal one, unique per element).
    pub fn declared_value_reference(&self) -> u32 {
        self.fmi3.map_or(self.value_reference, |s| s.vr)
    }

    /// An FMI 3.0 array element's 1-based position in its array (row-major).
    pub fn array_element(&self) -> Option<u32> {
        self.fmi3.filter(|s| s.element).map(|s| s.index + 1)
    }

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
    /// FMI 3.0 `fixedInternalStepSize` [s]: the step the FMU takes inside (a host's hint
    /// for the communication step; FMPy's default output interval).
    pub fixed_internal_step_size: Option<f64>,
}

/// `<ModelExchange>`: the interface twinbench integrates itself (FMI 2.0 §3), with CVODE
/// between communication points ([`crate::import::model_exchange`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelExchange {
    pub model_identifier: String,
    pub needs_execution_tool: bool,
    /// `completedIntegratorStepNotNeeded` (FMI 2.0; default false: the FMU must be told of
    /// every completed integrator step with `fmi2CompletedIntegratorStep`).
    pub completed_integrator_step_not_needed: bool,
    pub can_be_instantiated_only_once_per_process: bool,
    pub can_get_and_set_fmu_state: bool,
    pub provides_directional_derivative: bool,
}

/// The FMI interface an instance runs through: Co-Simulation (the FMU steps itself) or
/// Model Exchange (twinbench integrates the FMU's equations). Names as in system files.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Interface {
    CoSimulation,
    ModelExchange,
}

impl Interface {
    pub const ALL: [Interface; 2] = [Interface::CoSimulation, Interface::ModelExchange];

    /// The name in system files (`interface = "model-exchange"`).
    pub const fn name(self) -> &'static str {
        match self {
            Interface::CoSimulation => "co-simulation",
            Interface::ModelExchange => "model-exchange",
        }
    }

    /// The element of modelDescription.xml that declares it.
    pub const fn element(self) -> &'static str {
        match self {
            Interface::CoSimulation => "CoSimulation",
            Interface::ModelExchange => "ModelExchange",
        }
    }

    /// The interface of a name; the error lists the names there are.
    pub fn from_name(name: &str) -> Result<Interface, String> {
        Interface::ALL
            .into_iter()
            .find(|i| i.name() == name)
            .ok_or_else(|| {
                format!(
                    "unknown interface \"{name}\" ({})",
                    Interface::ALL.map(Interface::name).join(", ")
                )
            })
    }
}

impl std::fmt::Display for Interface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
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
    pub model_exchange: Option<ModelExchange>,
    /// `numberOfEventIndicators` (FMI 2.0; 0 when absent).
    pub number_of_event_indicators: usize,
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
    /// `ModelStructure/Derivatives` (FMI 2.0): one per continuous state, in the order of
    /// the state vector (FMI 2.0 §2.2.8).
    pub derivatives: Vec<Unknown>,
    pub initial_unknowns: Vec<Unknown>,
    /// FMI 3.0: what the description has that twinbench cannot run (clocks, Scheduled
    /// Execution), each named; the archive check refuses the FMU with them.
    pub unsupported: Vec<String>,
    /// `variable(name)`'s index, built on its first use (a scan per name was quadratic for
    /// 100k FMI 3.0 aliases, M11).
    pub by_name: NameIndex,
}

/// The variables' positions by name, built once (for the variables there were then: a
/// description whose variables changed since falls back to a scan).
#[derive(Default)]
pub struct NameIndex(std::sync::OnceLock<(usize, HashMap<String, usize>)>);

impl Clone for NameIndex {
    fn clone(&self) -> Self {
        NameIndex::default()
    }
}

impl PartialEq for NameIndex {
    /// A cache: never what makes two descriptions differ.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl std::fmt::Debug for NameIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("NameIndex")
    }
}

impl ModelDescription {
    /// Whether the FMU declares `interface`.
    pub fn supports(&self, interface: Interface) -> bool {
        match interface {
            Interface::CoSimulation => self.co_simulation.is_some(),
            Interface::ModelExchange => self.model_exchange.is_some(),
        }
    }

    /// The interface an instance uses unless its system file chooses: Co-Simulation when
    /// the FMU has it, else Model Exchange (None: neither).
    pub fn default_interface(&self) -> Option<Interface> {
        Interface::ALL.into_iter().find(|i| self.supports(*i))
    }

    /// The `modelIdentifier` of `interface` (the library's name), if the FMU declares it.
    pub fn model_identifier(&self, interface: Interface) -> Option<&str> {
        match interface {
            Interface::CoSimulation => self.co_simulation.as_ref().map(|c| &c.model_identifier),
            Interface::ModelExchange => self.model_exchange.as_ref().map(|m| &m.model_identifier),
        }
        .map(String::as_str)
    }

    /// The number of continuous states (FMI 2.0: the `<Derivatives>` listed).
    pub fn number_of_continuous_states(&self) -> usize {
        self.derivatives.len()
    }

    pub fn variable(&self, name: &str) -> Option<&ScalarVariable> {
        let (built_for, index) = self.by_name.0.get_or_init(|| {
            let mut index = HashMap::with_capacity(self.variables.len());
            for (i, v) in self.variables.iter().enumerate() {
                index.entry(v.name.clone()).or_insert(i);
            }
            (self.variables.len(), index)
        });
        if *built_for == self.variables.len() {
            return index
                .get(name)
                .and_then(|&i| self.variables.get(i))
                .filter(|v| v.name == name);
        }
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
        // The listed indices as sets: a scan of a list per variable was quadratic (100k
        // FMI 3.0 aliases, each an output, took 4.5 s: M11).
        let index_set = |list: &[Unknown]| -> std::collections::HashSet<usize> {
            list.iter().map(|u| u.index).collect()
        };
        let (outputs_listed, initial_listed) =
            (index_set(&self.outputs), index_set(&self.initial_unknowns));
        let listed = |list: &std::collections::HashSet<usize>, i: usize| list.contains(&(i + 1));
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
        let outputs =
            names(&|i, v| v.causality == Causality::Output && !listed(&outputs_listed, i));
        let initial = names(&|i, v| computed_at_init(v) && !listed(&initial_listed, i));
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

// The names closest to a wrong one, for "did you mean" messages: tb-files' (shared with
// crates that do not import FMUs).
pub use tb_files::names::{closest, edit_distance};

fn unknown(m: &Attrs) -> Result<Unknown, String> {
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
    if super::reader::sniff_fmi_version(xml).is_some_and(|v| v.starts_with("3.")) {
        return super::description3::parse(xml);
    }
    let mut r = Reader2::default();
    walk(xml, &mut r)?;
    r.finish()
}

/// The FMI 2.0 reader: the shared elements, then `<ScalarVariable>`s and the model
/// structure.
#[derive(Default)]
struct Reader2 {
    md: ModelDescription,
    shared: Shared,
    current: Option<ScalarVariable>,
}

impl Visit for Reader2 {
    fn start(
        &mut self,
        stack: &[String],
        name: &str,
        m: &Attrs,
        empty: bool,
    ) -> Result<(), String> {
        let parent = stack.last().map(String::as_str).unwrap_or("");
        if self
            .shared
            .start(&mut self.md, Version::V2, parent, name, m, empty)?
        {
            return Ok(());
        }
        match (parent, name) {
            ("ModelVariables", "ScalarVariable") => {
                let v = scalar_variable(m)?;
                if empty {
                    return Err(format!("variable '{}' has no type element", v.name));
                }
                self.current = Some(v);
            }
            ("ScalarVariable", t @ ("Real" | "Integer" | "Boolean" | "String" | "Enumeration")) => {
                if let Some(v) = self.current.as_mut() {
                    let ctx = format!("variable '{}'", v.name);
                    v.ty = ScalarType::parse(t).expect("matched above");
                    v.declared_type = m.get("declaredType").cloned();
                    v.unit = m.get("unit").cloned();
                    v.start = m.get("start").cloned();
                    v.min = num(m, "min", &ctx)?;
                    v.max = num(m, "max", &ctx)?;
                    v.nominal = num(m, "nominal", &ctx)?;
                }
            }
            ("Outputs", "Unknown") => self.md.outputs.push(unknown(m)?),
            ("Derivatives", "Unknown") => self.md.derivatives.push(unknown(m)?),
            ("InitialUnknowns", "Unknown") => self.md.initial_unknowns.push(unknown(m)?),
            _ => {}
        }
        Ok(())
    }

    fn end(&mut self, _stack: &[String], name: &str) {
        if name == "ScalarVariable" {
            self.md.variables.extend(self.current.take());
        }
        self.shared.end(&mut self.md, Version::V2, name);
    }
}

impl Reader2 {
    /// The description, checked: unique names, aliases as the standard allows them, model
    /// structure indices in range.
    fn finish(mut self) -> Result<ModelDescription, String> {
        self.shared.finish(&mut self.md)?;
        let md = self.md;
        check_names_and_aliases(&md)?;
        for v in &md.variables {
            check_combination(v)?;
        }
        let n = md.variables.len();
        for u in md
            .outputs
            .iter()
            .chain(&md.derivatives)
            .chain(&md.initial_unknowns)
        {
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
}

/// A `<ScalarVariable>`'s own attributes (its type comes with its child element).
fn scalar_variable(m: &Attrs) -> Result<ScalarVariable, String> {
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
    Ok(ScalarVariable {
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
    })
}

/// Variable names are unique, and aliases are what FMI 2.0 allows (section 2.2.7,
/// `valueReference`): variables of one base type (Integer and Enumeration count as one) that
/// share a value reference are an alias set, one value under several names; variables of
/// different base types on one value reference are unrelated. In an alias set at most one
/// variable can be set (an input or a parameter: a set writes every name of the set), and the
/// start values must not contradict each other (one value has one start). An input or a
/// parameter whose aliases are locals or outputs (as OpenModelica exports them) is allowed.
/// FMI 3.0 declares aliases explicitly (`<Alias>`), each the same variable by design.
pub(crate) fn check_names_and_aliases(md: &ModelDescription) -> Result<(), String> {
    let mut by_name: HashMap<&str, u32> = HashMap::new();
    let mut sets: HashMap<VarKey, Vec<&ScalarVariable>> = HashMap::new();
    for v in &md.variables {
        if let Some(vr) = by_name.insert(&v.name, v.value_reference) {
            return Err(format!(
                "variable name '{}' appears twice (value references {vr} and {})",
                v.name, v.value_reference
            ));
        }
        sets.entry(v.key()).or_default().push(v);
    }
    if md.fmi_version.starts_with("3.") {
        return Ok(());
    }
    let mut sets: Vec<(VarKey, Vec<&ScalarVariable>)> =
        sets.into_iter().filter(|(_, s)| s.len() > 1).collect();
    sets.sort_by_key(|(k, _)| (k.1, k.0));
    for ((ty, vr), set) in sets {
        let settable: Vec<&&ScalarVariable> = set
            .iter()
            .filter(|x| matches!(x.causality, Causality::Input | Causality::Parameter))
            .collect();
        if settable.len() > 1 {
            return Err(format!(
                "value reference {vr} of {ty} is shared by {} '{}' ({}) and '{}' ({}): an alias set can have at most one variable that is set (FMI 2.0, section 2.2.7)",
                if settable.len() > 2 { "more than" } else { "both" },
                settable[0].name,
                settable[0].causality,
                settable[1].name,
                settable[1].causality
            ));
        }
        let starts: Vec<&&ScalarVariable> = set.iter().filter(|x| x.start.is_some()).collect();
        if let Some(b) = starts
            .iter()
            .skip(1)
            .find(|b| !same_start(starts[0], b, ty))
        {
            let a = starts[0];
            return Err(format!(
                "value reference {vr} of {ty} is shared by '{}' (start {}) and '{}' (start {}): one value cannot have two start values (FMI 2.0, section 2.2.7)",
                a.name,
                a.start.as_deref().unwrap_or_default(),
                b.name,
                b.start.as_deref().unwrap_or_default()
            ));
        }
    }
    Ok(())
}

/// The combinations of causality and variability FMI 2.0 allows (section 2.2.7, the table
/// after the definition of `variability`): a parameter is fixed or tunable, an input or an
/// output is not (a `constant` output is), only a local or an output is constant, and the
/// independent variable is continuous. FMPy refuses the same combinations.
fn check_combination(v: &ScalarVariable) -> Result<(), String> {
    use Causality as C;
    use Variability as V;
    let allowed = match v.variability {
        V::Constant => matches!(v.causality, C::Output | C::Local),
        V::Fixed | V::Tunable => {
            matches!(
                v.causality,
                C::Parameter | C::CalculatedParameter | C::Local
            )
        }
        V::Discrete => matches!(v.causality, C::Input | C::Output | C::Local),
        V::Continuous => matches!(
            v.causality,
            C::Input | C::Output | C::Local | C::Independent
        ),
    };
    if allowed {
        return Ok(());
    }
    Err(format!(
        "variable '{}': causality=\"{}\" with variability=\"{}\" is not allowed (FMI 2.0, section 2.2.7: {})",
        v.name,
        v.causality,
        v.variability,
        match v.causality {
            C::Parameter | C::CalculatedParameter => "a parameter is fixed or tunable",
            C::Input => "an input is discrete or continuous",
            C::Output => "an output is constant, discrete or continuous",
            C::Independent => "the independent variable is continuous",
            C::Local => "",
        }
    ))
}

/// Two start values of one alias set say the same (as numbers where they are numbers:
/// "1" and "1.0", "true" and "1").
fn same_start(a: &ScalarVariable, b: &ScalarVariable, ty: ScalarType) -> bool {
    if ty == ScalarType::String {
        return a.start == b.start;
    }
    match (a.start_f64(), b.start_f64()) {
        (Some(x), Some(y)) => x == y,
        _ => a.start == b.start,
    }
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
        // M17: a count that is not one is refused, naming it (it was taken as 0).
        let bad = XML.replace(
            "numberOfEventIndicators=\"0\"",
            "numberOfEventIndicators=\"-5\"",
        );
        assert!(parse(&bad)
            .unwrap_err()
            .contains("numberOfEventIndicators=\"-5\">: expected a whole number >= 0"));
    }

    #[test]
    fn a_truncated_description_is_refused_not_read_as_a_shorter_model() {
        // Cut after the first variable: without the check, a model of one variable.
        let cut = &XML[..XML.find("</ScalarVariable>").unwrap() + "</ScalarVariable>".len()];
        let e = parse(cut).unwrap_err();
        assert!(
            e.contains("the file ends before <ModelVariables> is closed (truncated?)"),
            "{e}"
        );
        // FMI 3.0 alike.
        let v3 = r#"<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="t">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables>
    <Float64 name="x" valueReference="1" causality="output"/>"#;
        let e = parse(v3).unwrap_err();
        assert!(
            e.contains("the file ends before <ModelVariables> is closed"),
            "{e}"
        );
        assert!(parse(&format!("{v3}</ModelVariables><ModelStructure><Output valueReference=\"1\"/></ModelStructure></fmiModelDescription>")).is_ok());
    }

    #[test]
    fn alias_sets_follow_the_standard() {
        let two = XML.replace("name=\"p\"", "name=\"n\"");
        assert!(parse(&two)
            .unwrap_err()
            .contains("variable name 'n' appears twice (value references 3 and 4)"));
        let with = |extra: &str| {
            XML.replace(
                "<ScalarVariable name=\"p\"",
                &format!("{extra}\n    <ScalarVariable name=\"p\""),
            )
        };
        // An input whose alias is an output, a parameter with a local alias (OpenModelica's
        // `_D_outputAlias_*`): one value under two names, allowed.
        let md = parse(&with(
            r#"<ScalarVariable name="u" valueReference="3" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="_D_p" valueReference="4" causality="local" variability="fixed"><Integer/></ScalarVariable>"#,
        ))
        .unwrap();
        assert_eq!(md.variables.len(), 4);
        // Two variables that can be set in one set: refused, naming both and the clause.
        let e = parse(&with(
            r#"<ScalarVariable name="q" valueReference="4" causality="parameter" variability="fixed"><Integer start="2"/></ScalarVariable>"#,
        ))
        .unwrap_err();
        assert!(
            e.contains("value reference 4 of Integer is shared by both 'q' (parameter) and 'p' (parameter): an alias set can have at most one variable that is set (FMI 2.0, section 2.2.7)"),
            "{e}"
        );
        // An Enumeration is in the Integers' space: an alias of an Integer.
        let e = parse(&with(
            r#"<ScalarVariable name="e" valueReference="4" causality="input"><Enumeration declaredType="E" start="2"/></ScalarVariable>"#,
        ))
        .unwrap_err();
        assert!(e.contains("'e' (input) and 'p' (parameter)"), "{e}");
        // Start values that contradict each other: refused; the same value twice: one start.
        let e = parse(&with(
            r#"<ScalarVariable name="p_copy" valueReference="4" causality="local" variability="fixed" initial="exact"><Integer start="3"/></ScalarVariable>"#,
        ))
        .unwrap_err();
        assert!(
            e.contains(
                "'p_copy' (start 3) and 'p' (start 2): one value cannot have two start values"
            ),
            "{e}"
        );
        assert!(parse(&with(
            r#"<ScalarVariable name="p_copy" valueReference="4" causality="local" variability="fixed" initial="exact"><Integer start="2"/></ScalarVariable>"#,
        ))
        .is_ok());
        // Another base type on the same value reference: another variable, however set.
        let md = parse(&with(
            r#"<ScalarVariable name="on" valueReference="4" causality="input"><Boolean start="true"/></ScalarVariable>
    <ScalarVariable name="k" valueReference="3" causality="input"><Integer start="7"/></ScalarVariable>"#,
        ))
        .unwrap();
        let key = |n: &str| md.variables.iter().find(|v| v.name == n).unwrap().key();
        assert_ne!(key("on"), key("p"));
        assert_ne!(key("k"), key("n"));
        assert_eq!(key("k"), (ScalarType::Integer, 3));
    }

    #[test]
    fn combinations_of_causality_and_variability_the_standard_forbids_are_refused() {
        let e = parse(&XML.replace(
            "causality=\"parameter\" variability=\"fixed\"",
            "causality=\"parameter\" variability=\"constant\"",
        ))
        .unwrap_err();
        assert!(
            e.contains("variable 'p': causality=\"parameter\" with variability=\"constant\" is not allowed (FMI 2.0, section 2.2.7: a parameter is fixed or tunable)"),
            "{e}"
        );
        let e = parse(&XML.replace(
            "causality=\"output\" myAttr",
            "causality=\"output\" variability=\"tunable\" myAttr",
        ))
        .unwrap_err();
        assert!(
            e.contains("an output is constant, discrete or continuous"),
            "{e}"
        );
        assert!(parse(&XML.replace(
            "causality=\"output\" myAttr",
            "causality=\"output\" variability=\"constant\" myAttr"
        ))
        .is_ok());
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
