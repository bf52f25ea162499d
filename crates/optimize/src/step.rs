//! One step of a study as a session runs it: its cost over the bench (the [`Problem`] its
//! optimiser minimises, evaluated here or on a remote evaluator), its seed, its generations
//! and its optimiser.

use super::bench::Bench;
use super::checkpoint::StepStart;
use super::cmaes::Cmaes;
use super::cost::{cost_of, StepCost};
use super::ga::Ga;
use super::optimizer::{evaluate_all, finite, Optimizer, Problem, RunState};
use super::pool::Outcome;
use super::remote::{Candidate, Evaluator};
use super::session::Session;
use super::study::{OptimizerKind, StepConfig, Study};
use crate::error::OptimizeError;
use crate::failure::{EvaluatorError, RunError};
use tb_compare::{Comparison, PreparedMeasurement};

/// One step's cost over the bench.
pub(crate) struct StepProblem<'a> {
    pub(crate) bench: &'a Bench,
    /// Each lap's measurement prepared for the step's signals.
    pub(crate) prepared: &'a [PreparedMeasurement],
    /// The step (0-based) and its cost.
    pub(crate) step: usize,
    pub(crate) cost: StepCost,
    /// Every parameter of the study with its current value.
    pub(crate) assignment: Vec<(String, f64)>,
    /// Indices into `assignment` of the step's parameters.
    pub(crate) index: Vec<usize>,
    pub(crate) bounds: Vec<(f64, f64)>,
    /// Where generations are evaluated when not on this process's threads.
    pub(crate) remote: Option<&'a dyn Evaluator>,
}

impl StepProblem<'_> {
    /// Every parameter's value with the step's parameters at `x`.
    pub(crate) fn params(&self, x: &[f64]) -> Vec<f64> {
        let mut a: Vec<f64> = self.assignment.iter().map(|p| p.1).collect();
        for (k, &i) in self.index.iter().enumerate() {
            a[i] = x[k];
        }
        a
    }

    /// Puts the step's parameters at `x` in the assignment the step starts from.
    pub(crate) fn set(&mut self, x: &[f64]) {
        for (j, &i) in self.index.iter().enumerate() {
            self.assignment[i].1 = x[j];
        }
    }

    /// The first lap's run (what the identifiability check and a step's own intervals
    /// look at).
    pub(crate) fn outcome(&self, x: &[f64]) -> Result<Outcome, RunError> {
        self.bench.workers().run(&self.params(x), &self.prepared[0])
    }

    /// Every lap's run.
    pub(crate) fn outcomes(&self, x: &[f64]) -> Result<Vec<Outcome>, RunError> {
        self.bench.outcomes(&self.params(x), self.prepared)
    }

    /// The step's cost of every lap's comparison, weighted.
    pub(crate) fn cost_of_laps(&self, config: &StepConfig, comparisons: &[&Comparison]) -> f64 {
        let weights = config.weights();
        let costs: Vec<f64> = comparisons
            .iter()
            .map(|c| cost_of(c, &config.signals, &weights, self.cost.bias_weight))
            .collect();
        self.bench.weighted(&costs)
    }
}

impl Problem for StepProblem<'_> {
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.bounds.clone()
    }

    fn evaluate(&self, x: &[f64]) -> Result<f64, RunError> {
        self.bench.cost(&self.cost, &self.params(x), self.prepared)
    }

    fn evaluate_many(
        &self,
        pool: &rayon::ThreadPool,
        xs: &[Vec<f64>],
    ) -> Result<Vec<Result<f64, RunError>>, OptimizeError> {
        let Some(remote) = self.remote else {
            return Ok(evaluate_all(pool, self, xs));
        };
        let candidates: Vec<Candidate> = xs
            .iter()
            .map(|x| Candidate {
                step: self.step,
                values: self.params(x),
            })
            .collect();
        let results = remote
            .evaluate(&candidates)
            .map_err(OptimizeError::Evaluator)?;
        if results.len() != xs.len() {
            return Err(OptimizeError::Evaluator(EvaluatorError::Results {
                results: results.len(),
                candidates: xs.len(),
            }));
        }
        Ok(results.into_iter().map(finite).collect())
    }
}

fn step_seed(seed: u64, step: usize) -> u64 {
    seed ^ (step as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

pub(crate) fn make_optimizer(
    study: &Study,
    kind: OptimizerKind,
    dim: usize,
    seed: u64,
    start: Vec<f64>,
) -> Result<Box<dyn Optimizer>, OptimizeError> {
    let o = &study.file.optimizer;
    Ok(match kind {
        OptimizerKind::Ga => Box::new(Ga::new(dim, o.ga.clone(), seed, Some(start))?),
        OptimizerKind::Cmaes => Box::new(Cmaes::new(dim, o.cmaes.clone(), seed, Some(start))?),
    })
}

/// One step as this session runs it: its configuration, seed and generations, and its
/// cost over the bench.
pub(crate) struct Step<'a> {
    pub(crate) config: &'a StepConfig,
    pub(crate) seed: u64,
    pub(crate) generations: usize,
    pub(crate) problem: StepProblem<'a>,
}

impl<'a> Step<'a> {
    /// Step `k` with its parameters at `index` in `assignment` (every parameter's value
    /// after the earlier steps) and the measurement prepared for its signals.
    pub(crate) fn new(
        session: &'a Session,
        k: usize,
        index: Vec<usize>,
        prepared: &'a [PreparedMeasurement],
        assignment: Vec<(String, f64)>,
    ) -> Step<'a> {
        let (study, options) = (session.study, session.options);
        let config = &study.file.steps[k];
        Step {
            config,
            seed: step_seed(study.file.seed, k),
            generations: options
                .generations
                .or(config.generations)
                .unwrap_or(study.file.optimizer.generations),
            problem: StepProblem {
                bench: &session.bench,
                prepared,
                step: k,
                cost: StepCost::of_step(study, k).expect("a step of the study"),
                assignment,
                index,
                bounds: config.parameters.iter().map(|p| (p.min, p.max)).collect(),
                remote: options.evaluator.as_deref(),
            },
        }
    }
}

/// A step ready for its generations: what it knew before the first one, the optimiser and
/// the generation loop's bookkeeping (restored from the checkpoint, or new).
pub(crate) struct StepBegun {
    pub(crate) start: StepStart,
    pub(crate) optimizer: Box<dyn Optimizer>,
    pub(crate) run: RunState,
}
