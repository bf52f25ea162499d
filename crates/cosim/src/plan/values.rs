//! Stage "parameters": settable variables resolved into typed slots, and the values of
//! the system file checked against them (type, declared range, Enumeration items).

use crate::{invalid, SystemError};
use std::fmt;
use tb_fmi::{ScalarType, VarKey};

/// A settable variable, resolved: which instance, which value reference, which type.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSlot {
    /// The system's name, `instance.variable`.
    pub name: String,
    /// Index of the instance.
    pub unit: usize,
    pub vr: u32,
    pub ty: ScalarType,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// The FMU's start value as a number, if it has one.
    pub start: Option<f64>,
    /// A String parameter whose FMU name ends in `_file`: it holds a path, and a relative
    /// one is taken relative to the file that sets it.
    pub is_path: bool,
    /// An Enumeration's items (name, value): a value must be one of them.
    pub items: Option<Vec<(String, i64)>>,
    /// The variable's unit (its own or its declared type's), for reports.
    pub variable_unit: Option<String>,
}

/// A typed parameter value.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    Real(f64),
    /// Integer and Enumeration.
    Integer(i32),
    Boolean(bool),
    String(String),
}

impl ParamValue {
    /// The value space it is set in (the typed `fmi2Set*` call that takes it).
    pub fn space(&self) -> ScalarType {
        match self {
            ParamValue::Real(_) => ScalarType::Real,
            ParamValue::Integer(_) => ScalarType::Integer,
            ParamValue::Boolean(_) => ScalarType::Boolean,
            ParamValue::String(_) => ScalarType::String,
        }
    }

    /// The value as a number (booleans 0/1), None for strings.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            ParamValue::Real(x) => Some(*x),
            ParamValue::Integer(i) => Some(*i as f64),
            ParamValue::Boolean(b) => Some(*b as i32 as f64),
            ParamValue::String(_) => None,
        }
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Real(x) => write!(f, "{x}"),
            ParamValue::Integer(i) => write!(f, "{i}"),
            ParamValue::Boolean(b) => write!(f, "{b}"),
            ParamValue::String(s) => write!(f, "{s:?}"),
        }
    }
}

impl ParamSlot {
    /// The variable's [`VarKey`]: (value space, value reference).
    pub fn key(&self) -> VarKey {
        (self.ty.value_space(), self.vr)
    }

