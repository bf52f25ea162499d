//! Typed values of the plan: parameter slots and values, the stop condition.

use crate::{invalid, SystemError};
use std::fmt;
use tb_fmi::ScalarType;

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
                        "{x} is outside the declared range [{}, {}] of '{}'",
                        self.min.map_or("-inf".into(), |m| m.to_string()),
                        self.max.map_or("inf".into(), |m| m.to_string()),
                        self.name
                    ),
                ));
            }
        }
        Ok(v)
    }
}

/// How a condition compares the signal with its threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    AtLeast,
    AtMost,
    Above,
    Below,
}

impl Op {
    pub fn symbol(self) -> &'static str {
        match self {
            Op::AtLeast => ">=",
            Op::AtMost => "<=",
            Op::Above => ">",
            Op::Below => "<",
        }
    }
}

/// `signal OP threshold`, e.g. `vehicle.lap >= 1`.
#[derive(Clone, Debug, PartialEq)]
pub struct Condition {
    pub signal: String,
    /// The signal's exchange slot.
    pub slot: usize,
    pub op: Op,
    pub threshold: f64,
}

impl Condition {
    /// Parse `instance.variable OP number` (OP one of `>=`, `<=`, `>`, `<`).
    pub fn parse(text: &str) -> Option<(String, Op, f64)> {
        for (sym, op) in [
            (">=", Op::AtLeast),
            ("<=", Op::AtMost),
            (">", Op::Above),
            ("<", Op::Below),
        ] {
            if let Some((a, b)) = text.split_once(sym) {
                let signal = a.trim();
                let threshold: f64 = b.trim().parse().ok()?;
                if crate::split_name(signal).is_none() || !threshold.is_finite() {
                    return None;
                }
                return Some((signal.to_string(), op, threshold));
            }
        }
        None
    }

    #[inline]
    pub fn holds(&self, x: f64) -> bool {
        match self.op {
            Op::AtLeast => x >= self.threshold,
            Op::AtMost => x <= self.threshold,
            Op::Above => x > self.threshold,
            Op::Below => x < self.threshold,
        }
    }
}

impl fmt::Display for Condition {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {} {}", self.signal, self.op.symbol(), self.threshold)
    }
}

/// When a run ends.
#[derive(Clone, Debug, PartialEq)]
pub enum Stop {
    /// At this time (the last step clamped to it).
    Time(f64),
    /// When the condition holds after a step; an error after `max_time` of simulated time.
    When { condition: Condition, max_time: f64 },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions_parse_and_hold() {
        let (s, op, t) = Condition::parse(" vehicle.lap >= 1 ").unwrap();
        assert_eq!((s.as_str(), op, t), ("vehicle.lap", Op::AtLeast, 1.0));
        let c = Condition {
            signal: s,
            slot: 0,
            op,
            threshold: t,
        };
        assert!(c.holds(1.0) && !c.holds(0.999));
        assert_eq!(c.to_string(), "vehicle.lap >= 1");
        assert_eq!(Condition::parse("x.y < -2.5").unwrap().1, Op::Below);
        for bad in [
            "lap",
            "vehicle.lap >= ",
            "lap >= 1",
            "a.b >= nan",
            "a.b = 1",
        ] {
            assert!(Condition::parse(bad).is_none(), "{bad}");
        }
    }
}
