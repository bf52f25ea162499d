//! How sure a step's fitted parameters are: a confidence interval for each, at the optimum,
//! from the same kind of sensitivities the identifiability check computes.
//!
//! **The method** (`"gauss-newton-hac"`). Around the step's best point every parameter is
//! moved by ±2 % of its value and the step's filtered signals are differenced centrally on
//! the distance grid: J_s, the sensitivity of signal s to each parameter, in the
//! parameter's own unit. With the residuals at the optimum, e_s = simulated − measured,
//! each signal's variance σ_s² = mean(e_s²), and its weight w_s from the study:
//!
//! - the Gauss–Newton information ("bread") B = Σ_s w_s J_sᵀ J_s / σ_s²;
//! - the scores u_g = Σ_s w_s J_s(g)ᵀ e_s(g) / σ_s² at each grid point g, and their long-run
//!   covariance ("meat") M = Σ_{|k|≤L} (1 − |k|/(L+1)) Σ_g u_g u_{g+k}ᵀ (Newey–West, Bartlett
//!   weights);
//! - the covariance of the estimate C = B⁻¹ M B⁻¹ (the sandwich), and the interval
//!   θ̂ ± z·√C_ii (z = 1.96 at 95 %).
//!
//! Why the sandwich with a long-run covariance rather than σ²·B⁻¹: filtered signals on a 1 m
//! grid are far from independent (a residual persists through a corner), and signals of one
//! step overlap (Fz_sum is Fz_front + Fz_rear). Counting every grid point of every signal as
//! an independent observation would make the intervals too narrow by the square root of the
//! residuals' correlation length in samples. The autocovariance of the scores up to lag L
//! carries both: for one signal with slowly varying sensitivities it is the effective sample
//! size N/τ, τ the integrated autocorrelation time of the residuals. L is taken from the
//! data: twice the lag at which the scores' autocorrelation first falls below 0.05 (at least
//! 10 grid points, at most an eighth of the grid, which is then said in the notes).
//!
//! **What is not a number.** A parameter the signals cannot see (the information has a
//! direction with an eigenvalue below 1e-9 of the largest, and the parameter takes part in
//! it) gets no interval, and so does one on a bound of its range (the optimum is then not a
//! stationary point: the data want it beyond). An interval end beyond a bound is open
//! (`None`): the range contains that whole side. A grid too short to estimate the
//! autocorrelation (fewer than 8 × 10 points) is said too. Each such case carries a
//! statement in words.

use crate::block::Block;
use crate::failure::RunError;
use crate::long_run::{scores_meat, MIN_BANDWIDTH};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use tb_compare::{PreparedMeasurement, Table, Workspace};

/// The name of the method in results (`interval_method`).
pub const METHOD: &str = "gauss-newton-hac";
/// Two-sided 95 % quantile of the normal distribution.
pub const Z95: f64 = 1.959_963_984_540_054;

/// The two-sided 95 % critical value of a t statistic whose variance is a Bartlett
/// long-run estimate of bandwidth ratio b = (L+1)/n (Kiefer & Vogelsang's fixed-b
/// asymptotics, their polynomial fit for the Bartlett kernel). The estimate is noisy and
/// biased low when L is a sizeable part of the grid (the scores sum to zero at the
/// optimum), and the normal 1.96 then covers less than 95 %: 2.34 at b = 1/8. Checked
/// against a simulation in this module's tests.
pub fn critical_value(b: f64) -> f64 {
    let b = b.clamp(0.0, 1.0);
    Z95 + 2.9694 * b + 0.4160 * b * b - 0.5324 * b * b * b
}
/// Each parameter's step for the sensitivities, relative to its value (or its range).
pub(crate) const REL_STEP: f64 = 0.02;
/// An information eigenvalue below this fraction of the largest: a direction not seen.
const NULL_RATIO: f64 = 1e-9;
/// A parameter closer to a bound than this fraction of its range is on the bound.
const ON_BOUND: f64 = 1e-6;
/// At least this many correlation lengths of grid for the long-run covariance.
const MIN_LENGTHS: usize = 8;

