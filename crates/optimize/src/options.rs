//! How to run a study: threads, observers, the checkpoint and resume, the command line's
//! overrides, a remote evaluator, the work after the steps.

use super::observe::StudyObserver;
use super::remote::Evaluator;
use super::study::OptimizerKind;
use std::path::PathBuf;
use std::sync::Arc;

/// How to run a study.
#[derive(Clone, Default)]
pub struct RunOptions {
    /// Evaluation threads (0: all cores).
    pub threads: usize,
    /// Told about every step, generation and the result, in order (progress bars, stop
    /// conditions, the report, a caller's own): [`StudyObserver`]. One that ends the study
    /// makes it [`StudyOutcome::Interrupted`](crate::StudyOutcome::Interrupted), its checkpoint kept.
    pub observers: Vec<Arc<dyn StudyObserver>>,
    /// Checkpoint file, written after every generation (None: no checkpoint).
    pub checkpoint: Option<PathBuf>,
    /// Continue from the checkpoint when it exists.
    pub resume: bool,
    /// Override the study's optimiser.
    pub optimizer: Option<OptimizerKind>,
    /// Override the generations of every step.
    pub generations: Option<usize>,
    /// Print the identifiability report and step summaries to stderr.
    pub verbose: bool,
    /// Optimise even when the first run says measurement and twin do not belong together.
    pub force: bool,
    /// Evaluate the generations' candidates here instead of on `threads` threads (the
    /// start, identifiability and result runs stay local).
    pub evaluator: Option<Arc<dyn Evaluator>>,
    /// Profile likelihood of every parameter after the joint refinement (as the study's
    /// `profiles = true`).
    pub profiles: bool,
    /// A moving-block bootstrap of the joint answer with this many refits
    /// ([`crate::bootstrap`]; 0: none, as the study's `bootstrap = N`).
    pub bootstrap: usize,
}

impl std::fmt::Debug for RunOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunOptions")
            .field("threads", &self.threads)
            .field("observers", &self.observers.len())
            .field("checkpoint", &self.checkpoint)
            .field("resume", &self.resume)
            .field("optimizer", &self.optimizer)
            .field("generations", &self.generations)
            .field("verbose", &self.verbose)
            .field("force", &self.force)
            .field("evaluator", &self.evaluator.is_some())
            .field("profiles", &self.profiles)
            .field("bootstrap", &self.bootstrap)
            .finish()
    }
}
