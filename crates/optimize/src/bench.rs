//! The laps of a study on the bench: per lap its worker pool (its system, the study's and
//! its own parameter values) and its measurement. A candidate's cost is the laps' costs
//! weighted and summed, the laps run in parallel; a study of one lap is exactly the
//! single-lap cost.

use super::cost::{cost_of, StepCost};
use super::pool::{Outcome, WorkerPool};
use super::study::{Lap, Study};
use crate::error::OptimizeError;
use crate::failure::RunError;
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;
use tb_compare::{CompareSettings, Measurement, PreparedMeasurement, Workspace};
use tb_fmi::FmuCache;

/// Filtered signals on the distance grid: per signal the grid range covered and the values.
pub type GridSignals = Vec<(Range<usize>, Vec<f64>)>;

/// One lap: what it is, its workers, its measurement.
pub struct LapBench {
    pub lap: Lap,
    pub workers: WorkerPool,
    pub measurement: Measurement,
}

/// The fitted laps of a study (or its held-out ones).
pub struct Bench {
    pub laps: Vec<LapBench>,
}

impl Bench {
    /// The study's fitted laps (`hold_out`: its held-out laps instead), each system
    /// compiled and each measurement loaded.
    pub fn new(
        study: &Study,
        cache: Arc<FmuCache>,
        hold_out: bool,
    ) -> Result<Bench, OptimizeError> {
        let laps = study
            .laps
            .iter()
            .filter(|l| l.hold_out == hold_out)
            .map(|lap| {
                Ok(LapBench {
                    workers: WorkerPool::for_lap(study, lap, cache.clone())?,
                    // The measurement's error as the comparison's (it re-exports the reader).
                    measurement: Measurement::load(&lap.measurement_path, &lap.channels)
                        .map_err(tb_compare::Error::from)?,
                    lap: lap.clone(),
                })
            })
            .collect::<Result<Vec<_>, OptimizeError>>()?;
        Ok(Bench { laps })
    }

    /// The first lap's workers: the assignment, units and slots every lap shares.
    pub fn workers(&self) -> &WorkerPool {
        &self.laps[0].workers
    }

    /// Each lap's measurement prepared for `signals`.
    pub fn prepare<S: AsRef<str>>(
        &self,
        signals: &[S],
        compare: &CompareSettings,
    ) -> Result<Vec<PreparedMeasurement>, tb_compare::Error> {
        self.laps
            .iter()
            .map(|l| PreparedMeasurement::new(&l.measurement, signals, compare))
            .collect()
    }

    /// Σ weight · cost over the laps / Σ weight (the one lap's cost when there is one).
    pub fn weighted(&self, costs: &[f64]) -> f64 {
        if costs.len() == 1 {
            return costs[0];
        }
        let (mut num, mut den) = (0.0, 0.0);
        for (l, c) in self.laps.iter().zip(costs) {
            num += l.lap.weight * c;
            den += l.lap.weight;
        }
        num / den
    }

    /// A candidate's cost over every lap (laps in parallel); a lap that fails fails the
    /// candidate, naming the lap.
    pub fn cost(
        &self,
        cost: &StepCost,
        values: &[f64],
        prepared: &[PreparedMeasurement],
    ) -> Result<f64, RunError> {
        if self.laps.len() == 1 {
            return cost.of(&self.laps[0].workers, values, &prepared[0]);
        }
        let costs: Vec<f64> = self
            .outcomes(values, prepared)?
            .iter()
            .map(|o| {
                cost_of(
                    &o.comparison,
                    &cost.signals,
                    &cost.weights,
                    cost.bias_weight,
                )
            })
            .collect();
        Ok(self.weighted(&costs))
    }

    /// Every lap run with `values` and compared (laps in parallel), in the laps' order.
    pub fn outcomes(
        &self,
        values: &[f64],
        prepared: &[PreparedMeasurement],
    ) -> Result<Vec<Outcome>, RunError> {
        let runs: Vec<Result<Outcome, RunError>> = self
            .laps
            .par_iter()
            .zip(prepared)
            .with_max_len(1)
            .map(|(l, p)| {
                l.workers.run(values, p).map_err(|e| match self.laps.len() {
                    1 => e,
                    _ => RunError::Lap {
                        lap: l.lap.name.clone(),
                        error: Box::new(e),
                    },
                })
            })
            .collect();
        runs.into_iter().collect()
    }

    /// Every lap run with `values`, and its `signals` filtered on the grid: per lap and
    /// signal (laps outer) the grid range the lap covers and the values there. The joint
    /// fit's residuals, local or on an evaluator's worker.
    pub fn signals<S: AsRef<str>>(
        &self,
        values: &[f64],
        prepared: &[PreparedMeasurement],
        signals: &[S],
    ) -> Result<GridSignals, RunError> {
        let mut ws = Workspace::new();
        let mut out = Vec::with_capacity(prepared.len() * signals.len());
        for (o, p) in self.outcomes(values, prepared)?.iter().zip(prepared) {
            for s in signals {
                out.push(
                    p.on_grid(&o.table, s.as_ref(), true, &mut ws)
                        .map_err(|e| RunError::Table(Box::new(e)))?,
                );
            }
        }
        Ok(out)
    }

    /// Lap name for rows of several laps (`None` for a study of one lap).
    pub fn label(&self, k: usize) -> Option<String> {
        (self.laps.len() > 1).then(|| self.laps[k].lap.name.clone())
    }

    /// Simulations run and their summed wall time, over the laps.
    pub fn runs(&self) -> (usize, f64) {
        self.laps.iter().fold((0, 0.0), |(n, t), l| {
            let (a, b) = l.workers.runs();
            (n + a, t + b)
        })
    }

    pub fn workers_created(&self) -> usize {
        self.laps.iter().map(|l| l.workers.workers_created()).sum()
    }
}
