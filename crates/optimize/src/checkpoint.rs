//! The study's checkpoint file: the completed steps' results and the step under way (its
//! start, the optimiser's bit-exact state, the generation loop's bookkeeping), written
//! atomically after every generation; and the initial lap kept beside it. Reading it back
//! refuses another version, another study and other command-line overrides.
//!
//! The format is JSON of the structs below, field by field in their order: changing a
//! field's name, order or serde attribute changes the format (`CHECKPOINT_VERSION`). The
//! file wraps it with its SHA-256 (`{"sha256":"…","checkpoint":{…}}`): an edited or damaged
//! checkpoint is refused, not trusted; and what it says is checked against the study
//! (steps, parameters, bounds, finite costs) before anything is taken from it.

use super::exact;
use super::identifiability::Identifiability;
use super::optimizer::RunState;
use super::options::RunOptions;
use super::results::StepResult;
use super::study::{OptimizerKind, Study};
use crate::error::OptimizeError;
use serde::{Deserialize, Serialize};
use std::path::Path;
use tb_compare::Comparison;
use tb_table::write_atomic;

/// What a step knows before its first generation (checkpointed, so a resume does not redo it).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct StepStart {
    #[serde(with = "exact::vec")]
    pub(crate) x0: Vec<f64>,
    /// The first lap's comparison, and the other laps' in a study of several.
    pub(crate) before: Comparison,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub(crate) before_other_laps: Vec<Comparison>,
    pub(crate) cost_before: f64,
    pub(crate) identifiability: Identifiability,
}

/// The step under way.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Current {
    pub(crate) step: usize,
    pub(crate) start: StepStart,
    pub(crate) optimizer: serde_json::Value,
    pub(crate) run: RunState,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Checkpoint {
    version: u32,
    fingerprint: String,
    /// The command line's overrides the study ran with (a resume must use the same).
    #[serde(default)]
    overrides: Overrides,
    pub(crate) completed: Vec<StepResult>,
    pub(crate) current: Option<Current>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Overrides {
    optimizer: Option<OptimizerKind>,
    generations: Option<usize>,
}

impl Overrides {
    fn of(o: &RunOptions) -> Overrides {
        Overrides {
            optimizer: o.optimizer,
            generations: o.generations,
        }
    }

    fn describe(&self) -> String {
        let mut v = Vec::new();
        if let Some(k) = self.optimizer {
            v.push(format!("--optimizer {}", k.name()));
        }
        if let Some(g) = self.generations {
            v.push(format!("--generations {g}"));
        }
        if v.is_empty() {
            "no overrides".into()
        } else {
            v.join(" ")
        }
    }
}

const CHECKPOINT_VERSION: u32 = 2;

/// The head of a checkpoint file, before the checkpoint's JSON and after it.
const HEAD: &str = "{\"sha256\":\"";
const MIDDLE: &str = "\",\"checkpoint\":";

/// Why a checkpoint file cannot be resumed from: its wrapping, or what it says against the
/// study. `step` counts from 1.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CheckpointProblem {
    #[error("not a twinbench checkpoint of this version (no digest at its start)")]
    NoDigest,
    #[error("a truncated digest")]
    TruncatedDigest,
    #[error("not a twinbench checkpoint (its wrapping is damaged)")]
    Wrapping,
    #[error("its content does not match its SHA-256: the file was edited or damaged (start without --resume)")]
    Digest,
    #[error("{completed} completed steps, the study has {steps}")]
    TooManySteps { completed: usize, steps: usize },
    #[error("completed step {step} is '{name}' (number {number}), the study's step {step} is '{expected}'")]
    OtherStep {
        step: usize,
        name: String,
        number: usize,
        expected: String,
    },
    #[error("completed step {step}: parameters {names:?}, the study's are {expected:?}")]
    OtherParameters {
        step: usize,
        names: Vec<String>,
        expected: Vec<String>,
    },
    #[error("completed step {step}: '{name}' = {exact:?} (printed {printed:?}) is not a value within [{min}, {max}]")]
    OutOfBounds {
        step: usize,
        name: String,
        exact: f64,
        printed: f64,
        min: f64,
        max: f64,
    },
    #[error("completed step {step}: a cost of {cost:?}")]
    Cost { step: usize, cost: f64 },
    #[error("the step under way is number {step}, after {completed} completed")]
    UnderWay { step: usize, completed: usize },
    #[error(
        "step {step} under way: its start {x0:?} (cost {cost:?}) is not within the step's bounds"
    )]
    Start {
        step: usize,
        x0: Vec<f64>,
        cost: f64,
    },
}

/// The checkpoint's JSON inside a file, its digest checked.
fn unwrap_digest(text: &str) -> Result<&str, CheckpointProblem> {
    let rest = text.strip_prefix(HEAD).ok_or(CheckpointProblem::NoDigest)?;
    let (digest, rest) = rest
        .split_at_checked(64)
        .ok_or(CheckpointProblem::TruncatedDigest)?;
    let body = rest
        .strip_prefix(MIDDLE)
        .and_then(|b| b.trim_end().strip_suffix('}'))
        .ok_or(CheckpointProblem::Wrapping)?;
    use sha2::Digest;
    let actual = format!("{:x}", sha2::Sha256::digest(body.as_bytes()));
    if actual != digest {
        return Err(CheckpointProblem::Digest);
    }
    Ok(body)
}

impl Checkpoint {
    /// A checkpoint of this study run with these options.
    pub(crate) fn new(
        study: &Study,
        options: &RunOptions,
        completed: Vec<StepResult>,
        current: Option<Current>,
    ) -> Checkpoint {
        Checkpoint {
            version: CHECKPOINT_VERSION,
            fingerprint: study.fingerprint.clone(),
            overrides: Overrides::of(options),
            completed,
            current,
        }
    }