/// One parameter's interval.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterInterval {
    pub name: String,
    pub value: f64,
    /// The interval's ends; `None` where the interval is open (past the parameter's range,
    /// or no interval at all).
    pub lo: Option<f64>,
    pub hi: Option<f64>,
    /// The standard error (None: not determined): `std_error_noise` where it is known.
    pub std_error: Option<f64>,
    /// The standard error from the scores' own long-run covariance, and from the residuals'
    /// autocovariance in time ([`crate::noise_time`]), where the laps' clocks were known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_error_scores: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_error_noise: Option<f64>,
    /// Why there is no interval, or no end, in words (None: a closed interval).
    pub statement: Option<String>,
}

impl ParameterInterval {
    /// `0.8164 [0.8010, 0.8318]`, `2.7416 [open, 3.9]`, or the statement.
    pub fn shown(&self, unit: Option<&str>) -> String {
        let u = unit.map(|u| format!(" {u}")).unwrap_or_default();
        let end = |e: Option<f64>| e.map_or("open".to_string(), |x| format!("{x:.4}"));
        match (self.lo, self.hi, self.std_error) {
            (None, None, None) => format!("{:.4}{u} (no interval)", self.value),
            (Some(lo), Some(hi), Some(_)) if self.value != 0.0 => format!(
                "{:.4}{u} [{}, {}] (±{:.1} %)",
                self.value,
                end(self.lo),
                end(self.hi),
                50.0 * (hi - lo) / self.value.abs()
            ),
            _ => format!("{:.4}{u} [{}, {}]", self.value, end(self.lo), end(self.hi)),
        }
    }
}

fn z95() -> f64 {
    Z95
}

/// The intervals of a step, with what they rest on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intervals {
    /// [`METHOD`].
    pub method: String,
    /// The confidence level (0.95).
    pub level: f64,
    pub parameters: Vec<ParameterInterval>,
    /// The grid points used and the Bartlett bandwidth L of the long-run covariance [m of
    /// grid steps].
    pub grid_points: usize,
    pub bandwidth: usize,
    /// Laps run for the sensitivities.
    pub laps: usize,
    /// The critical value the intervals use ([`critical_value`]; 1.96 in results written
    /// before it was kept).
    #[serde(default = "z95")]
    pub critical_value: f64,
    /// Statements about the whole step (a failed run, a short grid).
    pub notes: Vec<String>,
    /// The covariance of the estimates, in the parameters' units, in their order (empty in
    /// results written before it was kept, and where there is no interval).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub covariance: Vec<Vec<f64>>,
    /// Their correlation (the covariance scaled by the standard errors; `None` where a
    /// parameter has no spread).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub correlation: Vec<Vec<Option<f64>>>,
}

impl Intervals {
    /// The interval of a parameter by name.
    pub fn get(&self, name: &str) -> Option<&ParameterInterval> {
        self.parameters.iter().find(|p| p.name == name)
    }

    /// Intervals that could not be computed at all: every parameter without one, with why.
    pub(crate) fn none(names: &[String], x: &[f64], why: String, laps: usize) -> Intervals {
        Intervals {
            method: METHOD.into(),
            level: 0.95,
            parameters: names
                .iter()
                .zip(x)
                .map(|(n, &v)| ParameterInterval {
                    name: n.clone(),
                    value: v,
                    lo: None,
                    hi: None,
                    std_error: None,
                    std_error_scores: None,
                    std_error_noise: None,
                    statement: Some(why.clone()),
                })
                .collect(),
            grid_points: 0,
            bandwidth: 0,
            laps,
            critical_value: Z95,
            notes: vec![why],
            covariance: Vec::new(),
            correlation: Vec::new(),
        }
    }
}

