//! The optimiser interface and the generation loop.
//!
//! An [`Optimizer`] works in the unit box `[0, 1]^n` and is ask/tell: [`Optimizer::ask`]
//! proposes a generation of candidates, the caller evaluates them (in any order, on any
//! number of threads) and hands the costs back through [`Optimizer::tell`] in the order
//! asked. All random numbers are drawn inside `ask`/`tell` on the caller's thread, so a
//! seed fixes the result whatever the number of evaluation threads.
//!
//! A [`Problem`] knows nothing of the optimiser: bounds and a cost. [`minimize`] joins the
//! two: scaling from the unit box to the bounds, parallel evaluation with rayon, failures
//! turned into a penalty (their reason logged), per-generation callback (checkpoint,
//! progress, interruption).

use crate::error::OptimizeError;
use crate::failure::RunError;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;

/// An ask/tell optimiser over the unit box.
pub trait Optimizer: Send {
    /// Short name ("ga", "cmaes").
    fn name(&self) -> &'static str;
    fn dim(&self) -> usize;
    /// The next generation's candidates (each in `[0, 1]^n`).
    fn ask(&mut self) -> Vec<Vec<f64>>;
    /// The costs of the candidates of the last `ask`, in the same order (lower is better).
    fn tell(&mut self, costs: &[f64]);
    /// The best candidate evaluated so far and its cost.
    fn best(&self) -> Option<(&[f64], f64)>;
    /// Completed generations (tells).
    fn generation(&self) -> usize;
    /// The whole state (including the random generator), for a checkpoint.
    fn save(&self) -> serde_json::Value;
    /// Continue from a saved state.
    fn restore(&mut self, state: &serde_json::Value) -> Result<(), OptimizeError>;
}

/// An optimiser's state as [`Optimizer::save`] writes it into a checkpoint, read back by
/// [`restore_state`].
pub(crate) trait SavedState: serde::de::DeserializeOwned {
    /// The optimiser's name in messages ("GA", "CMA-ES").
    const LABEL: &'static str;
    /// Whether the state is of an optimiser with `dim` parameters.
    fn has_dim(&self, dim: usize) -> bool;
    /// Why a state of the right dimension cannot be used (a non-finite number, a misshapen
    /// matrix): the message up to the advice that follows it; `None` when it can.
    fn damage(&self, dim: usize) -> Option<String>;
}

/// [`Optimizer`]'s `generation`, `save` and `restore` of an optimiser whose whole state is
/// its field `s` (a [`SavedState`] with a `generation`), of `self.$dim` parameters.
macro_rules! state_methods {
    ($dim:ident) => {
        fn generation(&self) -> usize {
            self.s.generation
        }

        fn save(&self) -> serde_json::Value {
            crate::optimizer::save_state(&self.s)
        }

        fn restore(&mut self, state: &serde_json::Value) -> Result<(), OptimizeError> {
            self.s = crate::optimizer::restore_state(state, self.$dim)?;
            Ok(())
        }
    };
}
pub(crate) use state_methods;

/// An optimiser's state after one generation and a second optimiser that took it in: the
/// two ends of a checkpoint, for the tests that damage one.
#[cfg(test)]
pub(crate) fn saved_after_one_generation<O: Optimizer>(
    new: impl Fn() -> O,
) -> (serde_json::Value, O) {
    let mut first = new();
    let x = first.ask();
    first.tell(&vec![1.0; x.len()]);
    let good = first.save();
    let mut fresh = new();
    fresh.restore(&good).unwrap();
    (good, fresh)
}

/// The state as [`Optimizer::save`] writes it (it always serialises: plain numbers).
pub(crate) fn save_state<S: SavedState + Serialize>(s: &S) -> serde_json::Value {
    serde_json::to_value(s).unwrap_or_else(|e| panic!("{} state serialises: {e:?}", S::LABEL))
}

/// The one check of a restored optimiser state, before it replaces the running one: it
/// parses, it has the optimiser's dimension, and nothing in it is damaged (a damaged
/// checkpoint must not run a study of failed candidates to its end).
pub(crate) fn restore_state<S: SavedState>(
    state: &serde_json::Value,
    dim: usize,
) -> Result<S, OptimizeError> {
    let s: S = serde_json::from_value(state.clone())
        .map_err(|e| OptimizeError::Checkpoint(format!("{} state: {e}", S::LABEL)))?;
    if !s.has_dim(dim) {
        return Err(OptimizeError::Checkpoint(format!(
            "{} state has a different number of parameters",
            S::LABEL
        )));
    }
    if let Some(damage) = s.damage(dim) {
        return Err(OptimizeError::Checkpoint(format!(
            "{damage} (a damaged checkpoint: start without --resume)"
        )));
    }
    Ok(s)
}

/// Whether every number of `v` is finite.
pub(crate) fn all_finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// What is minimised: a cost over a box. `evaluate` is called from several threads at once;
/// `Err` is a failed evaluation (its text says why) that the driver penalises.
pub trait Problem: Sync {
    /// `(lower, upper)` per parameter, in the problem's own units.
    fn bounds(&self) -> Vec<(f64, f64)>;
    fn evaluate(&self, x: &[f64]) -> Result<f64, RunError>;
    /// A generation's candidates, results in the given order: by default on `pool`'s
    /// threads. A problem evaluated elsewhere (other processes, a cluster) overrides it;
    /// `Err` is a failure of that elsewhere, not of a candidate, and ends the run.
    fn evaluate_many(
        &self,
        pool: &rayon::ThreadPool,
        xs: &[Vec<f64>],
    ) -> Result<Vec<Result<f64, RunError>>, OptimizeError> {
        Ok(evaluate_all(pool, self, xs))
    }
}

