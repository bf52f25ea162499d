//! modelDescription.xml, documentation and GUID, generated from the variable table.

use crate::check::TableError;
use crate::model::Model;
use crate::variables::{format_real, Causality, VarInfo, VarTable};

/// Log categories declared in modelDescription.xml, in bit order.
pub const LOG_CATEGORIES: &[(&str, &str)] = &[
    (
        "logStatusError",
        "Errors: bad calls, bad values, model failures",
    ),
    ("logStatusWarning", "Warnings"),
    ("logEvents", "Information: initialisation, resets, states"),
    ("logAll", "All of the above"),
];

/// FNV-1a, 128 bit: a stable hash with no dependency (not for security, only identity).
fn fnv1a_128(data: &[u8]) -> u128 {
    let mut h: u128 = 0x6c62272e07bb014262b821756295c58d;
    for &b in data {
        h ^= b as u128;
        h = h.wrapping_mul(0x0000000001000000000000000000013B);
    }
    h
}

/// The canonical text of the interface: everything modelDescription.xml says of the model
/// and its variables. Any change of it changes the GUID.
pub fn canonical_interface<M: Model>() -> String {
    let i = M::INFO;
    let mut s = format!(
        // initial-deps: InitialUnknowns declare their dependencies (inputs and parameters).
        "fmi2.0|cs|initial-deps|{}|{}|{}|{}\n",
        i.name, i.identifier, i.version, i.description
    );
    for v in M::Vars::VARIABLES {
        s.push_str(&format!(
            "{}|{}|{}|{}|{}|{:?}|{:?}|{}|{:?}|{:?}|{}|{:?}|{:?}\n",
            v.name,
            v.value_reference,
            v.var_type().xml_name(),
            v.causality.xml_name(),
            v.variability.xml_name(),
            v.initial.map(|x| x.xml_name()),
            v.unit,
            v.start.xml_text(),
            v.min.map(format_real),
            v.max.map(format_real),
            v.description,
            v.depends_on,
            v.init_depends_on
        ));
        // Only where there is one: the GUIDs of models without Enumerations stay as they were.
        if let Some(t) = v.enumeration {
            s.push_str(&format!("enumeration|{t:?}\n"));
        }
    }
    s
}

/// GUID derived from the interface: stable across builds, changed by any interface change.
pub fn guid<M: Model>() -> String {
    guid_of(&canonical_interface::<M>())
}

/// A GUID-shaped FNV-1a-128 hash of `text`.
pub fn guid_of(text: &str) -> String {
    let h = fnv1a_128(text.as_bytes());
    let x = format!("{h:032x}");
    format!(
        "{{{}-{}-{}-{}-{}}}",
        &x[0..8],
        &x[8..12],
        &x[12..16],
        &x[16..20],
        &x[20..32]
    )
}

/// What `twinbench export-twin` changes in a model's description: the fitted twin's start
/// values, its own identity and its provenance. The default changes nothing: the packed
/// model's description.
#[derive(Clone, Debug, Default)]
pub struct Fitting {
    /// Start values by variable name, as the value's XML text (a Real's shortest text that
    /// reads back to the same f64: what the binary applies, see [`crate::fitted`]).
    pub starts: Vec<(String, String)>,
    /// The fitted FMU's own GUID (FMI 2.0) or instantiation token (FMI 3.0): its start
    /// values differ from the model's, so it is another FMU.
    pub token: Option<String>,
    /// The description's `description` attribute.
    pub description: Option<String>,
    /// Provenance: a well-formed XML fragment, the content of the `twinbench` tool
    /// annotation (FMI 2.0's `VendorAnnotations`, FMI 3.0's `Annotations`).
    pub annotation: Option<String>,
}

impl Fitting {
    /// The start value's XML text of `v`: the fitted one, else the table's.
    pub fn start_text(&self, v: &VarInfo) -> Option<String> {
        match self.starts.iter().find(|(n, _)| n == v.name) {
            Some((_, text)) => Some(text.clone()),
            None => v.has_start().then(|| v.start.xml_text()),
        }
    }
}

