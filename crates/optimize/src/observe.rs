//! Watching a study while it runs: the [`StudyObserver`] trait, what it is told (every
//! generation, the progress of the work after the steps) and the stop conditions
//! ([`StopOnFlag`] for Ctrl-C, [`StopAfter`]).

use super::optimizer::GenerationRecord;
use super::results::StudyResult;
use crate::failure::ObserverError;
use std::ops::ControlFlow;
use std::sync::Arc;

/// What watches a study while it runs: told of every step and generation and of its
/// result. The library draws nothing and decides nothing here: the command line's progress
/// bars, Python's `progress` callback, the stop conditions ([`StopOnFlag`] for Ctrl-C,
/// [`StopAfter`]) and the report are observers, and a caller attaches its own
/// ([`RunOptions::observers`](crate::RunOptions::observers)), in order.
pub trait StudyObserver: Send + Sync {
    /// A step starts (or resumes at generation `done` of `generations`).
    fn step_started(&self, _step: usize, _name: &str, _generations: usize, _done: usize) {}
    /// A generation of the current step is complete and checkpointed. `Break` ends the
    /// study after it, as an interruption (resumable), while the step has generations left;
    /// at a step's last generation the study goes on and asks again at the next one.
    fn generation(&self, _g: &GenerationDone<'_>) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }
    /// The current step's optimiser is done.
    fn step_finished(&self) {}
    /// The work after the steps, which has no generations (the joint refinement, the
    /// profiles, the bootstrap) ran a batch of laps, or ended (`done`).
    fn phase(&self, _p: &PhaseProgress<'_>) {}
    /// The study's result, before it is returned (not after an interruption); an error
    /// (the report could not be written) ends the study with it.
    fn finished(&self, _result: &StudyResult) -> Result<(), ObserverError> {
        Ok(())
    }
}

/// Where the work after the steps stands, as observers see it.
#[derive(Clone, Copy, Debug)]
pub struct PhaseProgress<'a> {
    /// `refinement`, `profiles` or `bootstrap`.
    pub phase: &'static str,
    /// The parameters it works on, by name.
    pub parameters: &'a [String],
    /// Laps run in this phase so far.
    pub laps: usize,
    /// Seconds since the phase began.
    pub seconds: f64,
    /// The phase is over.
    pub done: bool,
}

/// The phases' progress, told to the observers after every batch of laps (from any thread:
/// the profiles' walks run side by side).
pub(crate) struct Phases<'a> {
    observers: &'a [Arc<dyn StudyObserver>],
    parameters: &'a [String],
    /// Laps per point (one per lap of the study).
    laps_per_point: usize,
    now: std::sync::Mutex<(&'static str, usize, std::time::Instant)>,
}

impl<'a> Phases<'a> {
    pub(crate) fn new(
        observers: &'a [Arc<dyn StudyObserver>],
        parameters: &'a [String],
        laps_per_point: usize,
    ) -> Self {
        Phases {
            observers,
            parameters,
            laps_per_point,
            now: std::sync::Mutex::new(("refinement", 0, std::time::Instant::now())),
        }
    }

    pub(crate) fn begin(&self, phase: &'static str) {
        *self.now.lock().unwrap_or_else(|p| p.into_inner()) = (phase, 0, std::time::Instant::now());
    }

    /// `points` points ran (or, with `done`, the phase ended).
    pub(crate) fn ran(&self, points: usize, done: bool) {
        let (phase, laps, seconds) = {
            let mut now = self.now.lock().unwrap_or_else(|p| p.into_inner());
            now.1 += points * self.laps_per_point;
            (now.0, now.1, now.2.elapsed().as_secs_f64())
        };
        // Told outside the lock: an observer may take its time (Python's GIL).
        let p = PhaseProgress {
            phase,
            parameters: self.parameters,
            laps,
            seconds,
            done,
        };
        for o in self.observers {
            o.phase(&p);
        }
    }
}

/// A generation just completed, as observers see it.
pub struct GenerationDone<'a> {
    /// The step (1-based), its name and its generations.
    pub step: usize,
    pub name: &'a str,
    pub generations: usize,
    /// Generations of the step done so far (this one included).
    pub done: usize,
    pub record: &'a GenerationRecord,
    /// Where the candidates ran: the evaluator's workers (a cluster's, when it can say),
    /// else this process's threads.
    pub workers: Option<usize>,
}

/// Ends the study after the generation under way once `flag` is set (Ctrl-C, a signal).
pub struct StopOnFlag(pub Arc<std::sync::atomic::AtomicBool>);

impl StudyObserver for StopOnFlag {
    fn generation(&self, _g: &GenerationDone<'_>) -> ControlFlow<()> {
        match self.0.load(std::sync::atomic::Ordering::SeqCst) {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        }
    }
}

/// Ends the study after `n` generations of this session (an interruption at a chosen point,
/// for tests of resume).
pub struct StopAfter {
    n: usize,
    seen: std::sync::atomic::AtomicUsize,
}

impl StopAfter {
    pub fn new(n: usize) -> StopAfter {
        StopAfter {
            n,
            seen: std::sync::atomic::AtomicUsize::new(0),
        }
    }
}

impl StudyObserver for StopAfter {
    fn generation(&self, _g: &GenerationDone<'_>) -> ControlFlow<()> {
        let seen = self.seen.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        match seen >= self.n {
            true => ControlFlow::Break(()),
            false => ControlFlow::Continue(()),
        }
    }
}
