//! Stage "connections": every `from -> to` checked (causality, types, units, converted
//! where compatible), a replayed column's values checked against the input it drives, and
//! the inputs left unconnected.

use super::instances::Units;
use super::problems::ConversionError;
use super::units::{self, unit_conversion, Conversion};
use super::{ConnectionDef, Endpoint, InstanceDef, SignalTable};
use crate::config::{ConnectionConfig, Interpolation, SystemFile};
use crate::{invalid, split_name, SystemError};
use tb_fmi::import::description::{ModelDescription, ScalarVariable};
use tb_fmi::{Causality, ScalarType, Variability};

/// The checked connections (each source given its exchange slot), and the notes on unit
/// conventions bridged or overridden.
pub(super) fn connections(
    file: &SystemFile,
    units: Units<'_>,
    signals: &mut SignalTable,
    ctx_file: &str,
) -> Result<(Vec<ConnectionDef>, Vec<String>), SystemError> {
    let mut connections: Vec<ConnectionDef> = Vec::new();
    let mut notes = Vec::new();
    for conn in file.connections.iter().flat_map(|c| element_wise(c, units)) {
        let ctx = format!("{ctx_file}: connection \"{}\"", conn.text);
        let c = connection(&conn, units, signals, &ctx, &mut notes)?;
        if connections
            .iter()
            .any(|d| d.to_unit == c.to_unit && d.to_key() == c.to_key())
        {
            return Err(invalid(
                &ctx,
                format!("'{}' is already connected", c.to_name),
            ));
        }
        connections.push(c);
    }
    Ok((connections, notes))
}

/// FMI 3.0: a connection between two arrays of one size is one per element, in order
/// (`a.y -> b.u` gives `a.y[1] -> b.u[1]`, …); anything else is itself (and the check of
/// its names says what is wrong).
fn element_wise(conn: &ConnectionConfig, units: Units<'_>) -> Vec<ConnectionConfig> {
    let one = || vec![conn.clone()];
    let Some((a, b)) = conn.text.split_once("->") else {
        return one();
    };
    let (from, to) = (
        units.array_elements(a.trim()),
        units.array_elements(b.trim()),
    );
    if from.is_empty() || from.len() != to.len() {
        return one();
    }
    from.iter()
        .zip(&to)
        .map(|(f, t)| ConnectionConfig {
            text: format!("{f} -> {t}"),
            ..conn.clone()
        })
        .collect()
}

/// One connection, resolved and checked.
fn connection(
    conn: &ConnectionConfig,
    units: Units<'_>,
    signals: &mut SignalTable,
    ctx: &str,
    notes: &mut Vec<String>,
) -> Result<ConnectionDef, SystemError> {
    let text = &conn.text;
    let (a, b) = text
        .split_once("->")
        .ok_or_else(|| invalid(ctx, "expected \"instance.output -> instance.input\""))?;
    let (a, b) = (a.trim(), b.trim());
    let from = units.endpoint(ctx, a)?;
    let (to_unit, to_sv) = target_input(units, b, ctx)?;
    let to_def = &units.instances[to_unit];
    let (from_unit_name, from_md) =
        source_unit(units, &from, (a, b), (to_def, to_sv), text, ctx, notes)?;
    check_types(&from, a, to_sv, b, ctx)?;
    let conversion = checked_conversion(
        conn,
        units,
        (&from, a),
        (from_md, from_unit_name.as_deref()),
        to_def.description(),
        to_sv,
        ctx,
    )?;
    if let Some(note) = &conversion.note {
        notes.push(format!("connection \"{text}\": {note}"));
    }
    Ok(ConnectionDef {
        text: text.clone(),
        from_slot: signals.slot(&from, a),
        from,
        from_name: a.to_string(),
        to_unit,
        to_vr: to_sv.value_reference,
        to_ty: to_sv.ty,
        to_name: b.to_string(),
        scale: conversion.scale,
        offset: conversion.offset,
    })
}