/// Consistency of a variable table, by the rules of [`crate::check`]: the first broken rule
/// of each variable, all of them in one message. A table made by `variables!` passed them at
/// compile time already; the packer still refuses any table that fails them (a
/// [`VarTable`] written by hand).
pub fn validate_table<V: VarTable>() -> Result<(), InvalidTable> {
    let t = V::VARIABLES;
    let errors: Vec<TableError> = (0..t.len())
        .filter_map(|i| crate::check::check_variable(t, i).err())
        .collect();
    if errors.is_empty() {
        Ok(())
    } else {
        Err(InvalidTable { errors })
    }
}

/// The broken rules of a variable table ([`validate_table`]): the first of each variable,
/// in the table's order.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}", errors.iter().map(TableError::to_string).collect::<Vec<_>>().join("; "))]
pub struct InvalidTable {
    pub errors: Vec<TableError>,
}

/// Escape text for an XML attribute or element.
pub use tb_files::markup::xml_escape;

/// A variable's element opened with the attributes both versions write, in their order:
/// `    <{element} name=".." valueReference=".." description=".." causality=".."
/// variability=".."` and `initial` where the table says it.
pub(crate) fn open_variable(element: &str, v: &VarInfo) -> String {
    let mut s = format!(
        "    <{element} name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{}\" variability=\"{}\"",
        xml_escape(v.name),
        v.value_reference,
        xml_escape(v.description),
        v.causality.xml_name(),
        v.variability.xml_name()
    );
    if let Some(init) = v.initial {
        s.push_str(&format!(" initial=\"{}\"", init.xml_name()));
    }
    s
}

fn scalar_variable(v: &VarInfo, fitting: &Fitting) -> String {
    let mut s = open_variable("ScalarVariable", v);
    s.push_str(">\n      <");
    s.push_str(v.var_type().xml_name());
    if let Some(t) = v.enumeration {
        s.push_str(&format!(" declaredType=\"{}\"", xml_escape(t.name)));
    }
    s.push_str(&unit_and_range(v));
    if let Some(start) = fitting.start_text(v) {
        s.push_str(&format!(" start=\"{}\"", xml_escape(&start)));
    }
    s.push_str("/>\n    </ScalarVariable>\n");
    s
}

/// Each Enumeration type of `table` once, in the order of first use.
pub fn enumeration_types(table: &[VarInfo]) -> Vec<&'static crate::variables::EnumerationType> {
    let mut types: Vec<&'static crate::variables::EnumerationType> = Vec::new();
    for t in table.iter().filter_map(|v| v.enumeration) {
        if !types.iter().any(|k| k.name == t.name) {
            types.push(t);
        }
    }
    types
}

/// ` unit="…" min="…" max="…"`: the attributes both versions write alike.
pub fn unit_and_range(v: &VarInfo) -> String {
    let mut s = String::new();
    if let Some(u) = v.unit {
        s.push_str(&format!(" unit=\"{}\"", xml_escape(u)));
    }
    if let Some(m) = v.min {
        s.push_str(&format!(" min=\"{}\"", format_real(m)));
    }
    if let Some(m) = v.max {
        s.push_str(&format!(" max=\"{}\"", format_real(m)));
    }
    s
}

/// What an initial unknown depends on in initialization mode (1-based indices): the inputs
/// it feeds through (`depends_on`) and every parameter (what initialisation computes from;
/// listing a parameter it does not use is allowed, leaving one out would not be). Without
/// the attribute a host must assume every input, which turns a bench of FMUs into one
/// algebraic loop at initialisation.
pub fn initial_dependencies(table: &[VarInfo], v: &VarInfo) -> Vec<usize> {
    let mut deps: Vec<usize> = table
        .iter()
        .enumerate()
        .filter(|(_, k)| {
            v.depends_on.contains(&k.value_reference)
                || v.init_depends_on.contains(&k.value_reference)
                || k.causality == Causality::Parameter
        })
        .map(|(j, _)| j + 1)
        .collect();
    deps.sort_unstable();
    deps
}

