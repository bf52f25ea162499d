//! The model description: what twinbench knows of an FMU, FMI 2.0 and 3.0 alike (its
//! variables with their FMI 3.0 types, interfaces, units and types, default experiment and
//! model structure), and the checks of names and aliases both version readers run on it.
//! Read from modelDescription.xml by [`super::description`]; everything after loading
//! (plan, units, recording) uses these types alone.

use super::error::DescriptionError;
use crate::schema::{Causality, Initial, ScalarType, Variability};
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
    pub fmi3: Option<Fmi3Slot>,
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

/// An FMI 3.0 variable type (the element name in `ModelVariables`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fmi3Type {
    Float32,
    Float64,
    Int8,
    UInt8,
    Int16,
    UInt16,
    Int32,
    UInt32,
    Int64,
    UInt64,
    Boolean,
    String,
    Binary,
    Enumeration,
}

impl Fmi3Type {
    pub(crate) fn parse(name: &str) -> Option<Fmi3Type> {
        use Fmi3Type::*;
        Some(match name {
            "Float32" => Float32,
            "Float64" => Float64,
            "Int8" => Int8,
            "UInt8" => UInt8,
            "Int16" => Int16,
            "UInt16" => UInt16,
            "Int32" => Int32,
            "UInt32" => UInt32,
            "Int64" => Int64,
            "UInt64" => UInt64,
            "Boolean" => Boolean,
            "String" => String,
            "Binary" => Binary,
            "Enumeration" => Enumeration,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        use Fmi3Type::*;
        match self {
            Float32 => "Float32",
            Float64 => "Float64",
            Int8 => "Int8",
            UInt8 => "UInt8",
            Int16 => "Int16",
            UInt16 => "UInt16",
            Int32 => "Int32",
            UInt32 => "UInt32",
            Int64 => "Int64",
            UInt64 => "UInt64",
            Boolean => "Boolean",
            String => "String",
            Binary => "Binary",
            Enumeration => "Enumeration",
        }
    }

    /// The FMI 2.0 kind twinbench exchanges it as. Integers wider than 32 bits (UInt32,
    /// Int64, UInt64) travel as Real (an f64: exact up to 2^53, and a value it cannot carry
    /// exactly is an error naming the variable, never rounded in silence).
    pub fn kind(self) -> ScalarType {
        use Fmi3Type::*;
        match self {
            Float32 | Float64 | UInt32 | Int64 | UInt64 => ScalarType::Real,
            Boolean => ScalarType::Boolean,
            String | Binary => ScalarType::String,
            Enumeration => ScalarType::Enumeration,
            _ => ScalarType::Integer,
        }
    }
}

/// Where an FMI 3.0 value lives: its type, the FMU's value reference, and for an array
/// element its position in the array (row-major) and the array's element count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fmi3Slot {
    pub ty: Fmi3Type,
    pub vr: u32,
    pub index: u32,
    pub len: u32,
    /// An array's element (a one-element array's too), not a scalar.
    pub element: bool,
    /// A structural parameter: it sizes arrays, so twinbench never changes it.
    pub structural: bool,
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
    /// FMI 3.0 `fixedInternalStepSize` (s): the step the FMU takes inside (a host's hint
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
    pub fn from_name(name: &str) -> Result<Interface, UnknownInterface> {
        Interface::ALL
            .into_iter()
            .find(|i| i.name() == name)
            .ok_or_else(|| UnknownInterface {
                name: name.to_string(),
            })
    }
}

/// A name that is no interface's ([`Interface::from_name`]); the message lists the names.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown interface \"{name}\" ({})",
    Interface::ALL.map(Interface::name).join(", ")
)]
pub struct UnknownInterface {
    pub name: String,
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

    /// The variables of one causality (the inputs, the outputs), in declaration order.
    pub fn variables_of(&self, causality: Causality) -> impl Iterator<Item = &ScalarVariable> {
        self.variables
            .iter()
            .filter(move |v| v.causality == causality)
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

/// Variable names are unique, and aliases are what FMI 2.0 allows (section 2.2.7,
/// `valueReference`): variables of one base type (Integer and Enumeration count as one) that
/// share a value reference are an alias set, one value under several names; variables of
/// different base types on one value reference are unrelated. In an alias set at most one
/// variable can be set (an input or a parameter: a set writes every name of the set), and the
/// start values must not contradict each other (one value has one start). An input or a
/// parameter whose aliases are locals or outputs (as OpenModelica exports them) is allowed.
/// FMI 3.0 declares aliases explicitly (`<Alias>`), each the same variable by design.
pub(crate) fn check_names_and_aliases(md: &ModelDescription) -> Result<(), DescriptionError> {
    let mut by_name: HashMap<&str, u32> = HashMap::new();
    let mut sets: HashMap<VarKey, Vec<&ScalarVariable>> = HashMap::new();
    for v in &md.variables {
        if let Some(vr) = by_name.insert(&v.name, v.value_reference) {
            return Err(DescriptionError::DuplicateName {
                name: v.name.clone(),
                first: vr,
                second: v.value_reference,
            });
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
            return Err(DescriptionError::AliasSet {
                value_reference: vr,
                ty,
                more: settable.len() > 2,
                first: settable[0].name.clone(),
                first_causality: settable[0].causality,
                second: settable[1].name.clone(),
                second_causality: settable[1].causality,
            });
        }
        let starts: Vec<&&ScalarVariable> = set.iter().filter(|x| x.start.is_some()).collect();
        if let Some(b) = starts
            .iter()
            .skip(1)
            .find(|b| !same_start(starts[0], b, ty))
        {
            let a = starts[0];
            return Err(DescriptionError::AliasStarts {
                value_reference: vr,
                ty,
                first: a.name.clone(),
                first_start: a.start.clone().unwrap_or_default(),
                second: b.name.clone(),
                second_start: b.start.clone().unwrap_or_default(),
            });
        }
    }
    Ok(())
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