/// The intervals of a step at its best point `x` (within `bounds`): 2 laps per parameter on
/// `pool`, each made by `run`; `best` is the lap at `x` itself (already run by the step).
#[allow(clippy::too_many_arguments)]
pub(crate) fn at_optimum(
    names: &[String],
    signals: &[String],
    weights: &[f64],
    x: &[f64],
    bounds: &[(f64, f64)],
    prepared: &PreparedMeasurement,
    best: &Table,
    pool: &rayon::ThreadPool,
    run: impl Fn(&[f64]) -> Result<Table, RunError> + Sync,
) -> Intervals {
    let p = x.len();
    let h: Vec<f64> = x
        .iter()
        .zip(bounds)
        .map(|(&v, &(lo, hi))| REL_STEP * if v.abs() > 1e-12 { v.abs() } else { hi - lo })
        .collect();
    let points: Vec<Vec<f64>> = (0..2 * p)
        .map(|j| {
            let mut y = x.to_vec();
            y[j / 2] += if j % 2 == 0 { h[j / 2] } else { -h[j / 2] };
            y
        })
        .collect();
    let laps = points.len();
    let runs = super::identifiability::signals_on_grid(&points, signals, prepared, pool, run);
    let mut ws = Workspace::new();
    let at_best: Result<Vec<_>, RunError> = signals
        .iter()
        .map(|s| {
            prepared
                .on_grid(best, s, true, &mut ws)
                .map_err(|e| RunError::Table(Box::new(e)))
        })
        .collect();
    let (runs, at_best) = match (runs.into_iter().collect::<Result<Vec<_>, _>>(), at_best) {
        (Ok(r), Ok(b)) => (r, b),
        (Err(e), _) | (_, Err(e)) => {
            return Intervals::none(
                names,
                x,
                format!("no interval: a lap for the sensitivities failed ({e})"),
                laps,
            )
        }
    };
    // Per signal: the grid points every lap covers, the residual there and J's rows.
    let mut blocks = Vec::new();
    for (s, name) in signals.iter().enumerate() {
        // The stretch every lap covers: the latest start to the earliest end.
        let covered = runs.iter().map(|r| &r[s].0).chain([&at_best[s].0]);
        let lo = covered.clone().map(|c| c.start).max().unwrap_or(0);
        let hi = covered.map(|c| c.end).min().unwrap_or(0);
        let meas = prepared.measured(name).unwrap_or(&[]);
        let hi = hi.min(meas.len());
        if hi <= lo + 2 {
            return Intervals::none(
                names,
                x,
                format!("no interval: the laps and the measurement share no stretch of {name}"),
                laps,
            );
        }
        let at = |r: &(Range<usize>, Vec<f64>), g: usize| r.1[g - r.0.start];
        let residual: Vec<f64> = (lo..hi).map(|g| at(&at_best[s], g) - meas[g]).collect();
        let rows: Vec<Vec<f64>> = (lo..hi)
            .map(|g| {
                (0..p)
                    .map(|i| (at(&runs[2 * i][s], g) - at(&runs[2 * i + 1][s], g)) / (2.0 * h[i]))
                    .collect()
            })
            .collect();
        blocks.push(Block {
            start: lo,
            residual,
            rows,
            weight: weights[s],
            factor: None,
            segment: 0,
        });
    }
    sandwich(names, x, bounds, &blocks, laps)
}

/// The sandwich covariance from the signals' blocks, and the intervals from it.
pub(crate) fn sandwich(
    names: &[String],
    x: &[f64],
    bounds: &[(f64, f64)],
    blocks: &[Block],
    laps: usize,
) -> Intervals {
    sandwich_with(names, x, bounds, blocks, laps, None)
}