/// `<UnitDefinitions>`' units: each unit the variables of `table` use, once (FMI 2.0 and
/// 3.0 write them alike).
pub fn unit_definitions(table: &[VarInfo]) -> String {
    let mut unit_defs = String::new();
    for u in crate::variables::used_units(table) {
        unit_defs.push_str(&format!(
            "    <Unit name=\"{}\">\n      <BaseUnit{}/>\n    </Unit>\n",
            xml_escape(u.name),
            u.base_unit_attributes()
        ));
    }
    unit_defs
}

/// The FMI version a description is written for, where FMI 2.0 and 3.0 write the same
/// definitions differently.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Version {
    Fmi2,
    Fmi3,
}

/// `<TypeDefinitions>` with each Enumeration type once, or nothing when there is none: FMI
/// 2.0's `<SimpleType><Enumeration>`, FMI 3.0's `<EnumerationType>`.
pub fn type_definitions(table: &[VarInfo], version: Version) -> String {
    let types = enumeration_types(table);
    if types.is_empty() {
        return String::new();
    }
    let (element, inner, item_indent) = match version {
        Version::Fmi2 => ("SimpleType", Some("Enumeration"), "        "),
        Version::Fmi3 => ("EnumerationType", None, "      "),
    };
    let mut type_defs = String::from("  <TypeDefinitions>\n");
    for t in types {
        type_defs.push_str(&format!(
            "    <{element} name=\"{}\" description=\"{}\">\n",
            xml_escape(t.name),
            xml_escape(t.description)
        ));
        if let Some(inner) = inner {
            type_defs.push_str(&format!("      <{inner}>\n"));
        }
        for i in t.items {
            type_defs.push_str(&format!(
                "{item_indent}<Item name=\"{}\" value=\"{}\" description=\"{}\"/>\n",
                xml_escape(i.name),
                i.value,
                xml_escape(i.description)
            ));
        }
        if let Some(inner) = inner {
            type_defs.push_str(&format!("      </{inner}>\n"));
        }
        type_defs.push_str(&format!("    </{element}>\n"));
    }
    type_defs.push_str("  </TypeDefinitions>\n");
    type_defs
}

/// `<LogCategories>`' entries (the same in FMI 2.0 and 3.0).
pub fn log_categories() -> String {
    let mut categories = String::new();
    for (name, desc) in LOG_CATEGORIES {
        categories.push_str(&format!(
            "    <Category name=\"{name}\" description=\"{}\"/>\n",
            xml_escape(desc)
        ));
    }
    categories
}

/// `<ModelStructure>`: the outputs with their dependencies and the initial unknowns.
fn model_structure(table: &[VarInfo]) -> String {
    let index_of_vr = |vr: u32| table.iter().position(|v| v.value_reference == vr).unwrap() + 1;
    let mut outputs = String::new();
    let mut initial_unknowns = String::new();
    for (i, v) in table.iter().enumerate() {
        if v.causality == Causality::Output {
            let deps: Vec<String> = v
                .depends_on
                .iter()
                .map(|d| index_of_vr(*d).to_string())
                .collect();
            outputs.push_str(&format!(
                "      <Unknown index=\"{}\" dependencies=\"{}\"/>\n",
                i + 1,
                deps.join(" ")
            ));
        }
        let initial_unknown = (v.causality == Causality::Output
            && matches!(
                v.effective_initial(),
                Some(crate::variables::Initial::Approx)
                    | Some(crate::variables::Initial::Calculated)
            ))
            || v.causality == Causality::CalculatedParameter;
        if initial_unknown {
            initial_unknowns.push_str(&format!(
                "      <Unknown index=\"{}\" dependencies=\"{}\"/>\n",
                i + 1,
                initial_dependencies(table, v)
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(" ")
            ));
        }
    }
    let mut structure = String::new();
    if !outputs.is_empty() {
        structure.push_str(&format!("    <Outputs>\n{outputs}    </Outputs>\n"));
    }
    if !initial_unknowns.is_empty() {
        structure.push_str(&format!(
            "    <InitialUnknowns>\n{initial_unknowns}    </InitialUnknowns>\n"
        ));
    }
    structure
}

/// Fill the modelDescription.xml template (fmu-templates/modelDescription.xml).
pub fn render_model_description<M: Model>(template: &str, generation_tool: &str) -> String {
    render_fitted_description::<M>(template, generation_tool, &Fitting::default())
}

