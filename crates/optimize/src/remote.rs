//! Candidates evaluated somewhere else: in other processes, on other machines (a Dask
//! cluster through the Python package, `docs/distributed.md`).
//!
//! The study driver hands a generation to an [`Evaluator`] as [`Candidate`]s: the step and
//! every parameter's value, nothing else. A worker process holds one [`StudyEvaluator`] per
//! study, loaded once and kept between candidates; it computes the same cost, to the bit,
//! as the local evaluation (one function, [`StepCost::of`], for both). Whether the worker
//! has run other candidates before does not matter: a candidate sets every parameter and
//! every FMU instance is reset (`tests/determinism.rs`).
//!
//! A worker can only compute the right cost from the right files, so a task carries the
//! [`InputDigest`] of the study's files and a worker that sees other contents refuses,
//! naming the file.

use super::bench::Bench;
use super::pool::WorkerPool;
use super::study::Study;
use crate::error::OptimizeError;
use crate::failure::{EvaluatorError, RunError};
use serde::{Deserialize, Serialize};
use sha2::Digest;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tb_compare::PreparedMeasurement;
use tb_fmi::FmuCache;

// The step's cost lives beside `cost_of` (the bench shares it); named here too, where a
// worker's callers have always found it.
pub use super::cost::StepCost;

/// One candidate of a study step: the step (0-based) and the value of every parameter of
/// the study, in [`WorkerPool::assignment`]'s order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub step: usize,
    pub values: Vec<f64>,
}

/// Evaluates a generation's candidates (a process pool, a cluster). The inner results are
/// the candidates' costs or the reasons they failed (penalised, the study goes on), in the
/// order given; the outer `Err` is a failure of the evaluator itself (a lost cluster, an
/// interruption), which ends the study with the checkpoint of the last whole generation.
pub trait Evaluator: Send + Sync {
    fn evaluate(
        &self,
        candidates: &[Candidate],
    ) -> Result<Vec<Result<f64, RunError>>, EvaluatorError>;

    /// The joint fit's laps (the refinement, the profiles) at `points` (every parameter's
    /// value, [`WorkerPool::assignment`]'s order): per point the filtered signals of
    /// [`Study::joint_signals`] on the grid, per lap and signal (laps outer) the first grid
    /// index and the values ([`StudyEvaluator::signals`]), or why its run failed. An
    /// evaluator that cannot says so (`Err`) and the fit is not made.
    fn signals(
        &self,
        points: &[Vec<f64>],
    ) -> Result<Vec<Result<LapSignals, RunError>>, EvaluatorError> {
        let _ = points;
        Err(EvaluatorError::CostsOnly)
    }

    /// How many workers evaluate the candidates now (a cluster's: they come and go), when
    /// the evaluator can say.
    fn workers(&self) -> Option<usize> {
        None
    }
}

/// A point's filtered signals on the grid, per lap and signal: (first grid index, values).
pub type LapSignals = Vec<(usize, Vec<f64>)>;

/// SHA-256 of each file a study reads, in a fixed order: the study, its measurement and
/// every input of its system ([`tb_cosim::Plan::input_files`]). An FMU's entry is its
/// archive's SHA-256 and the digest of its unpacked folder's manifest (every file's path,
/// size, mode and BLAKE3), after every unpacked file was verified against it: the content
/// the worker's runs actually read (a resource file the FMU opens included).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputDigest {
    pub files: Vec<(PathBuf, String)>,
}

impl InputDigest {
    /// Each file's content hash: the SHA-256 of its bytes (an FMU's entry starts with its
    /// archive's), which a worker without the coordinator's disk asks for its copy by.
    pub fn contents(&self) -> Vec<(PathBuf, String)> {
        self.files
            .iter()
            .map(|(p, d)| {
                let sha = d.split(' ').next().unwrap_or(d);
                (p.clone(), sha.to_string())
            })
            .collect()
    }

    pub fn of(study: &Study, bench: &Bench) -> Result<InputDigest, OptimizeError> {
        let mut paths = vec![study.path.clone()];
        for l in &bench.laps {
            paths.push(l.lap.measurement_path.clone());
            paths.extend(l.workers.plan().input_files());
        }
        let files = paths
            .into_iter()
            .map(|p| {
                let plan = bench
                    .laps
                    .iter()
                    .map(|l| l.workers.plan())
                    .find(|plan| plan.file.fmus.values().any(|f| *f == p));
                // An FMU's content hash is the unpack cache's (kept in its index: no
                // second read and hash of the archive); its unpacked content is verified
                // (a cache `verifying_all` did so when it loaded it, repairing what differed).
                // A worker's mirror of the coordinator's files (docs/distributed.md) names
                // each file as the coordinator does, so that the two digests are equal.
                let named = tb_files::unmirror(&p);
                if let Some(plan) = plan {
                    let fmu = plan.cache.load(&p).map_err(tb_cosim::SystemError::from)?;
                    fmu.verify_all().map_err(tb_cosim::SystemError::from)?;
                    let digest = format!("{} unpacked {}", fmu.sha256, fmu.manifest_digest());
                    return Ok((named, digest));
                }
                let bytes = std::fs::read(&p).map_err(|e| OptimizeError::File {
                    path: p.clone(),
                    message: format!("cannot read: {e}"),
                })?;
                Ok((named, format!("{:x}", sha2::Sha256::digest(&bytes))))
            })
            .collect::<Result<_, OptimizeError>>()?;
        Ok(InputDigest { files })
    }

