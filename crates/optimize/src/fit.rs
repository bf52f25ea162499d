//! The joint least-squares fit of a study's parameters: Levenberg–Marquardt steps from
//! finite-difference sensitivities, on every step's signals at once.
//!
//! **Why.** A study fits its parameters in steps (the paper's method): the lift
//! coefficients first with the geometry at its start values, then the geometry with the
//! lift coefficients held. Each step's answer is then biased by the values the other steps
//! had while it ran, and an interval around it (whatever its width) is centred on the wrong
//! point: on synthetic laps the sequential answer's 95 % intervals held the truth in 4 of
//! 12 laps for `c_lift_rear`. The refinement moves all parameters together to the minimum
//! of one objective, the weighted sum of squares the intervals rest on,
//!
//!   S(θ) = Σ_s (w_s / σ_s²) Σ_g (y_s,g(θ) − ŷ_s,g)²,
//!
//! y_s the twin's filtered signal s on the distance grid, ŷ_s the measured one, w_s its
//! weight in the study, σ_s² its mean squared residual at the sequential answer (held
//! fixed, so S is one function). Its minimum is where the sandwich of
//! [`crate::interval`] is valid: a stationary point of the same weighted residuals.
//!
//! **How.** Each iteration runs 2 laps per parameter (central differences, ±2 % of the
//! value) for J, solves (JᵀJ + λ·diag JᵀJ) δ = −Jᵀr on the directions the signals see (a
//! direction with an eigenvalue below 1e-9 of the largest gets no step), clamps to the
//! bounds (a parameter on a bound that the gradient pushes out is held there), and runs
//! two trial laps in one batch, with λ and 10λ: the first that lowers S is taken (λ/3),
//! else λ·100 and two more trials. It stops before any lap when the Gauss–Newton step
//! (λ = 0) would move no parameter by more than 0.3 of its standard error (the sandwich at
//! the current point: what is left is well inside the interval; [`ANSWER`] says why not
//! less), when an accepted step lowers S by less than 1e-7 of itself or was accepted only
//! at λ ≥ 1 (a step that short means the quadratic model no longer predicts the twin's S:
//! the rest is S's roughness), when λ exceeds 1e8
//! (no step lowers S: a minimum), or after [`MAX_ITERATIONS`]. The sensitivities at the
//! last point are the intervals' (no further laps).
//!
//! The same iteration with one parameter held re-optimises the others at a profile point
//! ([`crate::profile`]).

use super::block::Block;
use super::cmaes::symmetric_eigen;
use super::interval::REL_STEP;
use crate::failure::RunError;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// The method's name in results.
pub const METHOD: &str = "levenberg-marquardt";
/// Iterations at most (each 2 laps per free parameter and at least one trial lap).
pub const MAX_ITERATIONS: usize = 15;
const NULL_RATIO: f64 = 1e-9;
const RELATIVE_DECREASE: f64 = 1e-7;
const LAMBDA_START: f64 = 1e-5;
/// How far a fit goes: at most `max_iterations`, and converged when the Gauss–Newton step
/// is below `close` of every standard error.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Limits {
    pub max_iterations: usize,
    pub close: f64,
}

/// The study's answer: within 0.3 standard errors of the least-squares point. The twin's S
/// is rough at the level of a few units (a fixed-step simulation, the lap's end), and its
/// sensitivities by ±2 % differences see that: near the minimum the Gauss–Newton step
/// stays at 0.2–0.3 standard errors while the trials it proposes no longer lower S (the
/// demo's lap). A 0.3 σ offset changes a 95 % interval's coverage by less than a point.
pub(crate) const ANSWER: Limits = Limits {
    max_iterations: MAX_ITERATIONS,
    close: 0.3,
};
const LAMBDA_MAX: f64 = 1e8;
/// The damping at which an accepted step ends the fit (module doc): on the bundled lap the
/// iterations after the first such step moved the answer by 0.4 of a scatter standard
/// error in 36 laps, S by 0.03 %.
const LAMBDA_ROUGH: f64 = 1.0;

/// One residual block: a signal (of a lap) compared on the distance grid.
#[derive(Clone, Debug)]
pub(crate) struct Series<'a> {
    /// The signal's name (and lap), for messages.
    pub name: String,
    pub weight: f64,
    /// The measured signal on the grid.
    pub measured: &'a [f64],
    /// The lap: blocks of one lap share their grid indices in the long-run covariance;
    /// another lap's are independent of them.
    pub segment: usize,
}

