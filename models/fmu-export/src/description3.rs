//! The FMI 3.0 modelDescription.xml and instantiation token, generated from the same
//! variable table as the FMI 2.0 one ([`crate::description`]): one model, two FMUs.
//!
//! How the table maps: Real → `Float64`, Integer → `Int32`, Boolean → `Boolean`, String →
//! `String` (its start as a `<Start value>` child), an Enumeration → `Enumeration` of its
//! `<EnumerationType>` (got and set as `Int64`). FMI 3.0 wants one independent variable:
//! `time`, on the value reference after the table's largest ([`time_value_reference`]).
//! The model structure lists each output and initial unknown by value reference, with the
//! same dependencies as FMI 2.0's indices.

use crate::description::{
    initial_dependencies, log_categories, open_variable, type_definitions, xml_escape, Fitting,
    Version,
};
use crate::model::Model;
use crate::variables::{format_real, Causality, Initial, ScalarType, Value, VarInfo, VarTable};

/// The value reference of the independent variable `time`: one past the table's largest.
pub fn time_value_reference<V: VarTable>() -> u32 {
    V::VARIABLES
        .iter()
        .map(|v| v.value_reference)
        .max()
        .unwrap_or(0)
        + 1
}

/// The instantiation token: the FMI 2.0 GUID's hash over the interface, marked as FMI 3.0
/// (the two descriptions of one model are two interfaces).
pub fn instantiation_token<M: Model>() -> String {
    crate::description::guid_of(&format!(
        "fmi3.0|{}",
        crate::description::canonical_interface::<M>()
    ))
}

/// The FMI 3.0 element of a variable's type.
fn element(v: &VarInfo) -> &'static str {
    element_name(v.var_type())
}

/// The FMI 3.0 element (and get/set type) of a table type.
pub fn element_name(t: ScalarType) -> &'static str {
    match t {
        ScalarType::Real => "Float64",
        ScalarType::Integer => "Int32",
        ScalarType::Boolean => "Boolean",
        ScalarType::String => "String",
        ScalarType::Enumeration => "Enumeration",
    }
}

fn variable(v: &VarInfo, fitting: &Fitting) -> String {
    let el = element(v);
    let mut s = open_variable(el, v);
    if let Some(t) = v.enumeration {
        s.push_str(&format!(" declaredType=\"{}\"", xml_escape(t.name)));
    }
    s.push_str(&crate::description::unit_and_range(v));
    match (fitting.start_text(v), v.start) {
        (Some(text), Value::Str(_)) => {
            s.push_str(&format!(
                ">\n      <Start value=\"{}\"/>\n    </{el}>\n",
                xml_escape(&text)
            ));
            return s;
        }
        (Some(text), _) => s.push_str(&format!(" start=\"{}\"", xml_escape(&text))),
        (None, _) => {}
    }
    s.push_str("/>\n");
    s
}

/// The units (each once), the Enumeration types and the log categories.
fn push_definitions(s: &mut String, table: &[VarInfo]) {
    // Units, each once.
    let units = crate::description::unit_definitions(table);
    if !units.is_empty() {
        s.push_str("  <UnitDefinitions>\n");
        s.push_str(&units);
        s.push_str("  </UnitDefinitions>\n");
    }
    s.push_str(&type_definitions(table, Version::Fmi3));
    s.push_str("  <LogCategories>\n");
    s.push_str(&log_categories());
    s.push_str("  </LogCategories>\n");
}