    /// Why `theirs` (the coordinator's) is not this worker's, naming the first file that
    /// differs; `None` when they agree.
    pub fn mismatch(&self, theirs: &InputDigest) -> Option<String> {
        if self.files.len() != theirs.files.len() {
            return Some(format!(
                "the study reads {} files here and {} on the coordinator (the system file differs)",
                self.files.len(),
                theirs.files.len()
            ));
        }
        self.files
            .iter()
            .zip(&theirs.files)
            .find(|(a, b)| a.1 != b.1)
            .map(|(mine, _)| {
                format!(
                    "{} differs from the coordinator's copy (its digest here is {}): every worker needs the same files (sent with the tasks on a Dask cluster, else on a shared path), and the same unpacked FMUs",
                    mine.0.display(),
                    mine.1
                )
            })
    }
}

/// The joint fit's signals and each fitted lap's measurement prepared for them.
type JointSignals = (Vec<String>, Vec<PreparedMeasurement>);

/// A study ready to evaluate candidates in a worker process: the worker pool (its
/// simulations kept between candidates), the measurement prepared once per step.
pub struct StudyEvaluator {
    study: Study,
    bench: Bench,
    digest: InputDigest,
    prepared: Mutex<HashMap<usize, Arc<Vec<PreparedMeasurement>>>>,
    /// The joint fit's signals and the measurement prepared for them, on their first use.
    /// (An error shared: every later point fails with it.)
    joint: std::sync::OnceLock<Result<JointSignals, Arc<tb_compare::Error>>>,
}

impl StudyEvaluator {
    pub fn load(path: &Path) -> Result<StudyEvaluator, OptimizeError> {
        let cache = FmuCache::temporary(false).map_err(tb_cosim::SystemError::from)?;
        Self::load_with(path, cache)
    }

    /// [`StudyEvaluator::load`] with FMUs from `cache`, which verifies every unpacked file
    /// of the study's FMUs before anything runs ([`FmuCache::verifying_all`]): a worker
    /// whose unpacked copy of a resource was changed repairs it, and its input digest
    /// says which content it runs on.
    pub fn load_with(path: &Path, cache: FmuCache) -> Result<StudyEvaluator, OptimizeError> {
        let study = Study::load(path)?;
        let cache = Arc::new(cache.verifying_all());
        let bench = Bench::new(&study, cache, false)?;
        let digest = InputDigest::of(&study, &bench)?;
        Ok(StudyEvaluator {
            study,
            bench,
            digest,
            prepared: Mutex::new(HashMap::new()),
            joint: std::sync::OnceLock::new(),
        })
    }

    pub fn study(&self) -> &Study {
        &self.study
    }

    /// The first lap's workers (the assignment every lap shares).
    pub fn workers(&self) -> &WorkerPool {
        self.bench.workers()
    }

    /// Every fitted lap.
    pub fn bench(&self) -> &Bench {
        &self.bench
    }

    pub fn digest(&self) -> &InputDigest {
        &self.digest
    }

    /// The candidate's cost, or why its run failed. An error of the worker itself (a step
    /// the study does not have, a measurement that cannot be prepared) is an `Err` too: the
    /// coordinator checked both before sending, so it cannot happen with the same files.
    pub fn cost(&self, c: &Candidate) -> Result<f64, RunError> {
        let cost = StepCost::of_step(&self.study, c.step).ok_or_else(|| RunError::NoSuchStep {
            study: self.study.path.clone(),
            steps: self.study.file.steps.len(),
            step: c.step + 1,
        })?;
        let prepared = self.prepared(c.step, &cost.signals)?;
        self.bench.cost(&cost, &c.values, &prepared)
    }

    /// The joint fit's signals at `values` (every parameter's value), as
    /// [`Evaluator::signals`] returns them for one point: the same numbers to the bit as the
    /// coordinator's own laps ([`Bench::signals`] for both).
    pub fn signals(&self, values: &[f64]) -> Result<LapSignals, RunError> {
        let (signals, prepared) = self
            .joint
            .get_or_init(|| {
                let (signals, _) = self.study.joint_signals();
                let prepared = self
                    .bench
                    .prepare(&signals, &self.study.file.compare)
                    .map_err(Arc::new)?;
                Ok((signals, prepared))
            })
            .as_ref()
            .map_err(|e| RunError::Prepare(e.clone()))?;
        let series = self.bench.signals(values, prepared, signals)?;
        Ok(series.into_iter().map(|(r, v)| (r.start, v)).collect())
    }

    fn prepared(
        &self,
        step: usize,
        signals: &[String],
    ) -> Result<Arc<Vec<PreparedMeasurement>>, RunError> {
        let mut map = self.prepared.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = map.get(&step) {
            return Ok(p.clone());
        }
        let p = Arc::new(
            self.bench
                .prepare(signals, &self.study.file.compare)
                .map_err(|e| RunError::Prepare(Arc::new(e)))?,
        );
        map.insert(step, p.clone());
        Ok(p)
    }
}
