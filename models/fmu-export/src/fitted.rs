//! A fitted twin's start values: `resources/fitted_start_values.toml`, written by
//! `twinbench export-twin` into a copy of a model's FMU, read once at instantiation.
//!
//! **Why a resource and not only the description.** FMI says a variable's start value is
//! the value the FMU has after instantiation; a host need not set it (FMPy, OMSimulator and
//! twinbench do not). The fitted values must therefore live in the binary's own defaults:
//! the library reads this file at instantiation and applies it after the table's defaults
//! (and again at `fmi2Reset`), and the description's start attributes say the same values.
//! The file also names the fitted FMU's own GUID (instantiation token), which the
//! library then accepts besides the model's: the fitted FMU is another FMU.
//!
//! ```toml
//! token = "{…}"          # the fitted description's guid / instantiationToken
//! [start]
//! c_lift_front = 0.9120481429575731
//! v_start = 52.43
//! ```
//! A value must name a variable with a start value that a host may set, with its type, in
//! its declared range: anything else refuses the instantiation, naming the file and the
//! variable (a broken file is never half applied).

use crate::error::ModelError;
use crate::variables::{Causality, ScalarType, Value, VarTable, Variability};
use std::path::{Path, PathBuf};

/// Why a fitted start value file refuses the instantiation.
#[derive(Debug, thiserror::Error)]
pub enum FittedError {
    /// The file cannot be read (not a regular file, too large, not text).
    #[error(transparent)]
    Read(#[from] ModelError),
    #[error("{path}: {source}")]
    Invalid {
        path: PathBuf,
        #[source]
        source: StartsError,
    },
}

/// What is wrong in a fitted start value file's text: the key or variable, and what was
/// expected.
#[derive(Debug, thiserror::Error)]
pub enum StartsError {
    #[error("{0}")]
    Toml(#[from] toml::de::Error),
    #[error("expected `token = \"…\"`, the fitted FMU's GUID")]
    NoToken,
    #[error("expected a `[start]` table of start values")]
    NoStartTable,
    #[error("unknown key `{key}` (expected `token` and `[start]`)")]
    UnknownKey { key: String },
    #[error("no variable named `{name}` in this model")]
    NoVariable { name: String },
    #[error("`{variable}` is not a parameter or input with a start value: it cannot be fitted")]
    NotFittable { variable: &'static str },
    /// `value` as the file writes it; `expected` the model's type in words.
    #[error("`{variable}` = {value}: expected {expected} (its type in the model)")]
    Type {
        variable: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("`{variable}` = {value}: expected a finite value in [{min}, {max}]")]
    Range {
        variable: &'static str,
        value: String,
        min: f64,
        max: f64,
    },
}

/// The file's name in `resources/`.
pub const START_FILE: &str = "fitted_start_values.toml";

/// One start value, owned (a String's text is not `'static`).
#[derive(Clone, Debug, PartialEq)]
enum Start {
    Value(Value),
    Text(String),
}

/// The fitted start values of one FMU, checked against the model's table.
#[derive(Clone, Debug, Default)]
pub struct FittedStarts {
    /// The fitted FMU's GUID / instantiation token.
    pub token: String,
    /// (index in the table, value), in the file's order.
    values: Vec<(usize, Start)>,
}

impl FittedStarts {
    /// The file in `resource_dir`, if there is one; an error names the file, the variable
    /// and what was expected.
    pub fn load<V: VarTable>(resource_dir: &Path) -> Result<Option<FittedStarts>, FittedError> {
        let path = resource_dir.join(START_FILE);
        if !path.exists() {
            return Ok(None);
        }
        let text = crate::resources::read_text(&path)?;
        Self::parse::<V>(&text)
            .map(Some)
            .map_err(|source| FittedError::Invalid { path, source })
    }

    /// The file in the resource folder a host gave at instantiation (none given: none).
    pub fn of_instance<V: VarTable>(
        resource_dir: Option<&Path>,
    ) -> Result<Option<FittedStarts>, FittedError> {
        Ok(resource_dir.map(Self::load::<V>).transpose()?.flatten())
    }

    /// Whether a host's GUID (instantiation token) names this FMU: the model's own, or the
    /// fitted description's when there are fitted starts.
    pub fn accepts(fitted: Option<&FittedStarts>, given: &str, model: &str) -> bool {
        given == model || fitted.is_some_and(|f| f.token == given)
    }

    /// The file's text, checked against the table `V`.
    pub fn parse<V: VarTable>(text: &str) -> Result<FittedStarts, StartsError> {
        let table: toml::Table = text.parse()?;
        let token = match table.get("token") {
            Some(toml::Value::String(t)) if !t.is_empty() => t.clone(),
            _ => return Err(StartsError::NoToken),
        };
        let Some(toml::Value::Table(start)) = table.get("start") else {
            return Err(StartsError::NoStartTable);
        };
        if let Some(other) = table.keys().find(|k| *k != "token" && *k != "start") {
            return Err(StartsError::UnknownKey { key: other.clone() });
        }
        let mut values = Vec::with_capacity(start.len());
        for (name, value) in start {
            let Some(index) = V::index_of(name) else {
                return Err(StartsError::NoVariable { name: name.clone() });
            };
            values.push((index, Self::checked::<V>(index, value)?));
        }
        Ok(FittedStarts { token, values })
    }

    /// `value` as variable `index`'s start: its type, finite, in its range, and a variable
    /// a host may give a start value.
    fn checked<V: VarTable>(index: usize, value: &toml::Value) -> Result<Start, StartsError> {
        let v = &V::VARIABLES[index];
        let settable = v.has_start()
            && v.variability != Variability::Constant
            && matches!(v.causality, Causality::Parameter | Causality::Input);
        if !settable {
            return Err(StartsError::NotFittable { variable: v.name });
        }
        let wrong = |expected| StartsError::Type {
            variable: v.name,
            value: value.to_string(),
            expected,
        };
        let start = match (v.var_type().value_space(), value) {
            (ScalarType::Real, toml::Value::Float(x)) => Start::Value(Value::Real(*x)),
            (ScalarType::Real, toml::Value::Integer(i)) => Start::Value(Value::Real(*i as f64)),
            (ScalarType::Integer, toml::Value::Integer(i)) => Start::Value(Value::Integer(
                i32::try_from(*i).map_err(|_| wrong("a 32-bit integer"))?,
            )),
            (ScalarType::Boolean, toml::Value::Boolean(b)) => Start::Value(Value::Boolean(*b)),
            (ScalarType::String, toml::Value::String(s)) => Start::Text(s.clone()),
            (ScalarType::Real, _) => return Err(wrong("a number")),
            (ScalarType::Integer | ScalarType::Enumeration, _) => return Err(wrong("an integer")),
            (ScalarType::Boolean, _) => return Err(wrong("true or false")),
            (ScalarType::String, _) => return Err(wrong("a string")),
        };
        if let Start::Value(x) = start {
            let f = x.as_f64();
            let (lo, hi) = (
                v.min.unwrap_or(f64::NEG_INFINITY),
                v.max.unwrap_or(f64::INFINITY),
            );
            if !f.is_finite() || f < lo || f > hi {
                return Err(StartsError::Range {
                    variable: v.name,
                    value: value.to_string(),
                    min: lo,
                    max: hi,
                });
            }
        }
        Ok(start)
    }

    /// Puts the start values into `vars` (the table's defaults before).
    pub fn apply<V: VarTable>(&self, vars: &mut V) {
        for (index, value) in &self.values {
            match value {
                Start::Value(x) => vars.set(*index, *x),
                Start::Text(s) => vars.set_str(*index, s),
            };
        }
    }
}
