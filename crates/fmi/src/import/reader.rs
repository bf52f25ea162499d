//! What the FMI 2.0 and FMI 3.0 modelDescription.xml readers share: the version found
//! before either reads ([`sniff_fmi_version`]), the walk over the XML (with the check that
//! the document is complete), the attribute helpers, and the elements both versions have
//! (the root, `<CoSimulation>`, `<DefaultExperiment>`, unit definitions with display units,
//! type definitions and their enumeration items, log categories). Each version's reader
//! adds its variables and model structure.

use super::error::DescriptionError;
use super::model::{CoSimulation, DefaultExperiment, ModelDescription, ModelExchange};
use crate::units::UnitDef;
use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use std::collections::HashMap;

/// An element's attributes by name.
pub(crate) type Attrs = HashMap<String, String>;

/// An element as it opens: its parent's name ("" for the root), its own, its attributes,
/// and whether it is empty (`<a/>`: no end follows).
#[derive(Clone, Copy)]
pub(crate) struct Element<'a> {
    pub parent: &'a str,
    pub name: &'a str,
    pub attrs: &'a Attrs,
    pub empty: bool,
}

/// The FMI version of the document being read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Version {
    V2,
    V3,
}

/// A version's reader of the elements as the walk meets them, after [`Shared`] has read the
/// ones both versions have.
pub(crate) trait Visit {
    /// The version this reader reads.
    const VERSION: Version;
    /// The description being read and the reader of the shared elements.
    fn shared(&mut self) -> (&mut ModelDescription, &mut Shared);
    /// An element that is not a shared one opens: `stack` holds its ancestors (the root
    /// first).
    fn start(&mut self, stack: &[String], e: Element) -> Result<(), DescriptionError>;
    /// An element (with children) closes: `stack` holds its ancestors. The shared reader
    /// sees it after this one.
    fn end(&mut self, stack: &[String], name: &str);
}

/// Reads `xml` with a new `V` and `finish`es it (the parse of either version).
pub(crate) fn read<V: Visit + Default>(
    xml: &str,
    finish: impl FnOnce(V) -> Result<ModelDescription, DescriptionError>,
) -> Result<ModelDescription, DescriptionError> {
    let mut v = V::default();
    walk(xml, &mut v)?;
    finish(v)
}

/// Walks `xml`, telling `v` every element; refuses a document that ends before its root
/// closes (a truncated file must not pass for a shorter model).
pub(crate) fn walk<V: Visit>(xml: &str, v: &mut V) -> Result<(), DescriptionError> {
    let mut reader = Reader::from_str(xml);
    let mut stack: Vec<String> = Vec::new();
    loop {
        let ev = reader
            .read_event()
            .map_err(|source| DescriptionError::Xml {
                position: reader.buffer_position(),
                source,
            })?;
        let (e, empty) = match &ev {
            Event::Start(e) => (e, false),
            Event::Empty(e) => (e, true),
            Event::End(_) => {
                let name = stack.pop().unwrap_or_default();
                v.end(&stack, &name);
                let (md, shared) = v.shared();
                shared.end(md, V::VERSION, &name);
                continue;
            }
            Event::Eof => break,
            _ => continue,
        };
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let m = attrs(e)?;
        let e = Element {
            parent: stack.last().map(String::as_str).unwrap_or(""),
            name: &name,
            attrs: &m,
            empty,
        };
        let (md, shared) = v.shared();
        if !shared.start(md, V::VERSION, e)? {
            v.start(&stack, e)?;
        }
        if !empty {
            stack.push(name);
        }
    }
    if let Some(open) = stack.last() {
        return Err(DescriptionError::Truncated {
            open: open.clone(),
            depth: stack.len(),
        });
    }
    Ok(())
}

