//! Parameter bindings, inline or in an `.ssv` file, onto the components' variables.

use super::error::SspImportError;
use super::importer::*;
use super::xml::*;
use std::collections::BTreeMap;

/// One `ParameterBinding`: its values into `parameters` (`instance.variable`).
pub(super) fn bind(
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
    let inner = imp.children(f, b, &["ParameterValues"], &[]).map_err(|e| {
        e.explained(
            |element| element == "ParameterMapping",
            |_| "parameter mappings are not supported: name the FMU's variables in the parameter set (prefix may prepend a common part)".into(),
        )
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
pub(super) struct Target<'a> {
    pub(super) components: &'a [Component],
    pub(super) component: Option<usize>,
    pub(super) prefix: &'a str,
}

/// The values of one `<ssv:ParameterSet>` (in `file`) into `parameters`.
pub(super) fn bind_set(
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
pub(super) fn parameter_target(
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
pub(super) fn parameter_value(
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