    /// Where the study starts: the checkpoint file's state when `options` say resume and the
    /// file exists (refused when it was made with other overrides), else nothing done.
    /// The flag says whether it was resumed.
    pub(crate) fn resume_or_new(
        study: &Study,
        options: &RunOptions,
    ) -> Result<(Checkpoint, bool), OptimizeError> {
        if options.resume {
            if let Some(path) = options.checkpoint.as_ref().filter(|p| p.exists()) {
                let checkpoint = Checkpoint::read(path, study)?;
                if checkpoint.overrides != Overrides::of(options) {
                    return Err(OptimizeError::Checkpoint(format!(
                        "{} was made with {}, this run has {}: resume with the same options (a study mixing budgets or optimisers is no result)",
                        path.display(),
                        checkpoint.overrides.describe(),
                        Overrides::of(options).describe()
                    )));
                }
                return Ok((checkpoint, true));
            }
        }
        Ok((Checkpoint::new(study, options, Vec::new(), None), false))
    }

    fn read(path: &Path, study: &Study) -> Result<Checkpoint, OptimizeError> {
        let text = tb_files::input::read_to_string(path, tb_files::Limit::CONFIG)
            .map_err(|e| OptimizeError::Checkpoint(e.to_string()))?;
        let bad = |m: &dyn std::fmt::Display| {
            OptimizeError::Checkpoint(format!("{}: {m}", path.display()))
        };
        let body = unwrap_digest(&text).map_err(|e| bad(&e))?;
        let c: Checkpoint = serde_json::from_str(body).map_err(|e| bad(&e))?;
        if c.version != CHECKPOINT_VERSION {
            return Err(OptimizeError::Checkpoint(format!(
                "{}: version {} (expected {CHECKPOINT_VERSION})",
                path.display(),
                c.version
            )));
        }
        if c.fingerprint != study.fingerprint {
            return Err(OptimizeError::Checkpoint(format!(
                "{} belongs to another study (or the study file changed): start without --resume",
                path.display()
            )));
        }
        c.check(study).map_err(|e| bad(&e))?;
        Ok(c)
    }

    /// What the checkpoint says fits the study: the completed steps are its first steps in
    /// order, with its parameters, values within their bounds (the printed ones the exact
    /// ones), finite costs; the step under way is the next one, its start within bounds.
    fn check(&self, study: &Study) -> Result<(), CheckpointProblem> {
        let steps = &study.file.steps;
        if self.completed.len() > steps.len() {
            return Err(CheckpointProblem::TooManySteps {
                completed: self.completed.len(),
                steps: steps.len(),
            });
        }
        for (k, (done, step)) in self.completed.iter().zip(steps).enumerate() {
            let at = k + 1;
            if done.step != k + 1 || done.name != step.name {
                return Err(CheckpointProblem::OtherStep {
                    step: at,
                    name: done.name.clone(),
                    number: done.step,
                    expected: step.name.clone(),
                });
            }
            let names: Vec<String> = done.parameters.iter().map(|p| p.name.clone()).collect();
            if names != step.parameter_names() || done.after_exact.len() != names.len() {
                return Err(CheckpointProblem::OtherParameters {
                    step: at,
                    names,
                    expected: step.parameter_names(),
                });
            }
            for ((p, exact), bound) in done
                .parameters
                .iter()
                .zip(&done.after_exact)
                .zip(&step.parameters)
            {
                if p.after.to_bits() != exact.to_bits() || !(bound.min..=bound.max).contains(exact)
                {
                    return Err(CheckpointProblem::OutOfBounds {
                        step: at,
                        name: p.name.clone(),
                        exact: *exact,
                        printed: p.after,
                        min: bound.min,
                        max: bound.max,
                    });
                }
            }
            for x in [done.cost_before, done.cost_after] {
                if !(x.is_finite() && x >= 0.0) {
                    return Err(CheckpointProblem::Cost { step: at, cost: x });
                }
            }
        }
        if let Some(c) = &self.current {
            let step = steps.get(c.step).filter(|_| c.step == self.completed.len());
            let Some(step) = step else {
                return Err(CheckpointProblem::UnderWay {
                    step: c.step + 1,
                    completed: self.completed.len(),
                });
            };
            let inside = c.start.x0.len() == step.parameters.len()
                && c.start
                    .x0
                    .iter()
                    .zip(&step.parameters)
                    .all(|(x, p)| (p.min..=p.max).contains(x));
            if !(inside && c.start.cost_before.is_finite() && c.start.cost_before >= 0.0) {
                return Err(CheckpointProblem::Start {
                    step: c.step + 1,
                    x0: c.start.x0.clone(),
                    cost: c.start.cost_before,
                });
            }
        }
        Ok(())
    }

    /// Writes the checkpoint atomically (a reader sees the old file or the new one).
    pub(crate) fn write(&self, path: &Path) -> Result<(), OptimizeError> {
        let body = serde_json::to_string_pretty(self)
            .map_err(|e| OptimizeError::Checkpoint(format!("serialising: {e}")))?;
        use sha2::Digest;
        let digest = format!("{:x}", sha2::Sha256::digest(body.as_bytes()));
        let text = format!("{HEAD}{digest}{MIDDLE}{body}}}\n");
        write_atomic(path, text.as_bytes())
            .map_err(|e| OptimizeError::Checkpoint(format!("writing {}: {e}", path.display())))
    }
}