/// The sandwich, and where the laps' `clocks` are known, with the meat from the residuals'
/// autocovariance in time ([`crate::noise_time`]), the scores' own long-run covariance
/// kept beside it (`std_error_scores`).
pub(crate) fn sandwich_with(
    names: &[String],
    x: &[f64],
    bounds: &[(f64, f64)],
    blocks: &[Block],
    laps: usize,
    clocks: Option<&crate::noise_time::Clocks>,
) -> Intervals {
    let p = x.len();
    // Work in parameters scaled by their range, for a well-conditioned information.
    let span: Vec<f64> = bounds
        .iter()
        .map(|(lo, hi)| (hi - lo).max(1e-300))
        .collect();
    let (segments, extents) = segments_of(blocks);
    // The shortest segment decides whether the autocorrelation can be estimated at all;
    // all of them together are the fixed-b ratio's n (independent laps add to the long-run
    // estimate's degrees of freedom as one lap of their summed length would).
    let n = extents.iter().map(|(a, b)| b - a).min().unwrap_or(0);
    let n_all = extents.iter().map(|(a, b)| b - a).sum::<usize>();
    let Some((bread, scores)) = bread_and_scores(blocks, &segments, &extents, &span) else {
        // A perfect fit (a synthetic lap without noise): no spread to scale by.
        return Intervals::none(
            names,
            x,
            "no interval: the twin matches the measurement exactly (no residual to estimate the spread from)".into(),
            laps,
        );
    };
    let mut notes = Vec::new();
    if n < MIN_LENGTHS * MIN_BANDWIDTH {
        let why = format!(
            "no interval: the compared stretch ({n} grid points) is shorter than {MIN_LENGTHS} correlation lengths of the residuals (at least {MIN_BANDWIDTH} points each), too short to estimate their autocorrelation"
        );
        return Intervals::none(names, x, why, laps);
    }
    let (meat, bandwidth) = scores_meat(&scores, n, p, &mut notes);
    let (inv, unseen, top) = inverse_on_seen(&bread, p);
    if top <= 0.0 {
        notes.push("the signals do not see any of the step's parameters".into());
    }
    let cov = mul(&mul(&inv, &meat), &inv);
    let factor = |b: &Block| {
        b.factor.unwrap_or_else(|| {
            let m = b.residual.len() as f64;
            b.weight / (b.residual.iter().map(|e| e * e).sum::<f64>() / m)
        })
    };
    let in_time = clocks.and_then(|c| crate::noise_time::meat(blocks, &span, factor, c));
    let cov_noise = in_time.as_ref().map(|t| mul(&mul(&inv, &t.meat), &inv));
    if in_time.as_ref().is_some_and(|t| t.capped) {
        notes.push(
            "the residuals stay correlated beyond a quarter of the lap in time: their autocovariance is cut there, and the intervals may be narrower than the data warrant".into(),
        );
    }
    // The noise in time where it could be estimated; the scores' own beside it.
    let cov_scores = cov;
    let cov = cov_noise.clone().unwrap_or_else(|| cov_scores.clone());
    let cv = critical_value((bandwidth + 1) as f64 / n_all as f64);
    let spread = Spread {
        cov: &cov,
        cov_scores: &cov_scores,
        cov_noise: cov_noise.as_deref(),
        span: &span,
        cv,
    };
    let parameters = (0..p)
        .map(|i| parameter_interval(i, names, x, bounds, unseen[i], &spread))
        .collect();
    let (covariance, correlation) = in_units(&cov, &span, p);
    Intervals {
        method: METHOD.into(),
        level: 0.95,
        parameters,
        grid_points: extents.iter().map(|(a, b)| b - a).sum(),
        bandwidth,
        laps,
        critical_value: cv,
        notes,
        covariance,
        correlation,
    }
}

