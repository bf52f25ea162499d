//! Parameter optimisation of the twin against a vehicle measurement (paper ch. 4.3;
//! `docs/optimize.md`).
//!
//! - [`study`]: the study file (system, measurement, comparison settings, optimiser, steps).
//! - [`optimizer`]: the ask/tell [`Optimizer`] trait, the [`Problem`] trait and the
//!   generation loop [`minimize`] (parallel evaluation with rayon, failures penalised).
//! - [`ga`]: real-coded GA (tournament, SBX, polynomial mutation, elitism); [`cmaes`]: CMA-ES.
//! - [`pool`]: the worker pool, candidates on the co-simulated bench: the system compiled
//!   once into a plan, one reused `Simulation` of it per worker, every study parameter
//!   resolved to a slot.
//! - [`bench`]: the laps of a study (one or several `[[measurement]]`s), each with its worker
//!   pool and measurement; a candidate's cost over all of them.
//! - [`remote`]: candidates evaluated in other processes or on other machines (the
//!   [`Evaluator`] a distributed study uses, the [`StudyEvaluator`] a worker holds).
//! - [`failure`]: why a candidate's run failed ([`RunError`]: the simulation's own error, a
//!   setting, a lap, ...), kept as itself through the pool, the laps, the fits and the
//!   evaluators, and across processes as its kind and message.
//! - [`rng`]: the seeded generator every random draw comes from; [`exact`]: bit-exact
//!   floats in checkpoints.
//! - [`identifiability`]: the identifiability check (finite-difference Jacobian,
//!   near-null directions).
//! - [`interval`]: each fitted parameter's confidence interval at a step's optimum
//!   (Gauss–Newton sandwich with a long-run covariance of the scores).
//! - [`fit`]: the joint least-squares refinement of all of a study's parameters on all its
//!   signals (Levenberg–Marquardt), where the intervals are centred.
//! - [`profile`]: profile likelihood, each parameter held on a grid and the others
//!   re-optimised by [`fit`]'s iteration (on request).
//! - [`driver`]: the study driver: steps in order, each starting from the earlier results,
//!   identifiability check, e before/after, a checkpoint after every generation, resume.
//! - [`checkpoint`]: the checkpoint file the driver writes after every generation and
//!   resumes from.
//!
//! Determinism: every random number is drawn on the calling thread in `ask`/`tell`, a
//! candidate's cost depends on the candidate only, and costs go back in the asked order, so
//! the same seed gives the same result with any number of threads, and a resumed study
//! (bit-exact optimiser state in the checkpoint) the same result as an uninterrupted one.

pub mod bench;
mod block;
pub mod bootstrap;
pub mod checkpoint;
pub mod cmaes;
mod cost;
pub mod driver;
pub mod error;
pub mod exact;
pub mod failure;
mod finish;
pub mod fit;
pub mod ga;
pub mod identifiability;
pub mod interval;
mod joint;
mod long_run;
pub mod model_check;
pub(crate) mod noise_time;
mod observe;
pub mod optimizer;
mod options;
pub mod pool;
pub mod profile;
pub mod remote;
mod results;
pub mod rng;
mod session;
mod step;
mod step_loop;
pub mod study;
#[cfg(test)]
mod test_curve;

pub use cmaes::{Cmaes, CmaesSettings};
pub use cost::StepCost;
pub use driver::run_study;
pub use error::OptimizeError;
pub use failure::{EvaluatorError, FailureKind, ObserverError, RunError};
pub use ga::{Ga, GaSettings};
pub use identifiability::Identifiability;
pub use interval::{Intervals, ParameterInterval};
pub use observe::{GenerationDone, PhaseProgress, StopAfter, StopOnFlag, StudyObserver};
pub use optimizer::{minimize, GenerationRecord, Optimizer, Problem, RunSettings, RunState};
pub use options::RunOptions;
pub use pool::WorkerPool;
pub use remote::{Candidate, Evaluator, InputDigest, LapSignals, StudyEvaluator};
pub use results::{StepResult, StudyOutcome, StudyResult};
pub use rng::Rng;
pub use study::{OptimizerKind, Study, StudyFile};
