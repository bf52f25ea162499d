//! Connections between components, with their unit conversion and linear transformation.

use super::error::SspImportError;
use super::importer::*;
use super::xml::*;
use crate::config::ConnectionConfig;
use tb_fmi::ScalarType;

/// One `Connection` between two components.
pub(super) fn connection(
    imp: &Importer<'_>,
    components: &[Component],
    c: &Node,
) -> Result<ConnectionConfig, SspImportError> {
    let f = SSD;
    let transforms = imp
        .children(f, c, &["LinearTransformation"], &["ConnectionGeometry"])
        .map_err(|e| {
            e.explained(
                |element| element.ends_with("MappingTransformation"),
                |_| "mapping transformations (Boolean, Integer, Enumeration) are not supported; a connection may have an <ssc:LinearTransformation>".into(),
            )
        })?;
    let (fk, fv) = connection_end(imp, components, c, "startElement", "startConnector")?;
    let (tk, tv) = connection_end(imp, components, c, "endElement", "endConnector")?;
    let (from, to) = (&components[fk], &components[tk]);
    let text = format!("{}.{fv} -> {}.{tv}", from.name, to.name);
    let suppress = match c.attr("suppressUnitConversion") {
        None => false,
        Some(s) => parse_bool(s).ok_or_else(|| {
            imp.invalid(
                f,
                c.line,
                format!("suppressUnitConversion=\"{s}\" is not a boolean"),
            )
        })?,
    };
    let lt = match transforms.first() {
        Some(t) => Some((
            imp.f64_attr(f, t, "factor")?.unwrap_or(1.0),
            imp.f64_attr(f, t, "offset")?.unwrap_or(0.0),
        )),
        None => None,
    };
    let tsv = to.md.variable(&tv).expect("checked with the connectors");
    let plain = ConnectionConfig::from(text.as_str());
    if tsv.ty != ScalarType::Real {
        if lt.is_some() {
            return Err(imp.invalid(
                f,
                c.line,
                format!(
                    "connection \"{text}\": a LinearTransformation applies to Real connectors, '{}.{tv}' is {}",
                    to.name,
                    tsv.ty.name()
                ),
            ));
        }
        return Ok(plain);
    }
    let ends = ((from, fv.as_str()), (to, tv.as_str()));
    let Some((scale, offset)) = connection_gain(imp, ends, suppress, lt)
        .map_err(|m| imp.invalid(f, c.line, format!("connection \"{text}\": {m}")))?
    else {
        return Ok(plain);
    };
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(imp.invalid(
            f,
            c.line,
            format!("connection \"{text}\": factor {scale} and offset {offset} must be finite, the factor non-zero"),
        ));
    }
    Ok(ConnectionConfig {
        text,
        scale: Some(scale),
        offset: Some(offset),
        from_unit: None,
        to_unit: None,
    })
}

/// One end of a connection: a component and one of its declared connectors.
pub(super) fn connection_end(
    imp: &Importer<'_>,
    components: &[Component],
    c: &Node,
    el: &str,
    con: &str,
) -> Result<(usize, String), SspImportError> {
    let f = SSD;
    let Some(e) = c.attr(el) else {
        return Err(imp.unsupported(
            f,
            c,
            &format!(
                "a connection without {el} uses the system's own connectors, which are not supported: connect components directly"
            ),
        ));
    };
    let k = components.iter().position(|x| x.name == e).ok_or_else(|| {
        imp.invalid(
            f,
            c.line,
            format!(
                "{el}=\"{e}\" is not a component (components: {})",
                component_names(components)
            ),
        )
    })?;
    let name = c.attr(con).unwrap_or_default().to_string();
    if !components[k].connectors.contains_key(&name) {
        return Err(imp.invalid(
            f,
            c.line,
            format!(
                "{con}=\"{name}\" is not a connector of component '{e}' (declared: {})",
                components[k]
                    .connectors
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ));
    }
    Ok((k, name))
}

/// The gain of a Real connection as `(scale, offset)`, or None where the plan's own unit
/// conversion of the FMUs' units is exactly what the SSD says: with the unit conversion
/// suppressed, the `LinearTransformation` alone (or none); else the connectors' units
/// converted, then the transformation applied.
pub(super) fn connection_gain(
    imp: &Importer<'_>,
    ((from, fv), (to, tv)): ((&Component, &str), (&Component, &str)),
    suppress: bool,
    lt: Option<(f64, f64)>,
) -> Result<Option<(f64, f64)>, crate::plan::ConversionError> {
    let fsv = from.md.variable(fv).expect("checked with the connectors");
    let tsv = to.md.variable(tv).expect("checked with the connectors");
    let fmu_units = (from.md.unit_of(fsv), to.md.unit_of(tsv));
    let con_units = (
        from.connectors[fv].0.as_deref().or(fmu_units.0),
        to.connectors[tv].0.as_deref().or(fmu_units.1),
    );
    if suppress {
        return Ok(match lt {
            None if fmu_units.0 == fmu_units.1
                || fmu_units.0.is_none()
                || fmu_units.1.is_none() =>
            {
                None
            }
            None => Some((1.0, 0.0)),
            Some(t) => Some(t),
        });
    }
    if lt.is_none() && con_units == fmu_units {
        // The plan converts the FMUs' own units, exactly as the SSD says.
        return Ok(None);
    }
    let conv = crate::plan::units::unit_conversion(
        (&imp.unit_md(&from.md), con_units.0),
        (&imp.unit_md(&to.md), con_units.1),
    )?;
    Ok(Some(match lt {
        None => (conv.scale, conv.offset),
        Some((factor, off)) => (factor * conv.scale, factor * conv.offset + off),
    }))
}