/// The input a connection drives, `b` (`instance.variable`): the unit, an instance (a
/// replayed channel cannot be driven), and its variable, which must be an input.
fn target_input<'u>(
    units: Units<'u>,
    b: &str,
    ctx: &str,
) -> Result<(usize, &'u ScalarVariable), SystemError> {
    let (tu, tv) = split_name(b)
        .ok_or_else(|| invalid(ctx, format!("'{b}' is not of the form instance.variable")))?;
    let to_unit = units.index(tu).ok_or_else(|| units.unknown(ctx, tu))?;
    if units.is_replay(to_unit) {
        return Err(invalid(
            ctx,
            format!("'{b}' is a replayed channel; it cannot be an input"),
        ));
    }
    let to_def = &units.instances[to_unit];
    let to_sv = to_def.variable(tv, ctx)?;
    require_causality(
        ctx,
        b,
        to_sv,
        Causality::Input,
        "an input: it cannot be connected to",
    )?;
    Ok((to_unit, to_sv))
}

/// The variable `name` (`sv`) must be of the causality `want`, which `what` names: else
/// the error says what it is instead.
fn require_causality(
    ctx: &str,
    name: &str,
    sv: &ScalarVariable,
    want: Causality,
    what: &str,
) -> Result<(), SystemError> {
    if sv.causality == want {
        return Ok(());
    }
    Err(invalid(
        ctx,
        format!(
            "'{name}' is {} {}, not {what}",
            sv.variability, sv.causality
        ),
    ))
}

/// The source `a`'s unit and, for an FMU variable, the model description that defines it;
/// an FMU variable must be an output. A replayed column without a unit takes the input
/// `b`'s, said in a note.
fn source_unit<'u>(
    units: Units<'u>,
    from: &Endpoint,
    (a, b): (&str, &str),
    (to_def, to_sv): (&InstanceDef, &ScalarVariable),
    text: &str,
    ctx: &str,
    notes: &mut Vec<String>,
) -> Result<(Option<String>, Option<&'u ModelDescription>), SystemError> {
    Ok(match from {
        Endpoint::Fmu {
            unit, unit_name, ..
        } => {
            let sv = units
                .variable(from)
                .expect("an FMU endpoint names a variable");
            require_causality(ctx, a, sv, Causality::Output, "an output")?;
            (
                unit_name.clone(),
                Some(units.instances[*unit].description()),
            )
        }
        // A column without a unit (an FMPy input file has none) takes the input's.
        Endpoint::Replay { unit_name, .. } if unit_name.is_empty() => {
            if let Some(u) = to_def.description().unit_of(to_sv) {
                notes.push(format!(
                    "connection \"{text}\": '{a}' has no unit; taken as '{b}''s unit {u}"
                ));
            }
            (None, None)
        }
        Endpoint::Replay { unit_name, .. } => (Some(unit_name.clone()), None),
    })
}

/// The connection's conversion ([`connection_conversion`]) from the source `a` (its model
/// description, if an FMU's, and its unit) to the input `to_sv` of `to_md`, its error put
/// in the connection's context; for a replayed column the fix it names is the column's
/// unit in the `[[replay]]`, not a scale.
fn checked_conversion(
    conn: &ConnectionConfig,
    units: Units<'_>,
    (from, a): (&Endpoint, &str),
    (from_md, from_unit_name): (Option<&ModelDescription>, Option<&str>),
    to_md: &ModelDescription,
    to_sv: &ScalarVariable,
    ctx: &str,
) -> Result<Conversion, SystemError> {
    let empty = ModelDescription::default();
    connection_conversion(
        conn,
        (from_md.unwrap_or(&empty), from_unit_name),
        (to_md, to_md.unit_of(to_sv)),
        to_sv.ty,
    )
    .map_err(|error| SystemError::Conversion {
        context: ctx.to_string(),
        error,
        hint: match from {
            // The fix for a replayed column is its unit, not a scale.
            Endpoint::Replay { unit, column, .. } => format!(
                "; if the file's unit for '{a}' is wrong or missing, name it in its [[replay]]: units = {{ {} = \"{}\" }}",
                units.replay(*unit).columns[*column],
                to_md.unit_of(to_sv).unwrap_or("1")
            ),
            _ => String::new(),
        },
    })
}