    /// A value from a system or study file (or `--set`), checked for type and range.
    pub fn value_from_toml(
        &self,
        value: &toml::Value,
        ctx: &str,
    ) -> Result<ParamValue, SystemError> {
        let name = &self.name;
        let mismatch = || {
            invalid(
                ctx,
                format!("'{name}' is {}, the value {value} is not", self.ty.name()),
            )
        };
        let v = match self.ty {
            ScalarType::Real => match (value.as_float(), value.as_integer()) {
                (Some(x), _) => ParamValue::Real(x),
                // An integer an f64 cannot hold exactly (beyond 2^53) is not rounded in
                // silence (an FMI 3.0 Int64 travels as a Real).
                (None, Some(i)) if (i as f64) as i64 == i => ParamValue::Real(i as f64),
                (None, Some(i)) => {
                    return Err(invalid(
                        ctx,
                        format!(
                            "'{name}': {i} cannot be carried exactly as a double (integers are exact up to 2^53 = 9007199254740992)"
                        ),
                    ))
                }
                _ => return Err(mismatch()),
            },
            // An Enumeration by an item's name (`"second_order"`) as well as by its value.
            ScalarType::Enumeration if value.is_str() => {
                let text = value.as_str().unwrap_or_default();
                let items = self.items.as_deref().unwrap_or_default();
                match items.iter().find(|(n, _)| n == text) {
                    Some((_, v)) => ParamValue::Integer(i32::try_from(*v).map_err(|_| mismatch())?),
                    None => {
                        return Err(invalid(
                            ctx,
                            format!(
                                "'{text}' is not an item of the Enumeration '{name}' ({})",
                                items
                                    .iter()
                                    .map(|(n, value)| format!("{value} '{n}'"))
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        ))
                    }
                }
            }
            ScalarType::Integer | ScalarType::Enumeration => {
                let i = value.as_integer().ok_or_else(mismatch)?;
                let i = i32::try_from(i).map_err(|_| {
                    invalid(
                        ctx,
                        format!(
                            "{i} does not fit the 32-bit {} '{name}' [{}, {}]",
                            self.ty.name(),
                            i32::MIN,
                            i32::MAX
                        ),
                    )
                })?;
                ParamValue::Integer(i)
            }
            ScalarType::Boolean => ParamValue::Boolean(value.as_bool().ok_or_else(mismatch)?),
            ScalarType::String => ParamValue::String(value.as_str().ok_or_else(mismatch)?.into()),
        };
        self.check(v, ctx)
    }

    /// A path value made absolute against `base` (the absolute folder of the system or
    /// study file, or the working directory for the command line; see
    /// [`tb_files::folder_of`]) and normalised. Other values pass unchanged.
    pub fn resolve_path(&self, value: ParamValue, base: &std::path::Path) -> ParamValue {
        match value {
            ParamValue::String(v) if self.is_path && !v.is_empty() && !v.starts_with("file:") => {
                ParamValue::String(
                    tb_files::resolve(base, std::path::Path::new(&v))
                        .display()
                        .to_string(),
                )
            }
            other => other,
        }
    }

    /// A path value set by an SSP package: a file inside the unpacked package, named
    /// relative to it; an absolute path, a URI or a name that climbs out is refused.
    pub fn inside_package(
        &self,
        value: ParamValue,
        package: &std::path::Path,
        ctx: &str,
    ) -> Result<ParamValue, SystemError> {
        let ParamValue::String(v) = &value else {
            return Ok(value);
        };
        if !self.is_path || v.is_empty() {
            return Ok(value);
        }
        let name = std::path::Path::new(v);
        let resolved = tb_files::resolve(package, name);
        if v.starts_with("file:") || name.is_absolute() || !resolved.starts_with(package) {
            return Err(invalid(
                ctx,
                format!(
                    "'{}' = \"{}\": a path an SSP package sets must name a file inside the package (relative to its root, without climbing out)",
                    self.name,
                    tb_files::excerpt(v)
                ),
            ));
        }
        Ok(ParamValue::String(resolved.display().to_string()))
    }

    /// A number for this slot (the optimiser's candidates), checked like any value.
    pub fn real(&self, x: f64) -> Result<ParamValue, SystemError> {
        let v = match self.ty {
            ScalarType::Real => ParamValue::Real(x),
            _ => {
                return Err(invalid(
                    format!("parameter \"{}\"", self.name),
                    format!("'{}' is {}, not Real", self.name, self.ty.name()),
                ))
            }
        };
        self.check(v, &format!("parameter \"{}\"", self.name))
    }

    /// Type and declared range.
    pub fn check(&self, v: ParamValue, ctx: &str) -> Result<ParamValue, SystemError> {
        let type_ok = matches!(
            (&v, self.ty),
            (ParamValue::Real(_), ScalarType::Real)
                | (
                    ParamValue::Integer(_),
                    ScalarType::Integer | ScalarType::Enumeration
                )
                | (ParamValue::Boolean(_), ScalarType::Boolean)
                | (ParamValue::String(_), ScalarType::String)
        );
        if !type_ok {
            return Err(invalid(
                ctx,
                format!(
                    "'{}' is {}, the value {v} is not",
                    self.name,
                    self.ty.name()
                ),
            ));
        }
        if let ParamValue::Real(x) = v {
            // NaN passes every range check and would reach the FMU (or be caught by it, late).
            if !x.is_finite() {
                return Err(invalid(
                    ctx,
                    format!("'{}' must be a finite number, got {x}", self.name),
                ));
            }
        }
        if let (ParamValue::Integer(i), Some(items)) = (&v, &self.items) {
            if !items.iter().any(|(_, value)| *value == i64::from(*i)) {
                return Err(invalid(
                    ctx,
                    format!(
                        "{i} is not an item of the Enumeration '{}' ({})",
                        self.name,
                        items
                            .iter()
                            .map(|(n, value)| format!("{value} '{n}'"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
        }
        if let Some(x) = v.as_f64().filter(|_| self.ty != ScalarType::Boolean) {
            if self.min.is_some_and(|m| x < m) || self.max.is_some_and(|m| x > m) {
                return Err(invalid(
                    ctx,
                    format!(
                        "{} is outside the declared range [{}, {}] of '{}'",
                        tb_files::number(x),
                        self.min.map_or("-inf".into(), tb_files::number),
                        self.max.map_or("inf".into(), tb_files::number),
                        self.name
                    ),
                ));
            }
        }
        Ok(v)
    }
}

/// Stage "parameters": the system file's `[parameters]`, typed and range-checked once,
/// a path made absolute against the file's folder.
pub(super) fn parameters(
    file: &crate::config::SystemFile,
    instances: &[super::InstanceDef],
    path: &std::path::Path,
    ctx_file: &str,
) -> Result<Vec<(ParamSlot, ParamValue)>, SystemError> {
    let folder = tb_files::folder_of(path);
    let mut parameters = Vec::new();
    for (name, value) in &file.parameters {
        let ctx = format!("{ctx_file}: parameter \"{name}\"");
        let slot = super::instances::parameter_slot(instances, name, &ctx)?;
        let value = slot.value_from_toml(value, &ctx)?;
        let value = match &file.package {
            Some(package) => slot.inside_package(value, package, &ctx)?,
            None => slot.resolve_path(value, &folder),
        };
        parameters.push((slot, value));
    }
    Ok(parameters)
}
