//! What a study records: each step's result (its parameters' and signals' changes, its
//! generations, its intervals), the joint answer over all steps, the laps a report draws,
//! and the whole result as a serialisable value; and how a run ended ([`StudyOutcome`]).

use super::exact;
use super::fit::Refinement;
use super::identifiability::Identifiability;
use super::optimizer::GenerationRecord;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use tb_compare::{Metrics, Table};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterChange {
    pub name: String,
    /// The variable's unit (absent in results written before units were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    pub min: f64,
    pub max: f64,
    pub before: f64,
    pub after: f64,
    pub change_percent: f64,
    /// The 95 % confidence interval of `after`: [lo, hi], an end `None` (JSON null) where
    /// it is open; absent when there is none (the statement says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval: Option<(Option<f64>, Option<f64>)>,
    /// How the interval was computed ([`crate::interval::METHOD`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval_method: Option<String>,
    /// Why the interval is open or missing, in words.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval_statement: Option<String>,
    /// The standard error of `after` (absent where there is no interval).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_error: Option<f64>,
    /// The interval that includes the twin's share of the error as well as the scatter
    /// ([`crate::model_check`]): the one to quote where the model check finds the twin
    /// wanting; [lo, hi], an end `None` where it is open.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval_with_model: Option<(Option<f64>, Option<f64>)>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SignalChange {
    /// The lap, in a study of several (absent for one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lap: Option<String>,
    pub signal: String,
    pub weight: f64,
    pub before: Metrics,
    pub after: Metrics,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepResult {
    pub step: usize,
    pub name: String,
    pub signals: Vec<String>,
    pub bias_weight: f64,
    pub optimizer: String,
    pub seed: u64,
    pub parameters: Vec<ParameterChange>,
    pub e: Vec<SignalChange>,
    pub cost_before: f64,
    pub cost_after: f64,
    pub identifiability: Identifiability,
    pub history: Vec<GenerationRecord>,
    pub evaluations: usize,
    pub failures: usize,
    pub failure_reasons: Vec<String>,
    /// Each parameter's 95 % confidence interval at the step's optimum (absent in results
    /// written before intervals were computed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intervals: Option<crate::interval::Intervals>,
    /// The parameter values after the step, bit-exact (the next step starts from them).
    #[serde(with = "exact::vec")]
    pub after_exact: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StudyResult {
    pub study: String,
    pub system: PathBuf,
    pub measurement: PathBuf,
    pub seed: u64,
    pub threads: usize,
    /// The comparison's settings (filter, grid): `twinbench validate` compares another lap
    /// the same way (absent in results written before they were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compare: Option<tb_compare::CompareSettings>,
    pub steps: Vec<StepResult>,
    /// The 95 % intervals of all the study's fitted parameters together at its answer
    /// (each step's own are conditional on the other steps' values).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_intervals: Option<crate::interval::Intervals>,
    /// The study's answer for all its parameters together: the refinement, each parameter
    /// from before its step to the answer, each signal at the start and at the answer
    /// (absent in results written before it was made).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<JointResult>,
    /// The held-out laps (`hold_out = true`): each signal at the study's start and with its
    /// answer, never fitted.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hold_out: Vec<SignalChange>,
    /// Profile likelihood of every parameter (asked for with `--profiles` or
    /// `profiles = true`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profiles: Option<crate::profile::Profiles>,
    /// Every parameter the study touches: initial and final values.
    pub parameters_initial: Vec<(String, f64)>,
    pub parameters_final: Vec<(String, f64)>,
    /// Full-lap simulations in this session, their summed wall time, and the session's
    /// wall time [s].
    pub simulations: usize,
    pub simulation_seconds: f64,
    pub wall_seconds: f64,
    /// `Simulation`s (sets of FMU instances) created: one per worker, reused.
    pub workers_created: usize,
    pub resumed: bool,
    /// The recorded laps a report draws (not serialised: tables of samples).
    #[serde(skip)]
    pub laps: StudyLaps,
}

/// All the study's parameters and signals together at its answer (Tab. 1's joint row).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointResult {
    /// Before: the value the parameter's (first) step started from; after: the answer,
    /// with the joint interval.
    pub parameters: Vec<ParameterChange>,
    /// Each signal of every step at the study's start and at its answer.
    pub e: Vec<SignalChange>,
    /// The joint refinement (absent with `refine = false`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refinement: Option<Refinement>,
    /// Whether the twin, not the noise, limits the answer ([`crate::model_check`]; absent
    /// where it could not be made, and in results written before it was).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_check: Option<crate::model_check::ModelCheck>,
    /// The moving-block bootstrap of the answer, where asked for (`--bootstrap N`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bootstrap: Option<crate::bootstrap::Bootstrap>,
}

/// The twin's laps of a study, on the comparison's uniform time grid: at the first step's
/// start (Tab. 1's "initial") and at the result. Kept from the runs the study made, so a
/// report simulates nothing.
#[derive(Clone, Debug, Default)]
pub struct StudyLaps {
    pub initial: Option<Table>,
    pub optimized: Option<Table>,
}

impl PartialEq for StudyLaps {
    fn eq(&self, other: &Self) -> bool {
        fn same(a: &Option<Table>, b: &Option<Table>) -> bool {
            match (a, b) {
                (Some(a), Some(b)) => a.names() == b.names() && a.columns() == b.columns(),
                (None, None) => true,
                _ => false,
            }
        }
        same(&self.initial, &other.initial) && same(&self.optimized, &other.optimized)
    }
}

impl StudyResult {
    pub fn initial_value(&self, name: &str) -> Option<f64> {
        self.parameters_initial
            .iter()
            .find(|(n, _)| n == name)
            .map(|p| p.1)
    }

    pub fn final_value(&self, name: &str) -> Option<f64> {
        self.parameters_final
            .iter()
            .find(|(n, _)| n == name)
            .map(|p| p.1)
    }
}

pub enum StudyOutcome {
    Finished(Box<StudyResult>),
    /// Stopped by an observer (Ctrl-C, [`StopAfter`](crate::StopAfter)); the checkpoint holds the state.
    Interrupted {
        generations: usize,
    },
}
