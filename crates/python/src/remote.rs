//! The two halves of a study evaluated elsewhere: the evaluator a remote worker holds and the
//! optimiser the caller asks and tells.

use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use tb_optimize::optimizer::{to_bounds, to_unit};
use tb_optimize::{Candidate, Cmaes, Ga, RunError, StudyEvaluator};

use crate::errors::{error, TwinbenchError};

/// A step as Python sees it: name, parameter names, bounds, start values.
pub(crate) type StepInfo = (String, Vec<String>, Vec<(f64, f64)>, Vec<Option<f64>>);

/// A study loaded for evaluating candidates: in a worker process (kept between tasks) or
/// for the ask/tell loop of an optimiser of the user's own.
#[pyclass(frozen)]
pub(crate) struct StudyEvaluatorPy {
    inner: Arc<StudyEvaluator>,
    digest: String,
}

#[pymethods]
impl StudyEvaluatorPy {
    #[new]
    fn new(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = py
            .detach(move || StudyEvaluator::load(&path))
            .map_err(error)?;
        let digest = serde_json::to_string(inner.digest()).map_err(error)?;
        Ok(StudyEvaluatorPy {
            inner: Arc::new(inner),
            digest,
        })
    }

    /// The SHA-256 of every file the study reads, as JSON.
    #[getter]
    fn digest(&self) -> String {
        self.digest.clone()
    }

    /// Every file the study reads with the SHA-256 of its bytes (an FMU's archive), as
    /// the coordinator names it: what a worker without its disk asks for.
    fn contents(&self) -> Vec<(PathBuf, String)> {
        self.inner.digest().contents()
    }

    /// Why the coordinator's digest is not this one (None when equal).
    fn mismatch(&self, theirs: &str) -> PyResult<Option<String>> {
        let theirs: tb_optimize::InputDigest = serde_json::from_str(theirs).map_err(|e| {
            TwinbenchError::new_err(format!(
                "the coordinator's input digest is not a twinbench digest (JSON of the study's files and their SHA-256): {e}"
            ))
        })?;
        Ok(self.inner.digest().mismatch(&theirs))
    }

    /// Every parameter of the study with its value before the study.
    fn assignment(&self) -> Vec<(String, f64)> {
        self.inner.workers().assignment()
    }

    /// The study's steps: name, parameter names, bounds, start values (None: the current
    /// value), generations.
    fn steps(&self) -> Vec<StepInfo> {
        self.inner
            .study()
            .file
            .steps
            .iter()
            .map(|s| {
                (
                    s.name.clone(),
                    s.parameter_names(),
                    s.parameters.iter().map(|p| (p.min, p.max)).collect(),
                    s.parameters.iter().map(|p| p.start).collect(),
                )
            })
            .collect()
    }

    /// One candidate's cost (every parameter's value): a float, or the reason its run
    /// failed (a str).
    fn cost(&self, py: Python<'_>, step: usize, values: Vec<f64>) -> PyResult<Py<PyAny>> {
        let inner = self.inner.clone();
        let result = py.detach(move || {
            tb_optimize::optimizer::finite(inner.cost(&Candidate { step, values }))
        });
        outcome_object(py, result)
    }

    /// The joint fit's filtered signals at `values` (every parameter's value): per lap and
    /// signal, the first grid index and the values as little-endian float64 bytes; or the
    /// reason the run failed (a str).
    fn signals(&self, py: Python<'_>, values: Vec<f64>) -> PyResult<Py<PyAny>> {
        let inner = self.inner.clone();
        let result = py.detach(move || inner.signals(&values));
        Ok(match result {
            Ok(series) => {
                let list: Vec<(usize, Py<PyBytes>)> = series
                    .into_iter()
                    .map(|(start, v)| {
                        let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
                        (start, PyBytes::new(py, &bytes).unbind())
                    })
                    .collect();
                list.into_pyobject(py)?.into_any().unbind()
            }
            Err(why) => failure_object(py, &why)?,
        })
    }

    /// Many candidates' costs on `threads` threads (0: all cores): each a float, or the
    /// reason its run failed (a str).
    fn costs(
        &self,
        py: Python<'_>,
        step: usize,
        candidates: Vec<Vec<f64>>,
        threads: usize,
    ) -> PyResult<Vec<Py<PyAny>>> {
        let inner = self.inner.clone();
        let results = py
            .detach(
                move || -> Result<Vec<Result<f64, RunError>>, tb_optimize::OptimizeError> {
                    let pool = tb_optimize::optimizer::thread_pool(threads)?;
                    Ok(pool.install(|| {
                        use rayon::prelude::*;
                        candidates
                            .par_iter()
                            .with_max_len(1)
                            .map(|values| {
                                tb_optimize::optimizer::finite(inner.cost(&Candidate {
                                    step,
                                    values: values.clone(),
                                }))
                            })
                            .collect()
                    }))
                },
            )
            .map_err(error)?;
        results.into_iter().map(|r| outcome_object(py, r)).collect()
    }
}

/// A cost as a float, a failure as its reason (a str).
pub(crate) fn outcome_object(py: Python<'_>, r: Result<f64, RunError>) -> PyResult<Py<PyAny>> {
    Ok(match r {
        Ok(c) => c.into_pyobject(py)?.into_any().unbind(),
        Err(e) => failure_object(py, &e)?,
    })
}