/// A lap's signals on the grid, one (covered range, values) per [`Series`].
pub(crate) type Simulated = Result<crate::bench::GridSignals, RunError>;

/// Why a fit cannot start or go on: a lap that failed, or laps that do not cover what the
/// fit compares.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    #[error(transparent)]
    Run(#[from] RunError),
    #[error("the laps and the measurement share no stretch of {signal}")]
    NoSharedStretch { signal: String },
    #[error("a lap does not cover the compared stretch of {signal} (grid points {start}..{end})")]
    NotCovered {
        signal: String,
        start: usize,
        end: usize,
    },
    #[error("the twin matches the measurement exactly (no residual to weigh the signals by)")]
    ExactMatch,
}

/// Runs the laps at a batch of points, the results in the points' order: on this
/// process's threads ([`on_pool`]) or on an [`crate::Evaluator`]'s workers.
pub(crate) trait Laps: Fn(&[Vec<f64>]) -> Vec<Simulated> + Sync {}
impl<T: Fn(&[Vec<f64>]) -> Vec<Simulated> + Sync> Laps for T {}

/// The batch of laps on `pool`'s threads, one lap per thread at a time.
pub(crate) fn on_pool<'p, G>(pool: &'p rayon::ThreadPool, lap: G) -> impl Laps + 'p
where
    G: Fn(&[f64]) -> Simulated + Sync + 'p,
{
    move |points: &[Vec<f64>]| {
        pool.install(|| points.par_iter().with_max_len(1).map(|x| lap(x)).collect())
    }
}

/// The fixed frame of a fit: the series, the grid points each is compared on, and each
/// series' scale √w/σ.
pub(crate) struct Frame<'a, F> {
    pub series: Vec<Series<'a>>,
    ranges: Vec<Range<usize>>,
    scale: Vec<f64>,
    pub bounds: Vec<(f64, f64)>,
    simulate: F,
    laps: std::sync::atomic::AtomicUsize,
    /// The laps' clocks (per lap, the time at each grid point) and the time bin: the
    /// sandwich then also estimates the noise in time ([`crate::noise_time`]).
    clocks: Option<(Vec<Vec<f64>>, f64)>,
    /// Per series, what is added to the measurement on its range (a bootstrap's
    /// replicate, [`crate::bootstrap`]); `None`: the measurement as it is.
    shift: Option<Vec<Vec<f64>>>,
}

/// The residuals (simulated − measured) of every series on its range at one point.
type Raw = Vec<Vec<f64>>;

/// A new frame with the residuals and the sensitivities at its start point.
type Started<'a, F> = (Frame<'a, F>, Raw, Vec<Option<Raw>>);

/// Where a fit ended.
#[derive(Clone, Debug)]
pub(crate) struct Solution {
    pub x: Vec<f64>,
    /// S at `x`.
    pub objective: f64,
    pub iterations: usize,
    /// Laps this fit ran (its trials and sensitivities; not those of its start).
    pub laps: usize,
    pub converged: bool,
    /// Why it stopped when not converged, in words.
    pub statement: Option<String>,
    /// The residuals and the sensitivities (∂y/∂θ_i per grid point, `None` for a held
    /// parameter) at `x`.
    pub(crate) raw: Raw,
    pub(crate) sensitivities: Vec<Option<Raw>>,
}

/// A study's refinement as results carry it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// [`METHOD`].
    pub method: String,
    pub parameters: Vec<String>,
    /// The signals (with their weights) the objective sums.
    pub signals: Vec<String>,
    pub weights: Vec<f64>,
    /// The sequential answer and the refined one, bit-exact.
    #[serde(with = "super::exact::vec")]
    pub before: Vec<f64>,
    #[serde(with = "super::exact::vec")]
    pub after: Vec<f64>,
    /// S (module doc) at both, divided by the grid points compared (1 at the start).
    pub objective_before: f64,
    pub objective_after: f64,
    pub iterations: usize,
    pub laps: usize,
    pub converged: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub statement: Option<String>,
}

/// Where a Levenberg–Marquardt descent stands: the point, its residuals and
/// sensitivities, its S, the damping λ, the laps run, and why it stopped early (if it did).
struct Descent {
    x: Vec<f64>,
    raw: Raw,
    sens: Vec<Option<Raw>>,
    s: f64,
    lambda: f64,
    laps: usize,
    statement: Option<String>,
}

