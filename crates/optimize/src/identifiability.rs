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
//!
//! `check` makes the runs and J (the study driver calls it before each new step);
//! [`analyse`] is the eigen-analysis of one set of signals.

use super::cmaes::symmetric_eigen;
use super::study::StepConfig;
use crate::failure::RunError;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use tb_compare::{PreparedMeasurement, Table, Workspace};

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

/// Each parameter's step, relative to its scale.
const REL_STEP: f64 = 0.02;

/// Per run: each signal's covered grid range and filtered values on it.
type Residuals = Result<Vec<(Range<usize>, Vec<f64>)>, RunError>;

/// The check of a step around `x0`: 2 runs per parameter, in parallel on `pool`, each a
/// lap of the twin that `run` makes with the step's parameters at a point, its signals
/// compared with `prepared`.
pub(crate) fn check(
    step: &StepConfig,
    null_ratio: f64,
    x0: &[f64],
    bounds: &[(f64, f64)],
    prepared: &PreparedMeasurement,
    pool: &rayon::ThreadPool,
    run: impl Fn(&[f64]) -> Result<Table, RunError> + Sync,
) -> Identifiability {
    // A parameter's scale: its start value, or the span of its bounds when that is 0.
    let scale: Vec<f64> = x0
        .iter()
        .zip(bounds)
        .map(|(&x, &(lo, hi))| if x.abs() > 1e-12 { x.abs() } else { hi - lo })
        .collect();
    let residuals = residuals(&perturbed(x0, &scale, bounds), step, prepared, pool, run);
    let (blocks, failures) = jacobian(residuals, step, prepared, x0.len());
    let combined = analyse(&step.signals, &blocks, &scale, null_ratio);
    let per_signal = step
        .signals
        .iter()
        .enumerate()
        .map(|(s, name)| {
            analyse(
                std::slice::from_ref(name),
                std::slice::from_ref(&blocks[s]),
                &scale,
                null_ratio,
            )
        })
        .collect();
    Identifiability {
        parameters: step.parameter_names(),
        start: x0.to_vec(),
        rel_step: REL_STEP,
        null_ratio,
        combined,
        per_signal,
        failures,
    }
}

/// The points of the central differences: each parameter moved by +`REL_STEP` and then
/// −`REL_STEP` of its scale, about a centre moved inside its declared range (a start on a
/// bound is stepped inward: a run outside the range would fail and leave the parameter
/// unseen). The pair stays 2·`REL_STEP` of its scale apart.
fn perturbed(x0: &[f64], scale: &[f64], bounds: &[(f64, f64)]) -> Vec<Vec<f64>> {
    (0..2 * x0.len())
        .map(|j| {
            let i = j / 2;
            let sign = if j % 2 == 0 { 1.0 } else { -1.0 };
            let h = REL_STEP * scale[i];
            let (lo, hi) = bounds[i];
            let centre = match lo + h <= hi - h {
                true => x0[i].clamp(lo + h, hi - h),
                false => x0[i],
            };
            let mut x = x0.to_vec();
            x[i] = centre + sign * h;
            x
        })
        .collect()
}

/// Each point's run: the step's signals filtered on the distance grid (one run per thread
/// at a time, results in the points' order).
fn residuals(
    points: &[Vec<f64>],
    step: &StepConfig,
    prepared: &PreparedMeasurement,
    pool: &rayon::ThreadPool,
    run: impl Fn(&[f64]) -> Result<Table, RunError> + Sync,
) -> Vec<Residuals> {
    signals_on_grid(points, &step.signals, prepared, pool, run)
}

/// Each point's run: `signals` filtered on the distance grid, with the grid range each
/// covers (one run per thread at a time, results in the points' order).
pub(crate) fn signals_on_grid(
    points: &[Vec<f64>],
    signals: &[String],
    prepared: &PreparedMeasurement,
    pool: &rayon::ThreadPool,
    run: impl Fn(&[f64]) -> Result<Table, RunError> + Sync,
) -> Vec<Residuals> {
    pool.install(|| {
        points
            .par_iter()
            .with_max_len(1)
            .map(|x| {
                let table = run(x)?;
                let mut ws = Workspace::new();
                signals
                    .iter()
                    .map(|s| {
                        prepared
                            .on_grid(&table, s, true, &mut ws)
                            .map_err(|e| RunError::Table(Box::new(e)))
                    })
                    .collect()
            })
            .collect()
    })
}

/// J from the runs' residuals: per signal, per parameter, its column on the grid points
/// every run covers, divided by the measured signal's standard deviation and √N, times
/// √weight. When a run failed, every column is a single 0 and the failures say why.
fn jacobian(
    residuals: Vec<Residuals>,
    step: &StepConfig,
    prepared: &PreparedMeasurement,
    p: usize,
) -> (Vec<Vec<Vec<f64>>>, Vec<String>) {
    let mut failures = Vec::new();
    let weights = step.weights();
    // Per signal, per parameter: the column of J.
    let mut blocks: Vec<Vec<Vec<f64>>> = vec![vec![Vec::new(); p]; step.signals.len()];
    if residuals.iter().all(|r| r.is_ok()) {
        let res: Vec<_> = residuals.into_iter().map(|r| r.unwrap()).collect();
        for (s, name) in step.signals.iter().enumerate() {
            // The grid points every run covers.
            let lo = res.iter().map(|r| r[s].0.start).max().unwrap_or(0);
            let hi = res.iter().map(|r| r[s].0.end).min().unwrap_or(0);
            let meas = prepared.measured(name).unwrap_or(&[]);
            let n = hi.saturating_sub(lo);
            let m = &meas[lo.min(meas.len())..hi.min(meas.len())];
            let mean = m.iter().sum::<f64>() / n.max(1) as f64;
            let sd = (m.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n.max(1) as f64)
                .sqrt()
                .max(1e-12);
            let norm = weights[s].sqrt() / (sd * (n.max(1) as f64).sqrt());
            for i in 0..p {
                let (plus, minus) = (&res[2 * i][s], &res[2 * i + 1][s]);
                let col: Vec<f64> = (lo..hi)
                    .map(|g| {
                        let a = plus.1[g - plus.0.start];
                        let b = minus.1[g - minus.0.start];
                        (a - b) / (2.0 * REL_STEP) * norm
                    })
                    .collect();
                blocks[s][i] = col;
            }
        }
    } else {
        for r in residuals.into_iter().filter_map(|r| r.err()) {
            failures.push(r.to_string());
        }
        for b in blocks.iter_mut() {
            for c in b.iter_mut() {
                *c = vec![0.0];
            }
        }
    }
    (blocks, failures)
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

#[cfg(test)]
mod tests {
    #[test]
    fn a_start_on_a_bound_is_stepped_inward() {
        // On the lower bound, on the upper bound, inside: each pair 2·REL_STEP·scale apart,
        // both points within the range.
        let x0 = [0.5, 2.0, 1.0];
        let scale = [0.5, 2.0, 1.0];
        let bounds = [(0.5, 1.5), (0.0, 2.0), (0.0, 2.0)];
        let p = super::perturbed(&x0, &scale, &bounds);
        for i in 0..3 {
            let (plus, minus) = (p[2 * i][i], p[2 * i + 1][i]);
            assert!(
                (plus - minus - 2.0 * super::REL_STEP * scale[i]).abs() < 1e-12,
                "{i}"
            );
            assert!(
                minus >= bounds[i].0 && plus <= bounds[i].1,
                "{i}: {minus} {plus}"
            );
        }
        // Inside the range the centre is the start itself.
        assert_eq!(p[4][2], 1.0 + super::REL_STEP);
    }
}