/// Which source types can drive which input: the same type, a number into a Real, an
/// Integer or Enumeration into either; a replayed column drives any numeric input (held
/// for the discrete ones; its values are checked against the input's type).
fn check_types(
    from: &Endpoint,
    a: &str,
    to: &ScalarVariable,
    b: &str,
    ctx: &str,
) -> Result<(), SystemError> {
    let from_ty = match from {
        Endpoint::Fmu { ty, .. } => *ty,
        Endpoint::Replay { .. } => ScalarType::Real,
    };
    let replayed = matches!(from, Endpoint::Replay { .. }) && to.ty != ScalarType::String;
    let type_ok = replayed
        || from_ty == to.ty
        || (to.ty == ScalarType::Real
            && matches!(
                from_ty,
                ScalarType::Integer | ScalarType::Boolean | ScalarType::Enumeration
            ))
        || (matches!(to.ty, ScalarType::Integer | ScalarType::Enumeration)
            && matches!(from_ty, ScalarType::Integer | ScalarType::Enumeration));
    if !type_ok {
        return Err(invalid(
            ctx,
            format!(
                "type mismatch: '{a}' is {}, '{b}' is {}",
                from_ty.name(),
                to.ty.name()
            ),
        ));
    }
    Ok(())
}

/// Replayed columns: which are held (the inputs FMPy holds: discrete and non-Real ones,
/// under `interpolation = "auto"`), as (replay, column); and their values fit the inputs
/// they drive.
pub(super) fn replayed_columns(
    connections: &[ConnectionDef],
    units: Units<'_>,
    ctx_file: &str,
) -> Result<Vec<(usize, usize)>, SystemError> {
    let mut to_hold = Vec::new();
    for c in connections {
        let Endpoint::Replay { unit, column, .. } = c.from else {
            continue;
        };
        let to = &units.instances[c.to_unit];
        let sv = to
            .description()
            .variables
            .iter()
            .find(|v| v.has_key(c.to_key()) && v.causality == Causality::Input)
            .expect("resolved by the connections stage");
        let r = units.replay(unit);
        let discrete = sv.ty != ScalarType::Real
            || matches!(sv.variability, Variability::Discrete | Variability::Tunable);
        if r.interpolation == Interpolation::Auto && discrete {
            to_hold.push((unit - units.instances.len(), column));
        }
        let ctx = format!("{ctx_file}: connection \"{}\"", c.text);
        check_replayed_values(r.values(column), &r.path, to.description(), sv, c, &ctx)?;
    }
    Ok(to_hold)
}

/// A replayed column's values against the input they drive: 32-bit integers for an
/// Integer, items for an Enumeration, 0 or 1 for a Boolean.
fn check_replayed_values(
    values: &[f64],
    path: &std::path::Path,
    md: &ModelDescription,
    sv: &ScalarVariable,
    c: &ConnectionDef,
    ctx: &str,
) -> Result<(), SystemError> {
    let bad = |k: usize, why: String| {
        invalid(
            ctx,
            format!(
                "{}, row {}: value {} {why}",
                path.display(),
                k + 1,
                values[k]
            ),
        )
    };
    match sv.ty {
        ScalarType::Integer | ScalarType::Enumeration => {
            if let Some(k) = values
                .iter()
                .position(|x| x.fract() != 0.0 || *x < i32::MIN as f64 || *x > i32::MAX as f64)
            {
                return Err(bad(
                    k,
                    format!(
                        "is not a 32-bit integer for {} '{}'",
                        sv.ty.name(),
                        c.to_name
                    ),
                ));
            }
            if let Some(items) = md.enumeration_items(sv) {
                if let Some(k) = values
                    .iter()
                    .position(|x| !items.iter().any(|(_, v)| *v as f64 == *x))
                {
                    return Err(bad(
                        k,
                        format!("is not an item of the Enumeration '{}'", c.to_name),
                    ));
                }
            }
        }
        ScalarType::Boolean => {
            if let Some(k) = values.iter().position(|x| *x != 0.0 && *x != 1.0) {
                return Err(bad(
                    k,
                    format!("is not 0 or 1 for the Boolean '{}'", c.to_name),
                ));
            }
        }
        _ => {}
    }
    Ok(())
}

