//! The study driver: the steps in order (each starts from the earlier steps' results), an
//! identifiability check and e before each step, the optimiser's generations with a
//! checkpoint after every one, e after, and the whole result as a serialisable value.
//!
//! This file runs a study from start to end; the stages live beside it: `session.rs` (what
//! every stage reads, where the study stands), `step.rs` (one step and its cost),
//! `step_loop.rs` (the steps run, resumed or passed over), `finish.rs` (a step's and the
//! study's result), `joint.rs` (the joint answer after the steps). What a study records is
//! in `results.rs`, its observers in `observe.rs`, how to run it in `options.rs`, the cost
//! in `cost.rs`.

use super::finish::finish_study;
use super::session::{Session, StudyState};
use super::step_loop::run_step;
use super::study::Study;
use crate::error::OptimizeError;
use std::time::Instant;

// The cost, the observers, the options and what a study records live in files of their own
// (the bench, a remote worker and the checkpoint share them); named here too, where callers
// have always found them.
pub use super::cost::cost_of;
pub use super::observe::{GenerationDone, PhaseProgress, StopAfter, StopOnFlag, StudyObserver};
pub use super::options::RunOptions;
pub use super::results::{
    JointResult, ParameterChange, SignalChange, StepResult, StudyLaps, StudyOutcome, StudyResult,
};

/// Runs a study (or continues it from its checkpoint): the steps in order, each passed over
/// when the checkpoint has it completed, then the result with the laps a report draws.
pub fn run_study(study: &Study, options: &RunOptions) -> Result<StudyOutcome, OptimizeError> {
    let wall = Instant::now();
    let session = Session::open(study, options)?;
    let mut state = StudyState::begin(&session)?;
    for k in 0..study.file.steps.len() {
        if run_step(&session, &mut state, k)?.is_break() {
            return Ok(StudyOutcome::Interrupted {
                generations: state.session_generations,
            });
        }
    }
    let result = finish_study(&session, state, wall)?;
    for o in &options.observers {
        o.finished(&result).map_err(OptimizeError::Observer)?;
    }
    Ok(StudyOutcome::Finished(Box::new(result)))
}