/// `<ModelStructure>`: the outputs and the initial unknowns with their dependencies, by
/// value reference.
fn push_model_structure(s: &mut String, table: &[VarInfo]) {
    s.push_str("  <ModelStructure>\n");
    let vrs = |deps: &mut dyn Iterator<Item = u32>| {
        deps.map(|d| d.to_string()).collect::<Vec<_>>().join(" ")
    };
    for v in table.iter().filter(|v| v.causality == Causality::Output) {
        s.push_str(&format!(
            "    <Output valueReference=\"{}\" dependencies=\"{}\"/>\n",
            v.value_reference,
            vrs(&mut v.depends_on.iter().copied())
        ));
    }
    for v in table {
        let initial_unknown = (v.causality == Causality::Output
            && matches!(
                v.effective_initial(),
                Some(Initial::Approx) | Some(Initial::Calculated)
            ))
            || v.causality == Causality::CalculatedParameter;
        if initial_unknown {
            let deps = initial_dependencies(table, v);
            s.push_str(&format!(
                "    <InitialUnknown valueReference=\"{}\" dependencies=\"{}\"/>\n",
                v.value_reference,
                vrs(&mut deps.iter().map(|&i| table[i - 1].value_reference))
            ));
        }
    }
    s.push_str("  </ModelStructure>\n");
}

/// The FMI 3.0 modelDescription.xml of `M`.
pub fn render_model_description3<M: Model>(generation_tool: &str) -> String {
    render_fitted_description3::<M>(generation_tool, &Fitting::default())
}

/// [`render_model_description3`] of a fitted twin (see [`Fitting`]).
pub fn render_fitted_description3<M: Model>(generation_tool: &str, fitting: &Fitting) -> String {
    let info = M::INFO;
    let table = M::Vars::VARIABLES;
    let mut s = String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    s.push_str(&format!(
        "<fmiModelDescription\n  fmiVersion=\"3.0\"\n  modelName=\"{}\"\n  instantiationToken=\"{}\"\n  description=\"{}\"\n  version=\"{}\"\n  generationTool=\"{}\"\n  variableNamingConvention=\"flat\">\n",
        xml_escape(info.name),
        fitting
            .token
            .clone()
            .unwrap_or_else(instantiation_token::<M>),
        xml_escape(fitting.description.as_deref().unwrap_or(info.description)),
        xml_escape(info.version),
        xml_escape(generation_tool)
    ));
    s.push_str(&format!(
        "  <CoSimulation\n    modelIdentifier=\"{}\"\n    needsExecutionTool=\"false\"\n    canBeInstantiatedOnlyOncePerProcess=\"false\"\n    canGetAndSetFMUState=\"true\"\n    canSerializeFMUState=\"true\"\n    providesDirectionalDerivatives=\"false\"\n    providesAdjointDerivatives=\"false\"\n    providesPerElementDependencies=\"false\"\n    canHandleVariableCommunicationStepSize=\"true\"\n    maxOutputDerivativeOrder=\"0\"\n    providesIntermediateUpdate=\"false\"\n    mightReturnEarlyFromDoStep=\"false\"\n    canReturnEarlyAfterIntermediateUpdate=\"false\"\n    hasEventMode=\"false\"\n    providesEvaluateDiscreteStates=\"false\"/>\n",
        xml_escape(info.identifier)
    ));
    push_definitions(&mut s, table);
    let de = info.default_experiment;
    s.push_str(&format!(
        "  <DefaultExperiment startTime=\"{}\" stopTime=\"{}\" stepSize=\"{}\"/>\n",
        format_real(de.start_time),
        format_real(de.stop_time),
        format_real(de.step_size)
    ));
    s.push_str("  <ModelVariables>\n");
    s.push_str(&format!(
        "    <Float64 name=\"time\" valueReference=\"{}\" description=\"Simulation time\" causality=\"independent\" variability=\"continuous\" unit=\"s\"/>\n",
        time_value_reference::<M::Vars>()
    ));
    for v in table {
        s.push_str(&variable(v, fitting));
    }
    s.push_str("  </ModelVariables>\n");
    push_model_structure(&mut s, table);
    if let Some(a) = &fitting.annotation {
        s.push_str(&format!(
            "  <Annotations>\n    <Annotation type=\"twinbench\">\n{a}    </Annotation>\n  </Annotations>\n"
        ));
    }
    s.push_str("</fmiModelDescription>\n");
    s
}