/// [`render_model_description`] of a fitted twin: its start values, GUID, description and
/// provenance annotation from `fitting`.
pub fn render_fitted_description<M: Model>(
    template: &str,
    generation_tool: &str,
    fitting: &Fitting,
) -> String {
    let info = M::INFO;
    let table = M::Vars::VARIABLES;

    let unit_defs = unit_definitions(table);
    let type_defs = type_definitions(table, Version::Fmi2);
    let categories = log_categories();
    let variables: String = table.iter().map(|v| scalar_variable(v, fitting)).collect();

    let structure = model_structure(table);
    let de = info.default_experiment;
    let default_experiment = format!(
        "<DefaultExperiment startTime=\"{}\" stopTime=\"{}\" stepSize=\"{}\"/>",
        format_real(de.start_time),
        format_real(de.stop_time),
        format_real(de.step_size)
    );

    let annotations = match &fitting.annotation {
        Some(a) => format!(
            "  <VendorAnnotations>\n    <Tool name=\"twinbench\">\n{a}    </Tool>\n  </VendorAnnotations>\n"
        ),
        None => String::new(),
    };
    template
        .replace("{{modelName}}", &xml_escape(info.name))
        .replace("{{modelIdentifier}}", &xml_escape(info.identifier))
        .replace("{{guid}}", &fitting.token.clone().unwrap_or_else(guid::<M>))
        .replace(
            "{{description}}",
            &xml_escape(fitting.description.as_deref().unwrap_or(info.description)),
        )
        .replace("{{version}}", &xml_escape(info.version))
        .replace("{{generationTool}}", &xml_escape(generation_tool))
        .replace("{{numberOfVariables}}", &table.len().to_string())
        .replace("{{unitDefinitions}}\n", &unit_defs)
        .replace("{{typeDefinitions}}\n", &type_defs)
        .replace("{{logCategories}}\n", &categories)
        .replace(
            "{{defaultExperiment}}\n",
            &format!("{default_experiment}\n{annotations}"),
        )
        .replace("{{modelVariables}}\n", &variables)
        .replace("{{modelStructure}}\n", &structure)
}

/// Fill the documentation template (fmu-templates/documentation/index.html).
pub fn render_documentation<M: Model>(template: &str) -> String {
    let info = M::INFO;
    let mut rows = String::new();
    for v in M::Vars::VARIABLES {
        let start = if v.has_start() {
            match v.start {
                crate::variables::Value::Str(t) => format!("\"{}\"", xml_escape(t)),
                other => other.xml_text(),
            }
        } else {
            String::new()
        };
        rows.push_str(&format!(
            "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>\n",
            xml_escape(v.name),
            v.value_reference,
            v.causality.xml_name(),
            v.variability.xml_name(),
            v.var_type().xml_name(),
            xml_escape(v.unit.unwrap_or("")),
            start,
            match (v.min, v.max) {
                (None, None) => String::new(),
                (a, b) => format!(
                    "[{}, {}]",
                    a.map_or("−∞".into(), format_real),
                    b.map_or("∞".into(), format_real)
                ),
            },
            match v.enumeration {
                None => xml_escape(v.description),
                Some(t) => format!(
                    "{} Items: {}.",
                    xml_escape(v.description),
                    t.items
                        .iter()
                        .map(|i| format!(
                            "{} <code>{}</code> ({})",
                            i.value,
                            xml_escape(i.name),
                            xml_escape(i.description)
                        ))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        ));
    }
    let de = info.default_experiment;
    template
        .replace("{{modelName}}", &xml_escape(info.name))
        .replace("{{description}}", &xml_escape(info.description))
        .replace("{{version}}", &xml_escape(info.version))
        .replace("{{guid}}", &guid::<M>())
        .replace(
            "{{defaultExperiment}}",
            &format!(
                "start {} s, stop {} s, step {} s",
                format_real(de.start_time),
                format_real(de.stop_time),
                format_real(de.step_size)
            ),
        )
        .replace("{{variableRows}}", &rows)
        .replace("{{modelDocumentation}}", info.documentation)
}
