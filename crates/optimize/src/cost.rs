//! The cost of a candidate: one comparison's cost over a step's signals ([`cost_of`]), and
//! a step's cost settings ([`StepCost`]), which the local evaluation, the bench's laps and
//! a remote worker share, so that all three compute the same cost to the bit.

use super::pool::WorkerPool;
use super::study::Study;
use tb_compare::{Comparison, PreparedMeasurement};

/// The cost of a comparison: Σ w·(e + β·|bias|) / Σ w over the step's signals.
pub fn cost_of(cmp: &Comparison, signals: &[String], weights: &[f64], bias_weight: f64) -> f64 {
    let mut num = 0.0;
    let mut den = 0.0;
    for (s, w) in signals.iter().zip(weights) {
        let m = match cmp.get(s) {
            Some(m) => m,
            None => return f64::NAN,
        };
        num += w * (m.e + bias_weight * m.bias.abs());
        den += w;
    }
    num / den
}

/// The cost of a step's comparison: its signals, their weights and the bias weight.
#[derive(Clone, Debug)]
pub struct StepCost {
    pub signals: Vec<String>,
    pub weights: Vec<f64>,
    pub bias_weight: f64,
}

impl StepCost {
    pub fn of_step(study: &Study, step: usize) -> Option<StepCost> {
        let s = study.file.steps.get(step)?;
        Some(StepCost {
            signals: s.signals.clone(),
            weights: s.weights(),
            bias_weight: s.bias_weight.unwrap_or(study.file.bias_weight),
        })
    }

    /// The cost of one run on the bench (the one function local and remote evaluation share).
    pub fn of(
        &self,
        workers: &WorkerPool,
        values: &[f64],
        prepared: &PreparedMeasurement,
    ) -> Result<f64, crate::RunError> {
        let o = workers.run(values, prepared)?;
        Ok(cost_of(
            &o.comparison,
            &self.signals,
            &self.weights,
            self.bias_weight,
        ))
    }
}