/// A candidate's result as the generation loop takes it: a cost that is not finite is a
/// failure.
pub fn finite(r: Result<f64, RunError>) -> Result<f64, RunError> {
    match r {
        Ok(c) if c.is_finite() => Ok(c),
        Ok(c) => Err(RunError::NotFinite(c)),
        Err(e) => Err(e),
    }
}

/// From the unit box to the bounds.
pub fn to_bounds(u: &[f64], bounds: &[(f64, f64)]) -> Vec<f64> {
    u.iter()
        .zip(bounds)
        .map(|(&u, &(lo, hi))| lo + u.clamp(0.0, 1.0) * (hi - lo))
        .collect()
}

/// From the bounds to the unit box.
pub fn to_unit(x: &[f64], bounds: &[(f64, f64)]) -> Vec<f64> {
    x.iter()
        .zip(bounds)
        .map(|(&x, &(lo, hi))| {
            if hi > lo {
                ((x - lo) / (hi - lo)).clamp(0.0, 1.0)
            } else {
                0.5
            }
        })
        .collect()
}

/// Settings of the generation loop.
#[derive(Clone, Debug)]
pub struct RunSettings {
    /// Stop after this many generations in total (counting resumed ones).
    pub max_generations: usize,
    /// Evaluation threads (0: all cores).
    pub threads: usize,
    /// Cost given to a failed candidate.
    pub penalty: f64,
}

/// One generation's record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GenerationRecord {
    pub generation: usize,
    /// Evaluations so far (after this generation).
    pub evaluations: usize,
    pub best_cost: f64,
    pub best_x: Vec<f64>,
    /// Failed candidates in this generation.
    pub failures: usize,
}

/// The loop's own bookkeeping, checkpointed with the optimiser.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunState {
    pub evaluations: usize,
    pub failures: usize,
    pub history: Vec<GenerationRecord>,
    /// Reasons of failed candidates (the first few).
    pub failure_reasons: Vec<String>,
}

const MAX_REASONS: usize = 20;

/// The most evaluation threads a pool may have.
pub const MAX_THREADS: usize = 1024;

/// Builds the evaluation thread pool (0: all cores).
pub fn thread_pool(threads: usize) -> Result<rayon::ThreadPool, OptimizeError> {
    // More threads than candidates ever run at once only cost memory (a million threads
    // would exhaust the machine before the first lap).
    if threads > MAX_THREADS {
        return Err(OptimizeError::Threads(format!(
            "{threads} threads asked for: at most {MAX_THREADS} (this machine has {} cores; 0 uses them all)",
            std::thread::available_parallelism().map_or(1, |n| n.get())
        )));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("tb-eval-{i}"))
        .build()
        .map_err(|e| OptimizeError::Threads(e.to_string()))
}

/// Evaluates candidates (problem units) in parallel; results in the given order.
pub fn evaluate_all<P: Problem + ?Sized>(
    pool: &rayon::ThreadPool,
    problem: &P,
    xs: &[Vec<f64>],
) -> Vec<Result<f64, RunError>> {
    pool.install(|| {
        xs.par_iter()
            .with_max_len(1)
            .map(|x| finite(problem.evaluate(x)))
            .collect()
    })
}

/// Runs generations until `settings.max_generations`, or until `on_generation` breaks.
/// `state` carries the counters and history (empty for a fresh run, restored on resume).
/// Returns the best point (problem units) and its cost.
pub fn minimize<P: Problem + ?Sized>(
    optimizer: &mut dyn Optimizer,
    problem: &P,
    settings: &RunSettings,
    state: &mut RunState,
    mut on_generation: impl FnMut(&dyn Optimizer, &RunState) -> ControlFlow<()>,
) -> Result<(Vec<f64>, f64), OptimizeError> {
    let bounds = problem.bounds();
    if bounds.len() != optimizer.dim() {
        return Err(OptimizeError::Invalid(format!(
            "the optimiser has {} dimensions, the problem {}",
            optimizer.dim(),
            bounds.len()
        )));
    }
    let pool = thread_pool(settings.threads)?;
    while optimizer.generation() < settings.max_generations {
        let unit = optimizer.ask();
        let xs: Vec<Vec<f64>> = unit.iter().map(|u| to_bounds(u, &bounds)).collect();
        let results = problem.evaluate_many(&pool, &xs)?;
        let mut failures = 0;
        let costs: Vec<f64> = results
            .into_iter()
            .zip(&xs)
            .map(|(r, x)| match r {
                Ok(c) => c,
                Err(reason) => {
                    failures += 1;
                    let text = format!(
                        "candidate {x:?} failed (cost {}): {reason}",
                        settings.penalty
                    );
                    log::warn!("{text}");
                    if state.failure_reasons.len() < MAX_REASONS {
                        state.failure_reasons.push(text);
                    }
                    settings.penalty
                }
            })
            .collect();
        optimizer.tell(&costs);
        state.evaluations += xs.len();
        state.failures += failures;
        let (bu, bc) = optimizer
            .best()
            .map(|(x, c)| (x.to_vec(), c))
            .unwrap_or((vec![f64::NAN; bounds.len()], f64::INFINITY));
        state.history.push(GenerationRecord {
            generation: optimizer.generation(),
            evaluations: state.evaluations,
            best_cost: bc,
            best_x: to_bounds(&bu, &bounds),
            failures,
        });
        if on_generation(optimizer, state).is_break() {
            break;
        }
    }
    let (bu, bc) = optimizer
        .best()
        .map(|(x, c)| (x.to_vec(), c))
        .ok_or_else(|| OptimizeError::Invalid("no generation was evaluated".into()))?;
    Ok((to_bounds(&bu, &bounds), bc))
}