/// What an iteration's damped steps came to.
enum Stride {
    /// A step was taken: the next iteration starts from it.
    Taken,
    /// No step is left to take, or the last one was short: the fit is done.
    Converged,
    /// A lap for the sensitivities failed: the fit stops where it is (the statement says
    /// why).
    Stopped,
}

impl<'a, F: Laps> Frame<'a, F> {
    /// The frame around `x0`: one lap at `x0` and 2 per parameter for the grid points every
    /// one of them covers (less a margin of 2 % of the stretch at each end, so that laps
    /// further away still cover them), and σ_s from the residuals at `x0`. Returns the
    /// frame with the sensitivities at `x0` (the first iteration's).
    pub fn new(
        series: Vec<Series<'a>>,
        bounds: Vec<(f64, f64)>,
        x0: &[f64],
        simulate: F,
    ) -> Result<Started<'a, F>, FitError> {
        let p = x0.len();
        let mut points = vec![x0.to_vec()];
        points.extend(
            around(x0, &bounds, &vec![true; p])
                .into_iter()
                .map(|(_, y)| y),
        );
        let runs: Vec<Vec<(Range<usize>, Vec<f64>)>> = simulate(&points)
            .into_iter()
            .collect::<Result<_, RunError>>()?;
        let mut ranges = Vec::new();
        for (b, s) in series.iter().enumerate() {
            let lo = runs.iter().map(|r| r[b].0.start).max().unwrap_or(0);
            let hi = runs
                .iter()
                .map(|r| r[b].0.end)
                .min()
                .unwrap_or(0)
                .min(s.measured.len());
            let margin = (hi.saturating_sub(lo)) / 50;
            let (lo, hi) = (lo + margin, hi.saturating_sub(margin));
            if hi <= lo + 2 {
                return Err(FitError::NoSharedStretch {
                    signal: s.name.clone(),
                });
            }
            ranges.push(lo..hi);
        }
        let mut frame = Frame {
            series,
            ranges,
            scale: Vec::new(),
            bounds,
            simulate,
            laps: std::sync::atomic::AtomicUsize::new(points.len()),
            clocks: None,
            shift: None,
        };
        let raws: Vec<Raw> = runs
            .iter()
            .map(|r| frame.raw(r))
            .collect::<Result<_, _>>()?;
        frame.scale = frame
            .series
            .iter()
            .zip(&raws[0])
            .map(|(s, e)| {
                let var = e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64;
                (s.weight / var).sqrt()
            })
            .collect();
        if frame.scale.iter().any(|c| !c.is_finite()) {
            return Err(FitError::ExactMatch);
        }
        let sens = frame.sensitivities(x0, &raws[1..], &vec![true; p]);
        let raw0 = raws.into_iter().next().expect("the lap at x0");
        Ok((frame, raw0, sens))
    }

    /// Laps run so far.
    pub fn laps(&self) -> usize {
        self.laps.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Grid points compared, over all series.
    pub fn points(&self) -> usize {
        self.ranges.iter().map(|r| r.len()).sum()
    }

    /// A lap's residuals on the frame's ranges (an error when it does not cover them).
    fn raw(&self, run: &[(Range<usize>, Vec<f64>)]) -> Result<Raw, FitError> {
        self.series
            .iter()
            .zip(&self.ranges)
            .zip(run)
            .enumerate()
            .map(|(b, ((s, want), (got, y)))| {
                if got.start > want.start || got.end < want.end {
                    return Err(FitError::NotCovered {
                        signal: s.name.clone(),
                        start: want.start,
                        end: want.end,
                    });
                }
                let shift = self.shift.as_ref().map(|shift| &shift[b]);
                Ok(want
                    .clone()
                    .map(|g| {
                        let e = y[g - got.start] - s.measured[g];
                        shift.map_or(e, |d| e - d[g - want.start])
                    })
                    .collect())
            })
            .collect()
    }

    /// Shifts the measurement of every series by `shift` (on its range), or puts it back.
    pub fn set_shift(&mut self, shift: Option<Vec<Vec<f64>>>) {
        self.shift = shift;
    }

    /// The residuals `raw` resampled in moving blocks of `block` grid points: per lap one
    /// draw of block starts over the lap's stretch, the same for every series of the lap.
    pub fn resample(&self, raw: &Raw, block: usize, rng: &mut crate::rng::Rng) -> Raw {
        let mut out: Raw = raw.clone();
        let mut segments: Vec<usize> = self.series.iter().map(|s| s.segment).collect();
        segments.sort_unstable();
        segments.dedup();
        for seg in segments {
            let of: Vec<usize> = (0..self.series.len())
                .filter(|&b| self.series[b].segment == seg)
                .collect();
            let lo = of.iter().map(|&b| self.ranges[b].start).min().unwrap_or(0);
            let hi = of.iter().map(|&b| self.ranges[b].end).max().unwrap_or(0);
            let len = hi - lo;
            let block = block.clamp(1, len.max(1));
            let mut idx = Vec::with_capacity(len + block);
            while idx.len() < len {
                let start = lo + rng.below(len - block + 1);
                idx.extend(start..start + block);
            }
            idx.truncate(len);
            for &b in &of {
                let r = &self.ranges[b];
                for g in r.clone() {
                    let src = idx[g - lo];
                    out[b][g - r.start] = if r.contains(&src) {
                        raw[b][src - r.start]
                    } else {
                        raw[b][g - r.start]
                    };
                }
            }
        }
        out
    }

    pub fn objective(&self, raw: &Raw) -> f64 {
        raw.iter()
            .zip(&self.scale)
            .map(|(e, c)| c * c * e.iter().map(|e| e * e).sum::<f64>())
            .sum()
    }

    /// Runs the laps at `points` in parallel; their residuals.
    fn run(&self, points: &[Vec<f64>]) -> Vec<Result<Raw, FitError>> {
        self.laps
            .fetch_add(points.len(), std::sync::atomic::Ordering::Relaxed);
        (self.simulate)(points)
            .into_iter()
            .map(|r| r.map_err(FitError::from).and_then(|r| self.raw(&r)))
            .collect()
    }

    /// The sensitivities from the laps around `x` (2 per free parameter, in
    /// [`around`]'s order).
    fn sensitivities(&self, x: &[f64], raws: &[Raw], free: &[bool]) -> Vec<Option<Raw>> {
        let steps = around(x, &self.bounds, free);
        let mut out = vec![None; x.len()];
        for (k, pair) in steps.chunks(2).enumerate() {
            let i = pair[0].0;
            let h = pair[0].1[i] - pair[1].1[i];
            let (plus, minus) = (&raws[2 * k], &raws[2 * k + 1]);
            out[i] = Some(
                plus.iter()
                    .zip(minus)
                    .map(|(a, b)| a.iter().zip(b).map(|(a, b)| (a - b) / h).collect())
                    .collect(),
            );
        }
        out
    }

    /// The sensitivities at `x` for the `free` parameters: 2 laps each.
    fn sensitivities_at(&self, x: &[f64], free: &[bool]) -> Result<Vec<Option<Raw>>, FitError> {
        let points: Vec<Vec<f64>> = around(x, &self.bounds, free)
            .into_iter()
            .map(|(_, y)| y)
            .collect();
        let raws: Vec<Raw> = self.run(&points).into_iter().collect::<Result<_, _>>()?;
        Ok(self.sensitivities(x, &raws, free))
    }

    /// Levenberg–Marquardt from `x0` (its residuals and sensitivities given) with the
    /// parameters where `free` is false held.
    pub fn minimise(
        &self,
        x0: &[f64],
        raw0: Raw,
        sens0: Vec<Option<Raw>>,
        free: &[bool],
        limits: Limits,
    ) -> Solution {
        let span: Vec<f64> = self.bounds.iter().map(|(lo, hi)| hi - lo).collect();
        let s = self.objective(&raw0);
        let mut at = Descent {
            x: x0.to_vec(),
            raw: raw0,
            sens: sens0,
            s,
            lambda: LAMBDA_START,
            laps: 0,
            statement: None,
        };
        let mut converged = false;
        let mut iterations = 0;
        while iterations < limits.max_iterations {
            iterations += 1;
            // Normal equations in range-scaled parameters.
            let (a, g) = self.normal_equations(&at.raw, &at.sens, &span);
            let active = self.active(&at.x, &g, free, &span);
            if active.is_empty() || self.close_enough(&at, &a, &g, &active, &span, limits) {
                converged = true;
                break;
            }
            match self.stride(&mut at, &a, &g, &active, free, &span) {
                Stride::Taken => {}
                Stride::Converged => {
                    converged = true;
                    break;
                }
                Stride::Stopped => break,
            }
        }
        let Descent {
            x,
            raw,
            sens,
            s,
            laps,
            mut statement,
            ..
        } = at;
        if !converged && statement.is_none() {
            statement = Some(format!(
                "not converged after {} iterations (S still falling)",
                limits.max_iterations
            ));
        }
        Solution {
            x,
            objective: s,
            iterations,
            laps,
            converged,
            statement,
            raw,
            sensitivities: sens,
        }
    }

    /// The free parameters the descent may move at `x` (`g` the gradient): a parameter on a
    /// bound that the descent pushes out stays there.
    fn active(&self, x: &[f64], g: &[f64], free: &[bool], span: &[f64]) -> Vec<usize> {
        (0..x.len())
            .filter(|&i| free[i])
            .filter(|&i| {
                let (lo, hi) = self.bounds[i];
                let tol = 1e-12 * span[i];
                !((x[i] - lo <= tol && g[i] > 0.0) || (hi - x[i] <= tol && g[i] < 0.0))
            })
            .collect()
    }

    /// Close enough: the Gauss–Newton step (λ = 0) moves no parameter by more than
    /// `limits.close` of its standard error (the sandwich at this point, no laps; 0.3 for
    /// the answer, 0.25 for a profile's points): what is left is far inside the interval,
    /// and more laps would not change the answer.
    fn close_enough(
        &self,
        at: &Descent,
        a: &[Vec<f64>],
        g: &[f64],
        active: &[usize],
        span: &[f64],
        limits: Limits,
    ) -> bool {
        let Some(gn) = solve(a, g, active, 0.0) else {
            return false;
        };
        let se = self.std_errors(&at.x, &at.raw, &at.sens);
        active
            .iter()
            .zip(&gn)
            .all(|(&i, d)| se[i].is_some_and(|se| (d * span[i]).abs() <= limits.close * se))
    }

    /// One iteration's damped steps from `at`: λ and 10λ tried in one batch, the first that
    /// lowers S taken (with the sensitivities there); where both are worse, shorter steps
    /// (λ × 100) until one is taken or the damping runs out.
    fn stride(
        &self,
        at: &mut Descent,
        a: &[Vec<f64>],
        g: &[f64],
        active: &[usize],
        free: &[bool],
        span: &[f64],
    ) -> Stride {
        loop {
            // Two trials in one batch (both cores busy): λ and 10λ, the first that
            // lowers S taken.
            let mut trials = Vec::new();
            for l in [at.lambda, 10.0 * at.lambda] {
                let Some(delta) = solve(a, g, active, l) else {
                    continue;
                };
                let mut trial = at.x.clone();
                for (k, &i) in active.iter().enumerate() {
                    let (lo, hi) = self.bounds[i];
                    trial[i] = (at.x[i] + delta[k] * span[i]).clamp(lo, hi);
                }
                if trial != at.x {
                    trials.push((l, trial));
                }
            }
            if trials.is_empty() {
                return Stride::Converged;
            }
            let points: Vec<Vec<f64>> = trials.iter().map(|t| t.1.clone()).collect();
            at.laps += points.len();
            let s = at.s;
            let accepted = trials
                .into_iter()
                .zip(self.run(&points))
                .find_map(|((l, trial), r)| match r {
                    Ok(r) if self.objective(&r) < s => Some((l, trial, r)),
                    _ => None,
                });
            match accepted {
                Some((l, trial, r)) => {
                    let s_new = self.objective(&r);
                    let small = at.s - s_new <= RELATIVE_DECREASE * at.s;
                    at.laps += 2 * free.iter().filter(|&&f| f).count();
                    match self.sensitivities_at(&trial, free) {
                        Ok(j) => {
                            (at.x, at.raw, at.sens, at.s) = (trial, r, j, s_new);
                        }
                        Err(e) => {
                            at.statement = Some(format!(
                                "stopped: a lap for the sensitivities at an accepted point failed ({e})"
                            ));
                            return Stride::Stopped;
                        }
                    }
                    at.lambda = (l / 3.0).max(1e-12);
                    // A step accepted only at λ ≥ 1 is far shorter than the
                    // Gauss–Newton one: the quadratic model no longer predicts S, and
                    // what is left of the way is S's roughness, not its minimum.
                    if small || l >= LAMBDA_ROUGH {
                        return Stride::Converged;
                    }
                    return Stride::Taken;
                }
                // Both worse, or laps that failed or fell short of the stretch: shorter
                // steps.
                None => {
                    at.lambda *= 100.0;
                    if at.lambda > LAMBDA_MAX {
                        return Stride::Converged;
                    }
                }
            }
        }
    }

    /// JᵀJ and Jᵀr of the scaled residuals, in range-scaled parameters (0 rows and columns
    /// for held parameters).
    fn normal_equations(
        &self,
        raw: &Raw,
        sens: &[Option<Raw>],
        span: &[f64],
    ) -> (Vec<Vec<f64>>, Vec<f64>) {
        let p = sens.len();
        let mut a = vec![vec![0.0; p]; p];
        let mut g = vec![0.0; p];
        for (b, c) in self.scale.iter().enumerate() {
            let c2 = c * c;
            for n in 0..raw[b].len() {
                let e = raw[b][n];
                for i in 0..p {
                    let Some(ji) = &sens[i] else { continue };
                    let ji = ji[b][n] * span[i];
                    g[i] += c2 * ji * e;
                    for j in 0..=i {
                        let Some(jj) = &sens[j] else { continue };
                        a[i][j] += c2 * ji * jj[b][n] * span[j];
                    }
                }
            }
        }
        // The upper triangle from the lower.
        let lower = a.clone();
        for (j, row) in a.iter_mut().enumerate() {
            for (i, x) in row.iter_mut().enumerate().skip(j + 1) {
                *x = lower[i][j];
            }
        }
        (a, g)
    }

    /// Each parameter's standard error at `x` from the sandwich (`None`: held, or not
    /// determined).
    fn std_errors(&self, x: &[f64], raw: &Raw, sens: &[Option<Raw>]) -> Vec<Option<f64>> {
        let free: Vec<usize> = (0..x.len()).filter(|&i| sens[i].is_some()).collect();
        let blocks = self.blocks_of(raw, sens);
        let names: Vec<String> = free.iter().map(|i| i.to_string()).collect();
        let xf: Vec<f64> = free.iter().map(|&i| x[i]).collect();
        let bf: Vec<(f64, f64)> = free.iter().map(|&i| self.bounds[i]).collect();
        let iv = self.sandwich(&names, &xf, &bf, &blocks, 0);
        let mut out = vec![None; x.len()];
        for (k, &i) in free.iter().enumerate() {
            out[i] = iv.parameters[k].std_error;
        }
        out
    }

    /// The residuals and the forward-difference sensitivities of the `free` parameters at
    /// `x`: 1 + 1 per free parameter laps, in one batch.
    pub fn start(&self, x: &[f64], free: &[bool]) -> Result<(Raw, Vec<Option<Raw>>), FitError> {
        let forward = forward_points(x, &self.bounds, free);
        let mut points = vec![x.to_vec()];
        points.extend(forward.iter().map(|(_, y)| y.clone()));
        let mut raws: Vec<Raw> = self.run(&points).into_iter().collect::<Result<_, _>>()?;
        let rest = raws.split_off(1);
        let raw = raws.pop().expect("the lap at x");
        let sens = forward_sensitivities(x, &raw, &forward, &rest);
        Ok((raw, sens))
    }

    /// At a solution (every parameter free): the naive covariance (JᵀWJ)⁻¹, as if every
    /// grid point were independent, and the sandwich variance of each parameter, both in
    /// the parameters' own units (0 where not determined).
    pub fn covariances(&self, solution: &Solution) -> (Vec<Vec<f64>>, Vec<f64>) {
        let p = solution.x.len();
        let span: Vec<f64> = self.bounds.iter().map(|(lo, hi)| hi - lo).collect();
        let (a, _) = self.normal_equations(&solution.raw, &solution.sensitivities, &span);
        let (vals, vecs) = symmetric_eigen(&a);
        let top = vals.iter().cloned().fold(0.0f64, f64::max);
        let mut naive = vec![vec![0.0; p]; p];
        for (k, &l) in vals.iter().enumerate() {
            if top.is_nan() || top <= 0.0 || l <= NULL_RATIO * top {
                continue;
            }
            for i in 0..p {
                for j in 0..p {
                    naive[i][j] += vecs[i][k] * vecs[j][k] / l * span[i] * span[j];
                }
            }
        }
        let se = self.std_errors(&solution.x, &solution.raw, &solution.sensitivities);
        (naive, se.iter().map(|s| s.map_or(0.0, |s| s * s)).collect())
    }

    /// Gives the frame the laps' clocks (per lap, the measured time at each grid point) and
    /// the width of a time bin, for the noise in time ([`crate::noise_time`]).
    pub fn set_clocks(&mut self, times: Vec<Vec<f64>>, bin_s: f64) {
        self.clocks = Some((times, bin_s));
    }

    /// The sandwich intervals of `blocks` ([`crate::interval::sandwich_with`], with the
    /// frame's clocks where it has them).
    pub fn sandwich(
        &self,
        names: &[String],
        x: &[f64],
        bounds: &[(f64, f64)],
        blocks: &[Block],
        laps: usize,
    ) -> super::interval::Intervals {
        let clocks = self
            .clocks
            .as_ref()
            .map(|(times, bin_s)| crate::noise_time::Clocks {
                times,
                bin_s: *bin_s,
            });
        super::interval::sandwich_with(names, x, bounds, blocks, laps, clocks.as_ref())
    }

    /// The objective per compared grid point (1 where every residual is at its σ).
    pub fn per_point(&self, objective: f64) -> f64 {
        objective / self.points() as f64
    }

    /// The blocks the intervals' sandwich takes: at a solution, every series' residuals and
    /// its sensitivities to the free parameters (in `free`'s order).
    pub fn blocks(&self, solution: &Solution) -> Vec<Block> {
        self.blocks_of(&solution.raw, &solution.sensitivities)
    }

    fn blocks_of(&self, raw: &Raw, sens: &[Option<Raw>]) -> Vec<Block> {
        let free: Vec<&Raw> = sens.iter().flatten().collect();
        self.series
            .iter()
            .enumerate()
            .map(|(b, s)| Block {
                start: self.ranges[b].start,
                segment: s.segment,
                residual: raw[b].clone(),
                rows: (0..raw[b].len())
                    .map(|n| free.iter().map(|j| j[b][n]).collect())
                    .collect(),
                weight: s.weight,
                factor: Some(self.scale[b] * self.scale[b]),
            })
            .collect()
    }
}