/// The `fmiVersion` attribute's value, found without parsing the XML.
pub(crate) fn sniff_fmi_version(xml: &str) -> Option<&str> {
    let i = xml.find("fmiVersion")?;
    let rest = xml[i + "fmiVersion".len()..].trim_start();
    let rest = rest.strip_prefix('=')?.trim_start();
    let q = rest.chars().next().filter(|c| *c == '"' || *c == '\'')?;
    let rest = &rest[1..];
    Some(&rest[..rest.find(q)?])
}

/// The elements both versions share, read into the description as they come.
#[derive(Default)]
pub(crate) struct Shared {
    current_unit: Option<(String, UnitDef)>,
    /// Display units become units of their own (after the FMU's own, which win a name).
    display_units: Vec<(String, UnitDef)>,
    current_type: Option<String>,
    saw_root: bool,
}

impl Shared {
    /// Reads the element if it is one of the shared ones (true), else leaves it to the
    /// version's reader (false).
    pub fn start(
        &mut self,
        md: &mut ModelDescription,
        version: Version,
        e: Element,
    ) -> Result<bool, DescriptionError> {
        match (e.parent, e.name) {
            ("", "fmiModelDescription") => {
                self.saw_root = true;
                let token = match version {
                    Version::V2 => "guid",
                    Version::V3 => "instantiationToken",
                };
                root_attributes(md, e.attrs, token)?;
            }
            ("", other) => {
                return Err(DescriptionError::Root {
                    found: other.to_string(),
                })
            }
            ("fmiModelDescription", "CoSimulation") => {
                md.co_simulation = Some(co_simulation(e.attrs, version)?)
            }
            ("fmiModelDescription", "ModelExchange") => {
                md.model_exchange = Some(model_exchange(e.attrs, version)?)
            }
            ("fmiModelDescription", "DefaultExperiment") => {
                md.default_experiment = Some(default_experiment(e.attrs)?)
            }
            ("UnitDefinitions", "Unit") => {
                let uname =
                    e.attrs
                        .get("name")
                        .cloned()
                        .ok_or_else(|| DescriptionError::Unnamed {
                            element: "Unit".into(),
                        })?;
                self.current_unit = Some((uname, UnitDef::DIMENSIONLESS));
                if e.empty {
                    md.units.extend(self.current_unit.take());
                }
            }
            ("Unit", "DisplayUnit") => {
                if let Some(u) = &self.current_unit {
                    self.display_units.extend(display_unit(e.attrs, u)?);
                }
            }
            ("Unit", "BaseUnit") => {
                if let Some((_, u)) = self.current_unit.as_mut() {
                    base_unit(e.attrs, u)?;
                }
            }
            ("LogCategories", "Category") => md.log_categories.extend(e.attrs.get("name").cloned()),
            _ => return self.type_definition(md, version, e),
        }
        Ok(true)
    }

