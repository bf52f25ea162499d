//! Torsional chain description (TOML), paper Eq. 1.
//!
//! ```toml
//! name = "EDU on the bench"
//! [[inertia]]              # J_1 ... J_n, left to right
//! name = "motor+gearbox"
//! inertia = 1.595          # kg·m²
//! [[spring]]               # c_T1 ... c_T(n-1), between inertia k and k+1
//! name = "side shaft"
//! stiffness = 8000.0       # N·m/rad
//! damping = 2.0            # N·m·s/rad (optional)
//! [ground_left]            # optional: c_T0, inertia 1 to ground; absent = free end
//! name = "mount"
//! stiffness = 1e5
//! ```
//!
//! An end without a ground spring is free. A rigid clamp is a ground spring with the
//! clamp's (high) stiffness.

use crate::error::{AnalysisError, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One lumped inertia `J_k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inertia {
    pub name: String,
    /// kg·m²
    pub inertia: f64,
    /// Absolute (to ground) viscous damping, N·m·s/rad, e.g. bearing or windage losses.
    #[serde(default)]
    pub damping: f64,
}

/// One torsional spring-damper `c_Tk`, `d_k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spring {
    pub name: String,
    /// N·m/rad
    pub stiffness: f64,
    /// N·m·s/rad
    #[serde(default)]
    pub damping: f64,
}

/// A chain of inertias joined by springs, either end free or grounded through a spring.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Chain {
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    #[serde(rename = "inertia")]
    pub inertias: Vec<Inertia>,
    #[serde(rename = "spring", default)]
    pub springs: Vec<Spring>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_left: Option<Spring>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_right: Option<Spring>,
}

/// Where a spring sits: between which degrees of freedom (`None` = ground).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SpringPlace {
    pub left: Option<usize>,
    pub right: Option<usize>,
}

/// A component's `value` (an inertia or a stiffness) positive and its `damping`
/// non-negative, both finite: else the error `not_positive` makes (chain, component,
/// value), or the damping's.
fn check_component(
    chain: &str,
    component: &str,
    value: f64,
    damping: f64,
    not_positive: impl FnOnce(String, String, f64) -> AnalysisError,
) -> Result<()> {
    if !(value.is_finite() && value > 0.0) {
        return Err(not_positive(
            chain.to_string(),
            component.to_string(),
            value,
        ));
    }
    if !(damping.is_finite() && damping >= 0.0) {
        return Err(AnalysisError::NegativeDamping {
            chain: chain.to_string(),
            component: component.to_string(),
            value: damping,
        });
    }
    Ok(())
}

impl Chain {
    /// Read and validate a chain from a TOML file.
    pub fn from_file(path: &Path) -> Result<Chain> {
        let file = path.display().to_string();
        let text =
            tb_files::input::read_to_string(path, tb_files::Limit::CONFIG).map_err(|source| {
                AnalysisError::Io {
                    file: file.clone(),
                    source,
                }
            })?;
        Chain::from_toml_str(&text, &file)
    }

    /// Parse and validate; `file` names the source in error messages.
    pub fn from_toml_str(text: &str, file: &str) -> Result<Chain> {
        let chain: Chain = toml::from_str(text).map_err(|e| AnalysisError::ChainFormat {
            file: file.to_string(),
            message: e.to_string().trim_end().to_string(),
        })?;
        chain.validate()?;
        Ok(chain)
    }

    /// Check the physics: positive inertias and stiffnesses, non-negative damping, at least
    /// two inertias, n−1 springs, unique names.
    pub fn validate(&self) -> Result<()> {
        let chain = || self.name.clone();
        let n = self.inertias.len();
        if n < 2 {
            return Err(AnalysisError::TooFewInertias {
                chain: chain(),
                count: n,
            });
        }
        if self.springs.len() != n - 1 {
            return Err(AnalysisError::SpringCount {
                chain: chain(),
                inertias: n,
                expected: n - 1,
                found: self.springs.len(),
            });
        }
        for j in &self.inertias {
            check_component(
                &self.name,
                &j.name,
                j.inertia,
                j.damping,
                |chain, component, value| AnalysisError::NonPositiveInertia {
                    chain,
                    component,
                    value,
                },
            )?;
        }
        for s in self.all_springs().map(|(s, _)| s) {
            check_component(
                &self.name,
                &s.name,
                s.stiffness,
                s.damping,
                |chain, component, value| AnalysisError::NonPositiveStiffness {
                    chain,
                    component,
                    value,
                },
            )?;
        }
        let mut names: Vec<&str> = self.inertias.iter().map(|j| j.name.as_str()).collect();
        names.extend(self.all_springs().map(|(s, _)| s.name.as_str()));
        let mut sorted = names.clone();
        sorted.sort_unstable();
        if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
            return Err(AnalysisError::DuplicateName {
                chain: chain(),
                name: w[0].to_string(),
            });
        }
        Ok(())
    }

    /// Whether neither end is grounded (the chain then has one rigid-body mode).
    pub fn is_free_free(&self) -> bool {
        self.ground_left.is_none() && self.ground_right.is_none()
    }

    /// All springs in the order of Eq. 5 (`c_T0`, `c_T1` … `c_Tn`), each with its place.
    pub fn all_springs(&self) -> impl Iterator<Item = (&Spring, SpringPlace)> {
        let n = self.inertias.len();
        let left = self.ground_left.iter().map(|s| {
            (
                s,
                SpringPlace {
                    left: None,
                    right: Some(0),
                },
            )
        });
        let inner = self.springs.iter().enumerate().map(|(k, s)| {
            (
                s,
                SpringPlace {
                    left: Some(k),
                    right: Some(k + 1),
                },
            )
        });
        let right = self.ground_right.iter().map(move |s| {
            (
                s,
                SpringPlace {
                    left: Some(n - 1),
                    right: None,
                },
            )
        });
        left.chain(inner).chain(right)
    }
}