/// The blocks' segments (a lap each), in order, and each one's extent on the grid: its
/// blocks' grid points, from the first start to the last end.
fn segments_of(blocks: &[Block]) -> (Vec<usize>, Vec<(usize, usize)>) {
    let mut segments: Vec<usize> = blocks.iter().map(|b| b.segment).collect();
    segments.sort_unstable();
    segments.dedup();
    let extent = |seg: usize| {
        let of = blocks.iter().filter(|b| b.segment == seg);
        let start = of.clone().map(|b| b.start).min().unwrap_or(0);
        let end = of.map(|b| b.start + b.residual.len()).max().unwrap_or(0);
        (start, end)
    };
    let extents: Vec<(usize, usize)> = segments.iter().map(|&g| extent(g)).collect();
    (segments, extents)
}

/// The information and the scores per segment (a lap) at each of its grid points.
type BreadAndScores = (Vec<Vec<f64>>, Vec<Vec<Vec<f64>>>);

/// The information ("bread") and the scores per segment (a lap) at each of its grid
/// points, summed where signals share one, in range-scaled parameters. Segments are
/// independent: the long-run covariance sums within each. `None` where a block's residual
/// has no spread to scale by.
fn bread_and_scores(
    blocks: &[Block],
    segments: &[usize],
    extents: &[(usize, usize)],
    span: &[f64],
) -> Option<BreadAndScores> {
    let p = span.len();
    let mut bread = vec![vec![0.0; p]; p];
    let mut scores: Vec<Vec<Vec<f64>>> = extents
        .iter()
        .map(|(a, b)| vec![vec![0.0; p]; b - a])
        .collect();
    for b in blocks {
        let g = segments.binary_search(&b.segment).expect("listed");
        let (start, _) = extents[g];
        let m = b.residual.len() as f64;
        let var = b.residual.iter().map(|e| e * e).sum::<f64>() / m;
        if !(var.is_finite() && var > 0.0) {
            return None;
        }
        let c = b.factor.unwrap_or(b.weight / var);
        for (k, (row, e)) in b.rows.iter().zip(&b.residual).enumerate() {
            let row: Vec<f64> = row.iter().zip(span).map(|(j, s)| j * s).collect();
            for i in 0..p {
                scores[g][b.start - start + k][i] += c * row[i] * e;
                for j in 0..p {
                    bread[i][j] += c * row[i] * row[j];
                }
            }
        }
    }
    Some((bread, scores))
}

/// B⁻¹ on the directions the signals see; a parameter in a direction they do not see has
/// no interval. The inverse, each parameter's largest share in an unseen direction, and
/// the information's largest eigenvalue.
fn inverse_on_seen(bread: &[Vec<f64>], p: usize) -> (Vec<Vec<f64>>, Vec<f64>, f64) {
    let (vals, vecs) = super::cmaes::symmetric_eigen(bread);
    let top = vals.iter().cloned().fold(0.0f64, f64::max);
    let mut unseen = vec![0.0f64; p];
    let mut inv = vec![vec![0.0; p]; p];
    for (k, &l) in vals.iter().enumerate() {
        if top <= 0.0 || top.is_nan() || l <= NULL_RATIO * top {
            for (i, u) in unseen.iter_mut().enumerate() {
                *u = u.max(vecs[i][k].abs());
            }
            continue;
        }
        for i in 0..p {
            for j in 0..p {
                inv[i][j] += vecs[i][k] * vecs[j][k] / l;
            }
        }
    }
    (inv, unseen, top)
}

/// What a parameter's interval is read from: the covariances of the estimate in
/// range-scaled parameters (the one the intervals use, the scores' own, the noise in
/// time's where it was estimated), the ranges and the critical value.
struct Spread<'a> {
    cov: &'a [Vec<f64>],
    cov_scores: &'a [Vec<f64>],
    cov_noise: Option<&'a [Vec<f64>]>,
    span: &'a [f64],
    cv: f64,
}