/// The points 2 per free parameter, ±[`REL_STEP`] of its value (of its range at 0), moved
/// inside the bounds: (parameter, point) in pairs (+, −).
fn around(x: &[f64], bounds: &[(f64, f64)], free: &[bool]) -> Vec<(usize, Vec<f64>)> {
    let mut out = Vec::new();
    for i in (0..x.len()).filter(|&i| free[i]) {
        let (lo, hi) = bounds[i];
        let h = REL_STEP
            * if x[i].abs() > 1e-12 {
                x[i].abs()
            } else {
                hi - lo
            };
        // A central difference that stays inside the range: shifted off a bound.
        let centre = x[i].clamp(lo + h, hi - h);
        let centre = if lo + h <= hi - h { centre } else { x[i] };
        for sign in [1.0, -1.0] {
            let mut y = x.to_vec();
            y[i] = centre + sign * h;
            out.push((i, y));
        }
    }
    out
}

/// One point per free parameter, +[`REL_STEP`] of its value (− on its upper bound).
fn forward_points(x: &[f64], bounds: &[(f64, f64)], free: &[bool]) -> Vec<(usize, Vec<f64>)> {
    (0..x.len())
        .filter(|&i| free[i])
        .map(|i| {
            let (lo, hi) = bounds[i];
            let h = REL_STEP
                * if x[i].abs() > 1e-12 {
                    x[i].abs()
                } else {
                    hi - lo
                };
            let mut y = x.to_vec();
            y[i] = if x[i] + h <= hi { x[i] + h } else { x[i] - h };
            (i, y)
        })
        .collect()
}