/// A warning for every input that is neither connected nor set and has no start value.
pub(super) fn unconnected_inputs(
    file: &SystemFile,
    units: Units<'_>,
    connections: &[ConnectionDef],
) -> Vec<String> {
    let mut warnings = Vec::new();
    for (k, inst) in units.instances.iter().enumerate() {
        for v in inst.description().variables_of(Causality::Input) {
            let connected = connections
                .iter()
                .any(|c| c.to_unit == k && c.to_key() == v.key());
            let set = file
                .parameters
                .contains_key(&format!("{}.{}", inst.name, v.name))
                || inst.ports.iter().any(|(ours, theirs)| {
                    theirs == &v.name
                        && file
                            .parameters
                            .contains_key(&format!("{}.{ours}", inst.name))
                });
            if !connected && !set && v.start.is_none() {
                warnings.push(format!(
                    "input '{}.{}' is not connected and has no start value",
                    inst.name, v.name
                ));
            }
        }
    }
    warnings
}

/// A connection's conversion: the file's gain, or the units (declared, or as the file
/// overrides them).
fn connection_conversion(
    conn: &ConnectionConfig,
    from: (&ModelDescription, Option<&str>),
    to: (&ModelDescription, Option<&str>),
    to_ty: ScalarType,
) -> Result<Conversion, ConversionError> {
    let gain = conn.scale.is_some() || conn.offset.is_some();
    let overridden = conn.from_unit.is_some() || conn.to_unit.is_some();
    if gain && overridden {
        return Err(ConversionError::GainAndUnits);
    }
    if (gain || overridden) && to_ty != ScalarType::Real {
        return Err(ConversionError::NotReal { ty: to_ty.name() });
    }
    if gain {
        return gain_conversion(conn, from.1, to.1);
    }
    let known = |md: &ModelDescription, u: &Option<String>, end: &'static str| match u {
        Some(u) if units::definition(md, u).is_none() => Err(ConversionError::UnknownUnit {
            end,
            unit: u.clone(),
            known: tb_fmi::units::UNITS
                .iter()
                .map(|d| d.name)
                .collect::<Vec<_>>()
                .join(", "),
        }),
        _ => Ok(()),
    };
    known(from.0, &conn.from_unit, "from_unit")?;
    known(to.0, &conn.to_unit, "to_unit")?;
    let from_unit = conn.from_unit.as_deref().or(from.1);
    let to_unit = conn.to_unit.as_deref().or(to.1);
    let mut c = unit_conversion((from.0, from_unit), (to.0, to_unit))?;
    if overridden {
        let said = format!(
            "units overridden in the system file: '{}' -> '{}', scale {}, offset {}",
            from_unit.unwrap_or("1"),
            to_unit.unwrap_or("1"),
            c.scale,
            c.offset
        );
        c.note = Some(match c.note {
            Some(n) => format!("{said}; {n}"),
            None => said,
        });
    }
    Ok(c)
}

/// The system file's own `scale`/`offset`, instead of the declared units.
fn gain_conversion(
    conn: &ConnectionConfig,
    from_unit: Option<&str>,
    to_unit: Option<&str>,
) -> Result<Conversion, ConversionError> {
    let scale = conn.scale.unwrap_or(1.0);
    let offset = conn.offset.unwrap_or(0.0);
    if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
        return Err(ConversionError::BadGain { scale, offset });
    }
    let declared = |u: Option<&str>| u.map_or("none".to_string(), |u| format!("'{u}'"));
    Ok(Conversion {
        scale,
        offset,
        note: Some(format!(
            "scale {scale} and offset {offset} from the system file (declared units {} and {} not used)",
            declared(from_unit),
            declared(to_unit)
        )),
    })
}