/// A failed run as a task returns it: its message, a str (`twinbench._failure.Failure`)
/// that carries its kind across the processes of a distributed study.
pub(crate) fn failure_object(py: Python<'_>, e: &RunError) -> PyResult<Py<PyAny>> {
    let class = py.import("twinbench._failure")?.getattr("Failure")?;
    Ok(class.call1((e.to_string(), e.kind().name()))?.unbind())
}

/// A failure a task returned (a str; its kind, when it says one) as the error it was.
pub(crate) fn failure_of(r: &Bound<'_, PyAny>) -> PyResult<RunError> {
    let kind = match r.getattr("kind") {
        Ok(k) => k.extract::<String>().unwrap_or_default(),
        Err(_) => String::new(),
    };
    Ok(RunError::from_wire(&kind, r.str()?.to_string()))
}

/// One of twinbench's optimisers, ask/tell, in the problem's own units (its bounds).
#[pyclass]
pub(crate) struct OptimizerPy {
    inner: Mutex<Box<dyn tb_optimize::Optimizer>>,
    bounds: Vec<(f64, f64)>,
    /// Candidates of the last `ask` (a `tell` must bring as many costs).
    asked: usize,
}

#[pymethods]
impl OptimizerPy {
    #[new]
    #[pyo3(signature = (kind, bounds, seed, start=None))]
    fn new(
        kind: &str,
        bounds: Vec<(f64, f64)>,
        seed: u64,
        start: Option<Vec<f64>>,
    ) -> PyResult<Self> {
        for (k, &(lo, hi)) in bounds.iter().enumerate() {
            // The width too (M15): (-1e308, 1e308) is finite at both ends, but not across.
            if !(lo.is_finite() && hi.is_finite() && lo < hi && (hi - lo).is_finite()) {
                return Err(TwinbenchError::new_err(format!(
                    "bounds[{k}] = ({lo:e}, {hi:e}): expected finite lower < upper, and a finite width"
                )));
            }
        }
        if let Some(s) = &start {
            if s.len() != bounds.len() {
                return Err(TwinbenchError::new_err(format!(
                    "start has {} values for {} bounds",
                    s.len(),
                    bounds.len()
                )));
            }
            for (k, (&x, &(lo, hi))) in s.iter().zip(&bounds).enumerate() {
                if !(x.is_finite() && lo <= x && x <= hi) {
                    return Err(TwinbenchError::new_err(format!(
                        "start[{k}] = {x:?}: expected a number within its bounds [{lo}, {hi}]"
                    )));
                }
            }
        }
        let dim = bounds.len();
        let start_unit = start.map(|s| to_unit(&s, &bounds));
        let inner: Box<dyn tb_optimize::Optimizer> = match kind {
            "ga" => Box::new(Ga::new(dim, Default::default(), seed, start_unit).map_err(error)?),
            "cmaes" | "cma-es" => {
                Box::new(Cmaes::new(dim, Default::default(), seed, start_unit).map_err(error)?)
            }
            other => {
                return Err(TwinbenchError::new_err(format!(
                    "unknown optimiser '{other}' (ga, cmaes)"
                )))
            }
        };
        Ok(OptimizerPy {
            inner: Mutex::new(inner),
            bounds,
            asked: 0,
        })
    }

    /// The next generation's candidates (each within the bounds).
    fn ask(&mut self) -> Vec<Vec<f64>> {
        let asked = self.lock().ask();
        self.asked = asked.len();
        asked.iter().map(|u| to_bounds(u, &self.bounds)).collect()
    }

    /// The costs of the last `ask`'s candidates, in its order (lower is better).
    fn tell(&mut self, costs: Vec<f64>) -> PyResult<()> {
        if costs.len() != self.asked {
            return Err(TwinbenchError::new_err(format!(
                "tell: {} costs for the {} candidates of the last ask",
                costs.len(),
                self.asked
            )));
        }
        if let Some(k) = costs.iter().position(|c| !c.is_finite()) {
            return Err(TwinbenchError::new_err(format!(
                "tell: cost {k} is {:?}: costs are finite numbers (give a failed candidate a penalty)",
                costs[k]
            )));
        }
        self.lock().tell(&costs);
        self.asked = 0;
        Ok(())
    }

    /// The best candidate so far and its cost (None before the first tell).
    fn best(&self) -> Option<(Vec<f64>, f64)> {
        self.lock()
            .best()
            .map(|(u, c)| (to_bounds(u, &self.bounds), c))
    }

    #[getter]
    fn generation(&self) -> usize {
        self.lock().generation()
    }

    #[getter]
    fn name(&self) -> &'static str {
        self.lock().name()
    }

    /// The whole state as JSON (bit-exact), for a checkpoint.
    fn save(&self) -> PyResult<String> {
        serde_json::to_string(&self.lock().save()).map_err(error)
    }

    /// Continue from `save()`'s JSON.
    fn restore(&mut self, state: &str) -> PyResult<()> {
        let v: serde_json::Value = serde_json::from_str(state).map_err(|e| {
            TwinbenchError::new_err(format!(
                "Optimizer.restore: the state is not the JSON text Optimizer.save() gives ({e})"
            ))
        })?;
        self.lock().restore(&v).map_err(error)?;
        self.asked = 0;
        Ok(())
    }
}

impl OptimizerPy {
    fn lock(&self) -> std::sync::MutexGuard<'_, Box<dyn tb_optimize::Optimizer>> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }
}