/// Forward-difference sensitivities at `x` (its residuals `raw`) from the laps at
/// [`forward_points`].
fn forward_sensitivities(
    x: &[f64],
    raw: &Raw,
    points: &[(usize, Vec<f64>)],
    raws: &[Raw],
) -> Vec<Option<Raw>> {
    let mut out = vec![None; x.len()];
    for ((i, y), r) in points.iter().zip(raws) {
        let h = y[*i] - x[*i];
        out[*i] = Some(
            r.iter()
                .zip(raw)
                .map(|(a, b)| a.iter().zip(b).map(|(a, b)| (a - b) / h).collect())
                .collect(),
        );
    }
    out
}

/// (JᵀJ + λ·diag) δ = −g on the `active` parameters, by eigen-decomposition; directions
/// with an eigenvalue below [`NULL_RATIO`] of the largest get no step. `None`: no direction
/// left (nothing to move).
fn solve(a: &[Vec<f64>], g: &[f64], active: &[usize], lambda: f64) -> Option<Vec<f64>> {
    let m = active.len();
    let sub: Vec<Vec<f64>> = active
        .iter()
        .map(|&i| {
            active
                .iter()
                .map(|&j| a[i][j] + if i == j { lambda * a[i][i] } else { 0.0 })
                .collect()
        })
        .collect();
    let (vals, vecs) = symmetric_eigen(&sub);
    let top = vals.iter().cloned().fold(0.0f64, f64::max);
    if !(top.is_finite() && top > 0.0) {
        return None;
    }
    let mut delta = vec![0.0; m];
    for (k, &l) in vals.iter().enumerate() {
        if l <= NULL_RATIO * top {
            continue;
        }
        let proj: f64 = (0..m).map(|r| vecs[r][k] * g[active[r]]).sum();
        for (r, d) in delta.iter_mut().enumerate() {
            *d -= vecs[r][k] * proj / l;
        }
    }
    Some(delta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_curve;

    /// A two-parameter curve y = a·exp(−b·t) fitted from a wrong start: the fit finds the
    /// least-squares point, which a second start reaches as well (both within 0.3 standard
    /// errors of it).
    #[test]
    fn levenberg_marquardt_finds_the_least_squares_point_of_a_curve() {
        let n = 400;
        let t: Vec<f64> = (0..n).map(|g| g as f64 / 100.0).collect();
        let noise: Vec<f64> = (0..n)
            .map(|g| 0.01 * ((g * 7919) % 13) as f64 - 0.06)
            .collect();
        let measured = test_curve::measured_decay(&t, &noise);
        let pool = test_curve::pool(2);
        let simulate = |x: &[f64]| test_curve::simulate_decay(&t, x);
        let fit = |x0: [f64; 2]| {
            let series = vec![Series {
                name: "y".into(),
                weight: 1.0,
                measured: &measured,
                segment: 0,
            }];
            let bounds = vec![(0.1, 10.0), (0.01, 5.0)];
            let (frame, raw, sens) =
                Frame::new(series, bounds, &x0, on_pool(&pool, simulate)).unwrap();
            let sol = frame.minimise(&x0, raw, sens, &[true, true], ANSWER);
            assert!(sol.converged, "{sol:?}");
            let (_, var) = frame.covariances(&sol);
            (sol.x, [var[0].sqrt(), var[1].sqrt()])
        };
        let (a, se) = fit([1.0, 0.3]);
        let (b, _) = fit([3.5, 1.5]);
        assert!(
            (a[0] - 2.0).abs() < 0.02 && (a[1] - 0.7).abs() < 0.02,
            "{a:?}"
        );
        // Each start ends within 0.3 standard errors of the least-squares point.
        for k in 0..2 {
            assert!(
                (a[k] - b[k]).abs() < 0.6 * se[k],
                "{a:?} vs {b:?} (σ {se:?})"
            );
        }
    }

    /// A parameter whose optimum lies beyond its bound ends on the bound.
    #[test]
    fn a_parameter_the_data_push_past_its_bound_stays_on_it() {
        let n = 200;
        let t: Vec<f64> = (0..n).map(|g| g as f64 / 50.0).collect();
        let measured: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(g, t)| 3.0 * t + 0.01 * ((g % 5) as f64 - 2.0))
            .collect();
        let pool = test_curve::pool(1);
        let simulate =
            |x: &[f64]| -> Simulated { Ok(vec![(0..n, t.iter().map(|t| x[0] * t).collect())]) };
        let series = vec![Series {
            name: "y".into(),
            weight: 1.0,
            measured: &measured,
            segment: 0,
        }];
        let (frame, raw, sens) =
            Frame::new(series, vec![(0.5, 2.0)], &[1.0], on_pool(&pool, simulate)).unwrap();
        let sol = frame.minimise(&[1.0], raw, sens, &[true], ANSWER);
        assert_eq!(sol.x, vec![2.0]);
        assert!(sol.converged);
    }
}
