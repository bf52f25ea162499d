//! The identifiability check before a step: which parameter directions the step's
//! validation signals cannot see.
//!
//! Around the start point, every parameter is moved by ±`rel_step` of its scale (its start
//! value, or the span of its bounds when that is 0) and the comparison residual of each
//! signal (simulated − measured, filtered, on the distance grid, divided by the measured
//! signal's standard deviation and √N, times √weight) is differenced centrally: the
//! columns of J are the residuals' sensitivities to a relative change of each parameter.
//! The eigen-decomposition of JᵀJ then gives the directions the signals see (large
//! eigenvalues) and those they cannot (eigenvalue below `null_ratio` of the largest).
//! Each signal alone is checked too, from the same runs: `Fz_sum` alone sees only
//! `c_lift_front + c_lift_rear` (Eq. 18), the axle sums see the split.

use super::cmaes::symmetric_eigen;
use serde::{Deserialize, Serialize};

/// A linear combination of parameters, in their own units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Direction {
    /// One coefficient per parameter (largest magnitude scaled to 1).
    pub coefficients: Vec<f64>,
    /// Its eigenvalue of JᵀJ relative to the largest.
    pub relative_eigenvalue: f64,
}

/// The check for one set of signals.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SignalSetCheck {
    pub signals: Vec<String>,
    /// ‖∂r/∂ln p‖ per parameter.
    pub sensitivity: Vec<f64>,
    /// Combinations the signals see (Σ c_i·p_i), strongest first.
    pub visible: Vec<Direction>,
    /// Changes Δp ∝ coefficients that leave the residual (almost) unchanged.
    pub unseen: Vec<Direction>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    pub parameters: Vec<String>,
    pub start: Vec<f64>,
    pub rel_step: f64,
    pub null_ratio: f64,
    /// All the step's signals together, then each signal alone.
    pub combined: SignalSetCheck,
    pub per_signal: Vec<SignalSetCheck>,
    /// Runs that failed (the check is then incomplete).
    pub failures: Vec<String>,
}

fn normalise(v: &[f64]) -> Vec<f64> {
    let m = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return v.to_vec();
    }
    // Sign: the largest component positive.
    let k = v
        .iter()
        .position(|x| x.abs() == m)
        .expect("the maximum is one of them");
    let s = if v[k] < 0.0 { -1.0 } else { 1.0 };
    v.iter().map(|x| s * x / m).collect()
}

/// Analyse a Jacobian given as columns per parameter, rows per signal block.
/// `blocks[s][i]` is the column of parameter i restricted to signal s (relative units);
/// `scale[i]` converts a relative change into the parameter's units.
pub fn analyse(
    signals: &[String],
    blocks: &[Vec<Vec<f64>>],
    scale: &[f64],
    null_ratio: f64,
) -> SignalSetCheck {
    let p = scale.len();
    let mut jtj = vec![vec![0.0; p]; p];
    for block in blocks {
        for i in 0..p {
            for j in 0..p {
                jtj[i][j] += block[i]
                    .iter()
                    .zip(&block[j])
                    .map(|(a, b)| a * b)
                    .sum::<f64>();
            }
        }
    }
    let sensitivity: Vec<f64> = (0..p).map(|i| jtj[i][i].sqrt()).collect();
    let (vals, vecs) = symmetric_eigen(&jtj);
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| vals[b].total_cmp(&vals[a]));
    let top = vals[order[0]].max(f64::MIN_POSITIVE);
    let mut visible = Vec::new();
    let mut unseen = Vec::new();
    for &k in &order {
        let v: Vec<f64> = (0..p).map(|i| vecs[i][k]).collect();
        let rel = (vals[k] / top).max(0.0);
        if rel < null_ratio {
            // A change Δ(ln p) ∝ v, in units: Δp_i = v_i·scale_i.
            unseen.push(Direction {
                coefficients: normalise(
                    &v.iter().zip(scale).map(|(a, s)| a * s).collect::<Vec<_>>(),
                ),
                relative_eigenvalue: rel,
            });
        } else {
            // The residual sees Σ v_i·Δp_i/scale_i.
            visible.push(Direction {
                coefficients: normalise(
                    &v.iter().zip(scale).map(|(a, s)| a / s).collect::<Vec<_>>(),
                ),
                relative_eigenvalue: rel,
            });
        }
    }
    SignalSetCheck {
        signals: signals.to_vec(),
        sensitivity,
        visible,
        unseen,
    }
}

fn combination(names: &[String], c: &[f64], sep_sign: bool) -> String {
    let mut s = String::new();
    for (k, (n, &x)) in names.iter().zip(c).enumerate() {
        if x.abs() < 0.01 {
            continue;
        }
        let short = n.split_once('.').map_or(n.as_str(), |(_, v)| v);
        let sign = if x < 0.0 { "−" } else { "+" };
        if s.is_empty() {
            if x < 0.0 {
                s.push('−');
            }
        } else {
            s.push_str(&format!(" {sign} "));
        }
        let prefix = if sep_sign { "Δ" } else { "" };
        s.push_str(&format!("{:.2}·{prefix}{short}", x.abs()));
        let _ = k;
    }
    s
}

impl SignalSetCheck {
    /// One line: what these signals see and what they cannot.
    pub fn describe(&self, parameters: &[String]) -> String {
        let sig = self.signals.join(" + ");
        if self.unseen.is_empty() {
            return format!(
                "{sig}: every direction seen (smallest eigenvalue {:.1e} of the largest)",
                self.visible.last().map_or(0.0, |d| d.relative_eigenvalue)
            );
        }
        let sees: Vec<String> = self
            .visible
            .iter()
            .map(|d| combination(parameters, &d.coefficients, false))
            .collect();
        let blind: Vec<String> = self
            .unseen
            .iter()
            .map(|d| {
                format!(
                    "{} (eigenvalue {:.1e} of the largest)",
                    combination(parameters, &d.coefficients, true),
                    d.relative_eigenvalue
                )
            })
            .collect();
        format!(
            "{sig}: sees only {}; cannot see {}",
            if sees.is_empty() {
                "nothing".into()
            } else {
                sees.join(" and ")
            },
            blind.join(", ")
        )
    }
}

impl Identifiability {
    pub fn report_lines(&self) -> Vec<String> {
        let mut v = vec![self.combined.describe(&self.parameters)];
        if self.per_signal.len() > 1 {
            for c in &self.per_signal {
                v.push(format!("  alone: {}", c.describe(&self.parameters)));
            }
        }
        for f in &self.failures {
            v.push(format!("  failed run: {f}"));
        }
        v
    }

    /// Whether the step's signals together leave a direction unseen.
    pub fn has_unseen(&self) -> bool {
        !self.combined.unseen.is_empty()
    }
}
