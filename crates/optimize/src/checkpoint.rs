//! The study's checkpoint file: the completed steps' results and the step under way (its
//! start, the optimiser's bit-exact state, the generation loop's bookkeeping), written
//! atomically after every generation; and the initial lap kept beside it. Reading it back
//! refuses another version, another study and other command-line overrides.
//!
//! The format is JSON of the structs below, field by field in their order: changing a
//! field's name, order or serde attribute changes the format (`CHECKPOINT_VERSION`).

use super::driver::{RunOptions, StepResult};
use super::exact;
use super::identifiability::Identifiability;
use super::optimizer::RunState;
use super::study::{OptimizerKind, Study};
use super::OptimizeError;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tb_compare::Comparison;
use tb_table::write_atomic;

/// Where a study with a checkpoint keeps its initial lap (written once, read on resume).
pub fn initial_lap_path(checkpoint: &Path) -> PathBuf {
    checkpoint.with_extension("initial-lap.csv")
}

/// What a step knows before its first generation (checkpointed, so a resume does not redo it).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct StepStart {
    #[serde(with = "exact::vec")]
    pub(crate) x0: Vec<f64>,
    pub(crate) before: Comparison,
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

const CHECKPOINT_VERSION: u32 = 1;

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
        let c: Checkpoint = serde_json::from_str(&text)
            .map_err(|e| OptimizeError::Checkpoint(format!("{}: {e}", path.display())))?;
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
        Ok(c)
    }

    /// Writes the checkpoint atomically (a reader sees the old file or the new one).
    pub(crate) fn write(&self, path: &Path) -> Result<(), OptimizeError> {
        let text = serde_json::to_vec_pretty(self)
            .map_err(|e| OptimizeError::Checkpoint(format!("serialising: {e}")))?;
        write_atomic(path, &text)
            .map_err(|e| OptimizeError::Checkpoint(format!("writing {}: {e}", path.display())))
    }
}