    /// Type definitions: a Real type's unit, an Enumeration type's items (FMI 2.0
    /// `<SimpleType name><Real unit/>`, FMI 3.0 `<Float64Type name unit/>`,
    /// `<EnumerationType name><Item/>`).
    fn type_definition(
        &mut self,
        md: &mut ModelDescription,
        version: Version,
        e: Element,
    ) -> Result<bool, DescriptionError> {
        match (version, e.parent, e.name) {
            (Version::V2, "TypeDefinitions", "SimpleType") => {
                self.current_type = e.attrs.get("name").cloned()
            }
            (Version::V2, "SimpleType", "Real") => {
                if let (Some(t), Some(u)) = (&self.current_type, e.attrs.get("unit")) {
                    md.type_units.insert(t.clone(), u.clone());
                }
            }
            (Version::V3, "TypeDefinitions", t) if t.ends_with("Type") => {
                self.current_type = e.attrs.get("name").cloned();
                if let (Some(tn), Some(u)) = (&self.current_type, e.attrs.get("unit")) {
                    md.type_units.insert(tn.clone(), u.clone());
                }
                if e.empty {
                    self.current_type = None;
                }
            }
            (Version::V2, "Enumeration", "Item") | (Version::V3, "EnumerationType", "Item") => {
                if let Some(t) = &self.current_type {
                    let item = enumeration_item(e.attrs, t)?;
                    md.enumerations.entry(t.clone()).or_default().push(item);
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// An element closes.
    pub fn end(&mut self, md: &mut ModelDescription, version: Version, name: &str) {
        match (version, name) {
            (_, "Unit") => md.units.extend(self.current_unit.take()),
            (Version::V2, "SimpleType") => self.current_type = None,
            (Version::V3, n) if n.ends_with("Type") => self.current_type = None,
            _ => {}
        }
    }

    /// The document is read: it had its root; the display units join the units.
    pub fn finish(self, md: &mut ModelDescription) -> Result<(), DescriptionError> {
        if !self.saw_root {
            return Err(DescriptionError::NoRoot);
        }
        for d in self.display_units {
            if md.unit_def(&d.0).is_none() {
                md.units.push(d);
            }
        }
        Ok(())
    }
}

/// `<CoSimulation>`'s capabilities (FMI 3.0 spells two flags `FMUState` and has no input
/// interpolation flag).
fn co_simulation(m: &Attrs, version: Version) -> Result<CoSimulation, DescriptionError> {
    let (state, serialize, derivatives) = match version {
        Version::V2 => (
            "canGetAndSetFMUstate",
            "canSerializeFMUstate",
            "providesDirectionalDerivative",
        ),
        Version::V3 => (
            "canGetAndSetFMUState",
            "canSerializeFMUState",
            "providesDirectionalDerivatives",
        ),
    };
    Ok(CoSimulation {
        model_identifier: m.get("modelIdentifier").cloned().ok_or(
            DescriptionError::NoModelIdentifier {
                element: "CoSimulation",
            },
        )?,
        needs_execution_tool: flag(m, "needsExecutionTool"),
        can_handle_variable_communication_step_size: flag(
            m,
            "canHandleVariableCommunicationStepSize",
        ),
        can_be_instantiated_only_once_per_process: flag(m, "canBeInstantiatedOnlyOncePerProcess"),
        can_get_and_set_fmu_state: flag(m, state),
        can_serialize_fmu_state: flag(m, serialize),
        can_interpolate_inputs: version == Version::V2 && flag(m, "canInterpolateInputs"),
        provides_directional_derivative: flag(m, derivatives),
        // Only a positive number is a step; anything else is no hint at all.
        fixed_internal_step_size: match version {
            Version::V2 => None,
            Version::V3 => m
                .get("fixedInternalStepSize")
                .and_then(|v| v.trim().parse::<f64>().ok())
                .filter(|h| h.is_finite() && *h > 0.0),
        },
    })
}

/// `<ModelExchange>`'s attributes (FMI 3.0 spells the directional derivatives in the
/// plural, and has no `completedIntegratorStepNotNeeded`: its `needsCompletedIntegratorStep`
/// says the opposite, default false).
fn model_exchange(m: &Attrs, version: Version) -> Result<ModelExchange, DescriptionError> {
    let (derivatives, not_needed) = match version {
        Version::V2 => (
            "providesDirectionalDerivative",
            flag(m, "completedIntegratorStepNotNeeded"),
        ),
        Version::V3 => (
            "providesDirectionalDerivatives",
            !flag(m, "needsCompletedIntegratorStep"),
        ),
    };
    Ok(ModelExchange {
        model_identifier: m.get("modelIdentifier").cloned().ok_or(
            DescriptionError::NoModelIdentifier {
                element: "ModelExchange",
            },
        )?,
        needs_execution_tool: flag(m, "needsExecutionTool"),
        completed_integrator_step_not_needed: not_needed,
        can_be_instantiated_only_once_per_process: flag(m, "canBeInstantiatedOnlyOncePerProcess"),
        can_get_and_set_fmu_state: flag(
            m,
            match version {
                Version::V2 => "canGetAndSetFMUstate",
                Version::V3 => "canGetAndSetFMUState",
            },
        ),
        provides_directional_derivative: flag(m, derivatives),
    })
}

pub(crate) fn attrs(e: &BytesStart) -> Result<Attrs, DescriptionError> {
    let mut m = HashMap::new();
    for a in e.attributes() {
        let a = a.map_err(DescriptionError::Attribute)?;
        let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
        let val = a
            .unescape_value()
            .map_err(|source| DescriptionError::AttributeValue {
                attribute: key.clone(),
                source,
            })?;
        m.insert(key, val.into_owned());
    }
    Ok(m)
}

pub(crate) fn num(
    m: &HashMap<String, String>,
    key: &str,
    ctx: &str,
) -> Result<Option<f64>, DescriptionError> {
    match m.get(key) {
        None => Ok(None),
        Some(s) => s
            .trim()
            .parse()
            .map(Some)
            .map_err(|_| DescriptionError::NotANumber {
                context: ctx.to_string(),
                attribute: key.to_string(),
                found: s.clone(),
            }),
    }
}

/// `<BaseUnit>` (the same in FMI 2.0 and 3.0) into `u`.
pub(crate) fn base_unit(
    m: &HashMap<String, String>,
    u: &mut UnitDef,
) -> Result<(), DescriptionError> {
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
pub(crate) fn default_experiment(
    m: &HashMap<String, String>,
) -> Result<DefaultExperiment, DescriptionError> {
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
) -> Result<(String, i64), DescriptionError> {
    let item = m.get("name").cloned().unwrap_or_default();
    let value = m
        .get("value")
        .and_then(|v| v.trim().parse::<i64>().ok())
        .ok_or_else(|| DescriptionError::EnumerationItem {
            ty: ty.to_string(),
            item: item.clone(),
        })?;
    Ok((item, value))
}

/// A `<DisplayUnit name factor offset>` of `unit` as a unit definition of its own:
/// display = factor·value + offset, so SI = base.factor·(display − offset)/factor +
/// base.offset. An FMI 3.0 `inverse` display unit is not linear and is left out.
pub(crate) fn display_unit(
    m: &HashMap<String, String>,
    unit: &(String, UnitDef),
) -> Result<Option<(String, UnitDef)>, DescriptionError> {
    let Some(name) = m.get("name") else {
        return Err(DescriptionError::UnnamedDisplayUnit {
            unit: unit.0.clone(),
        });
    };
    if flag(m, "inverse") {
        return Ok(None);
    }
    let ctx = format!("unit '{}': DisplayUnit '{name}'", unit.0);
    let factor = num(m, "factor", &ctx)?.unwrap_or(1.0);
    let offset = num(m, "offset", &ctx)?.unwrap_or(0.0);
    if factor == 0.0 || !factor.is_finite() || !offset.is_finite() {
        return Err(DescriptionError::DisplayUnit {
            unit: unit.0.clone(),
            name: name.clone(),
            factor,
            offset,
        });
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
pub(crate) fn root_attributes(
    md: &mut ModelDescription,
    m: &HashMap<String, String>,
    token: &str,
) -> Result<(), DescriptionError> {
    let get = |key: &str| m.get(key).cloned().unwrap_or_default();
    md.fmi_version = get("fmiVersion");
    md.model_name = get("modelName");
    md.guid = get(token);
    md.description = get("description");
    md.generation_tool = get("generationTool");
    // A count that is not one (M17: "-5" was taken as 0) is refused, naming it.
    md.number_of_event_indicators = match m.get("numberOfEventIndicators") {
        None => 0,
        Some(s) => s
            .trim()
            .parse()
            .map_err(|_| DescriptionError::EventIndicators {
                found: tb_files::shown(s, 40, true),
            })?,
    };
    Ok(())
}

pub(crate) fn int_attr(m: &HashMap<String, String>, key: &str) -> i32 {
    m.get(key).and_then(|s| s.trim().parse().ok()).unwrap_or(0)
}

pub(crate) fn flag(m: &HashMap<String, String>, key: &str) -> bool {
    m.get(key).is_some_and(|s| s == "true" || s == "1")
}