/// Parameter i's interval, or why it has none: not seen by the signals (`unseen`, its
/// largest share in a direction they do not see), on a bound, or open on a side.
fn parameter_interval(
    i: usize,
    names: &[String],
    x: &[f64],
    bounds: &[(f64, f64)],
    unseen: f64,
    spread: &Spread,
) -> ParameterInterval {
    let Spread {
        cov,
        cov_scores,
        cov_noise,
        span,
        cv,
    } = *spread;
    let (lo_b, hi_b) = bounds[i];
    let range = format!("[{}, {}]", tb_files::number(lo_b), tb_files::number(hi_b));
    let bare = |statement: String| ParameterInterval {
        name: names[i].clone(),
        value: x[i],
        lo: None,
        hi: None,
        std_error: None,
        std_error_scores: None,
        std_error_noise: None,
        statement: Some(statement),
    };
    if unseen > 0.1 {
        return bare(format!(
            "not determined by these signals within {range}: the information has a direction they do not see, and this parameter is in it"
        ));
    }
    let tol = ON_BOUND * (hi_b - lo_b);
    if x[i] - lo_b <= tol || hi_b - x[i] <= tol {
        let which = if x[i] - lo_b <= tol { "lower" } else { "upper" };
        return bare(format!(
            "on its {which} bound ({}): the optimum is not inside the range, so no interval; the data want it beyond {range}",
            tb_files::number(if which == "lower" { lo_b } else { hi_b })
        ));
    }
    let se = cov[i][i].max(0.0).sqrt() * span[i];
    let std_error_scores = cov_noise
        .as_ref()
        .map(|_| cov_scores[i][i].max(0.0).sqrt() * span[i]);
    let std_error_noise = cov_noise
        .as_ref()
        .map(|c| c[i][i].max(0.0).sqrt() * span[i]);
    let (lo, hi) = (x[i] - cv * se, x[i] + cv * se);
    let (lo, hi) = ((lo >= lo_b).then_some(lo), (hi <= hi_b).then_some(hi));
    let statement = match (lo, hi) {
        (None, None) => Some(format!("not determined by these signals within {range}")),
        (None, Some(_)) => Some(format!(
            "open below: any value down to the bound {} fits",
            tb_files::number(lo_b)
        )),
        (Some(_), None) => Some(format!(
            "open above: any value up to the bound {} fits",
            tb_files::number(hi_b)
        )),
        _ => None,
    };
    ParameterInterval {
        name: names[i].clone(),
        value: x[i],
        lo,
        hi,
        std_error: Some(se),
        std_error_scores,
        std_error_noise,
        statement,
    }
}

/// The covariance in the parameters' own units (from the range-scaled `cov`), and the
/// correlation (the covariance scaled by the standard errors; `None` where a parameter
/// has no spread).
fn in_units(cov: &[Vec<f64>], span: &[f64], p: usize) -> (Vec<Vec<f64>>, Vec<Vec<Option<f64>>>) {
    let covariance: Vec<Vec<f64>> = (0..p)
        .map(|i| (0..p).map(|j| cov[i][j] * span[i] * span[j]).collect())
        .collect();
    let correlation: Vec<Vec<Option<f64>>> = (0..p)
        .map(|i| {
            (0..p)
                .map(|j| {
                    let d = (covariance[i][i] * covariance[j][j]).sqrt();
                    (d > 0.0).then(|| covariance[i][j] / d)
                })
                .collect()
        })
        .collect();
    (covariance, correlation)
}

