//! What every stage of a study reads (the [`Session`]: the study, how it is run, its laps
//! on the bench, the threads) and where the study stands, carried from step to step (the
//! [`StudyState`]).

use super::bench::Bench;
use super::checkpoint::Checkpoint;
use super::optimizer::thread_pool;
use super::options::RunOptions;
use super::results::StudyLaps;
use super::study::{OptimizerKind, Study};
use crate::error::OptimizeError;
use std::sync::Arc;
use tb_fmi::FmuCache;

/// What every stage of a study reads: the study, how it is run, the worker pool on its
/// compiled system, the measurement, the threads of the start's runs and the optimiser.
pub(crate) struct Session<'a> {
    pub(crate) study: &'a Study,
    pub(crate) options: &'a RunOptions,
    /// The fitted laps.
    pub(crate) bench: Bench,
    /// The unpacked FMUs (the held-out laps' workers load theirs from it too).
    pub(crate) cache: Arc<FmuCache>,
    /// The identifiability check's threads (the generations' are `minimize`'s own).
    pub(crate) pool: rayon::ThreadPool,
    pub(crate) kind: OptimizerKind,
}

impl<'a> Session<'a> {
    /// Compiles the system, loads the measurement, builds the threads.
    pub(crate) fn open(
        study: &'a Study,
        options: &'a RunOptions,
    ) -> Result<Session<'a>, OptimizeError> {
        let cache = Arc::new(FmuCache::temporary(false).map_err(tb_cosim::SystemError::from)?);
        let bench = Bench::new(study, cache.clone(), false)?;
        let pool = thread_pool(options.threads)?;
        Ok(Session {
            study,
            options,
            bench,
            cache,
            pool,
            kind: options.optimizer.unwrap_or(study.file.optimizer.kind),
        })
    }
}

/// Where the study stands, carried from step to step.
pub(crate) struct StudyState {
    /// The completed steps and the step under way (what the checkpoint file holds).
    pub(crate) checkpoint: Checkpoint,
    pub(crate) resumed: bool,
    /// Every parameter the study touches, with its initial value.
    pub(crate) initial: Vec<(String, f64)>,
    /// The same parameters with their values after the steps done so far.
    pub(crate) assignment: Vec<(String, f64)>,
    pub(crate) laps: StudyLaps,
    /// The first step's start point (for the initial lap when it has to be made again).
    pub(crate) first_x0: Option<Vec<f64>>,
    /// Generations run in this session.
    pub(crate) session_generations: usize,
}

impl StudyState {
    /// The study's state from its checkpoint (resume), else before its first step.
    pub(crate) fn begin(session: &Session) -> Result<StudyState, OptimizeError> {
        let assignment = session.bench.workers().assignment();
        let (checkpoint, resumed) = Checkpoint::resume_or_new(session.study, session.options)?;
        // A resumed study simulates its initial lap again (one lap) at the end rather than
        // read one beside the checkpoint, which nothing vouches for (M14).
        let laps = StudyLaps::default();
        Ok(StudyState {
            checkpoint,
            resumed,
            initial: assignment.clone(),
            assignment,
            laps,
            first_x0: None,
            session_generations: 0,
        })
    }

    /// Sets the step's parameters (at `index` in the assignment) to `values`.
    pub(crate) fn set(&mut self, index: &[usize], values: &[f64]) {
        for (j, &i) in index.iter().enumerate() {
            self.assignment[i].1 = values[j];
        }
    }
}