fn mul(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let p = a.len();
    (0..p)
        .map(|i| {
            (0..p)
                .map(|j| (0..p).map(|k| a[i][k] * b[k][j]).sum())
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block from row 0 of segment 0, weight 1 and no factor.
    fn block_of(residual: Vec<f64>, rows: Vec<Vec<f64>>) -> Block {
        Block {
            start: 0,
            residual,
            rows,
            weight: 1.0,
            factor: None,
            segment: 0,
        }
    }

    /// A standard normal number: Box–Muller from a small LCG (deterministic).
    fn gauss(seed: &mut u64) -> f64 {
        let mut u = || {
            *seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((*seed >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (a, b) = (u(), u());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }

    /// y = a + b·t on a grid with AR(1) noise of correlation ρ: the interval of b covers
    /// its truth about 95 % of the time, where the interval that counts every point as
    /// independent covers far less.
    #[test]
    fn ar1_noise_on_a_line_is_covered_at_the_level() {
        // A residual that persists for 50 points, as a logged load's on the 1 m grid.
        let (n, rho, truth) = (4000usize, 0.98f64, [1.0, 0.5]);
        let mut seed = 12345u64;
        let mut gauss = || gauss(&mut seed);
        let t: Vec<f64> = (0..n).map(|g| g as f64 / n as f64).collect();
        let (mut covered, mut naive_covered, cases) = (0, 0, 200);
        let mut z = Vec::with_capacity(cases);
        for _ in 0..cases {
            let mut e = 0.0;
            let y: Vec<f64> = t
                .iter()
                .map(|&t| {
                    e = rho * e + (1.0 - rho * rho).sqrt() * gauss();
                    truth[0] + truth[1] * t + 0.1 * e
                })
                .collect();
            // Least squares fit.
            let (st, sy) = (t.iter().sum::<f64>(), y.iter().sum::<f64>());
            let stt = t.iter().map(|t| t * t).sum::<f64>();
            let sty = t.iter().zip(&y).map(|(t, y)| t * y).sum::<f64>();
            let nf = n as f64;
            let b = (nf * sty - st * sy) / (nf * stt - st * st);
            let a = (sy - b * st) / nf;
            let block = block_of(
                t.iter().zip(&y).map(|(t, y)| a + b * t - y).collect(),
                t.iter().map(|&t| vec![1.0, t]).collect(),
            );
            let names = vec!["a".to_string(), "b".to_string()];
            let iv = sandwich(
                &names,
                &[a, b],
                &[(-10.0, 10.0), (-10.0, 10.0)],
                &[block],
                0,
            );
            let pb = &iv.parameters[1];
            z.push((b - truth[1]) / pb.std_error.expect("a standard error"));
            let (lo, hi) = (pb.lo.expect("an interval"), pb.hi.expect("an interval"));
            if lo <= truth[1] && truth[1] <= hi {
                covered += 1;
            }
            // Every point independent: σ²(XᵀX)⁻¹.
            let var = y
                .iter()
                .zip(&t)
                .map(|(y, t)| (y - a - b * t).powi(2))
                .sum::<f64>()
                / nf;
            let se_naive = (var * nf / (nf * stt - st * st)).sqrt();
            if (b - truth[1]).abs() <= Z95 * se_naive {
                naive_covered += 1;
            }
        }
        let share = covered as f64 / cases as f64;
        let naive = naive_covered as f64 / cases as f64;
        let sd = (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        eprintln!(
            "AR(1) ρ = {rho}: coverage {share} (every point independent: {naive}), sd(z) {sd:.3}"
        );
        assert!(share >= 0.9, "coverage {share}");
        // The standard error itself calibrated (not only the critical value): the
        // standardised errors spread as a standard normal's, within [0.8, 1.25].
        assert!((0.8..=1.25).contains(&sd), "sd(z) {sd}");
        assert!(naive < 0.6, "the naive interval covered {naive}");
    }

    /// The fixed-b critical value against a simulation: the mean of n = 400 white-noise
    /// samples, its t statistic with the Bartlett long-run variance (the same weights as
    /// the sandwich) at L + 1 = b·n; the simulated 95 % quantile of |t| within 0.06 of the
    /// polynomial, and far from 1.96 at b = 1/8.
    #[test]
    fn the_fixed_b_critical_value_matches_a_simulation() {
        let (n, cases) = (400usize, 20000usize);
        let mut seed = 99u64;
        let mut gauss = || gauss(&mut seed);
        for b in [0.05, 0.125, 0.2] {
            let l = (b * n as f64).round() as usize - 1;
            let mut t: Vec<f64> = (0..cases)
                .map(|_| {
                    let x: Vec<f64> = (0..n).map(|_| gauss()).collect();
                    let m = x.iter().sum::<f64>() / n as f64;
                    let u: Vec<f64> = x.iter().map(|x| x - m).collect();
                    let mut omega: f64 = u.iter().map(|u| u * u).sum();
                    for k in 1..=l {
                        let w = 1.0 - k as f64 / (l + 1) as f64;
                        omega += 2.0 * w * (0..n - k).map(|g| u[g] * u[g + k]).sum::<f64>();
                    }
                    (m * n as f64).abs() / omega.sqrt()
                })
                .collect();
            t.sort_by(f64::total_cmp);
            let q = t[(0.95 * cases as f64) as usize];
            let cv = critical_value(b);
            eprintln!("b = {b}: simulated {q:.3}, polynomial {cv:.3}");
            assert!(
                (q - cv).abs() < 0.06,
                "b = {b}: simulated {q}, polynomial {cv}"
            );
        }
        assert!(critical_value(0.125) > 2.3);
    }

    #[test]
    fn an_unseen_parameter_and_one_on_its_bound_get_a_statement_not_a_number() {
        // y = a·t + 0·c: c is not seen; and a fit with b on its bound.
        let n = 500;
        let t: Vec<f64> = (0..n).map(|g| g as f64 / n as f64).collect();
        let block = block_of(
            t.iter().map(|t| 0.01 * (37.0 * t).sin()).collect(),
            t.iter().map(|&t| vec![t, 0.0]).collect(),
        );
        let names = vec!["a".to_string(), "vehicle.l".to_string()];
        let iv = sandwich(&names, &[1.0, 3.0], &[(0.0, 2.0), (2.0, 4.5)], &[block], 4);
        assert!(iv.parameters[0].lo.is_some() && iv.parameters[0].hi.is_some());
        let l = &iv.parameters[1];
        assert_eq!((l.lo, l.hi, l.std_error), (None, None, None));
        assert!(
            l.statement
                .as_deref()
                .unwrap()
                .starts_with("not determined by these signals within [2, 4.5]"),
            "{l:?}"
        );
        assert_eq!(l.shown(Some("m")), "3.0000 m (no interval)");
        let block = block_of(
            t.iter().map(|t| 0.01 * (37.0 * t).sin()).collect(),
            t.iter().map(|&t| vec![t, 1.0]).collect(),
        );
        let iv = sandwich(&names, &[1.0, 2.0], &[(0.0, 2.0), (2.0, 4.5)], &[block], 4);
        let l = &iv.parameters[1];
        assert!(
            l.statement
                .as_deref()
                .unwrap()
                .starts_with("on its lower bound (2)"),
            "{l:?}"
        );
        assert!(l.lo.is_none() && l.hi.is_none());
    }

    #[test]
    fn a_short_grid_and_a_perfect_fit_are_said_not_computed() {
        let rows: Vec<Vec<f64>> = (0..30).map(|g| vec![g as f64]).collect();
        let names = vec!["a".to_string()];
        let short = block_of(
            (0..30).map(|g| ((g / 10) as f64) - 1.0).collect(),
            rows.clone(),
        );
        let iv = sandwich(&names, &[1.0], &[(0.0, 2.0)], &[short], 2);
        assert!(
            iv.notes[0].contains("too short to estimate their autocorrelation"),
            "{iv:?}"
        );
        let exact = block_of(vec![0.0; 30], rows);
        let iv = sandwich(&names, &[1.0], &[(0.0, 2.0)], &[exact], 2);
        assert!(
            iv.notes[0].contains("matches the measurement exactly"),
            "{iv:?}"
        );
        assert!(iv.parameters[0].lo.is_none());
    }
}
