//! `optimize` and `load_study`: a study run from Python, its generations evaluated here or
//! on the caller's executor (a Dask cluster).

use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tb_optimize::{
    Candidate, Evaluator, EvaluatorError, GenerationDone, LapSignals, OptimizerKind, RunError,
    StopOnFlag, Study, StudyObserver,
};

use crate::errors::{error, TwinbenchError};
use crate::remote::failure_of;

/// Hands a study's generations to a `concurrent.futures.Executor`: one task per candidate,
/// `function(study_path, digest_json, step, values)` returning the cost or the reason it
/// failed; and the joint fit's laps, one task per point, `signals(study_path, digest_json,
/// values)` returning the filtered signals or the reason the run failed. A Python
/// exception (a lost cluster, Ctrl-C) stops the study; it is kept and raised as itself
/// once the study has returned.
pub(crate) struct ExecutorEvaluator {
    executor: Py<PyAny>,
    function: Py<PyAny>,
    signals: Option<Py<PyAny>>,
    study: String,
    digest: String,
    raised: Mutex<Option<PyErr>>,
}

impl ExecutorEvaluator {
    /// `function(study, digest, *args)` for each task's `args`, submitted together; the
    /// results in order, each checked by `take` (an `Err` is the executor's own failure:
    /// the remaining futures are cancelled and the error kept to be raised).
    fn tasks<T>(
        &self,
        function: &Py<PyAny>,
        args: Vec<Vec<Py<PyAny>>>,
        take: impl Fn(usize, &Bound<'_, PyAny>) -> PyResult<T>,
    ) -> Result<Vec<T>, EvaluatorError> {
        Python::attach(|py| {
            let run = || -> PyResult<Vec<T>> {
                let submit = self.executor.bind(py).getattr("submit")?;
                let mut futures = Vec::with_capacity(args.len());
                for a in args {
                    let mut all: Vec<Py<PyAny>> = vec![
                        function.clone_ref(py),
                        self.study.clone().into_pyobject(py)?.into_any().unbind(),
                        self.digest.clone().into_pyobject(py)?.into_any().unbind(),
                    ];
                    all.extend(a);
                    let all = pyo3::types::PyTuple::new(py, all)?;
                    match submit.call1(all) {
                        Ok(f) => futures.push(f),
                        Err(e) => {
                            cancel(&futures);
                            return Err(e);
                        }
                    }
                }
                let mut out = Vec::with_capacity(futures.len());
                for (k, f) in futures.iter().enumerate() {
                    match f.call_method0("result").and_then(|r| take(k, &r)) {
                        Ok(t) => out.push(t),
                        Err(e) => {
                            cancel(&futures[k..]);
                            return Err(e);
                        }
                    }
                }
                py.check_signals()?;
                Ok(out)
            };
            run().map_err(|e| {
                let text = e.to_string();
                *self.raised.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                EvaluatorError::Raised(text)
            })
        })
    }
}

impl Evaluator for ExecutorEvaluator {
    /// The cluster's workers now, when the executor says (`workers()`: twinbench's Dask
    /// executor does).
    fn workers(&self) -> Option<usize> {
        Python::attach(|py| {
            let ex = self.executor.bind(py);
            if !ex.hasattr("workers").unwrap_or(false) {
                return None;
            }
            ex.call_method0("workers").ok()?.extract::<usize>().ok()
        })
    }

    fn evaluate(
        &self,
        candidates: &[Candidate],
    ) -> Result<Vec<Result<f64, RunError>>, EvaluatorError> {
        // The task's arguments after study and digest: the step and the values.
        let args = Python::attach(|py| -> PyResult<Vec<Vec<Py<PyAny>>>> {
            candidates
                .iter()
                .map(|c| {
                    Ok(vec![
                        c.step.into_pyobject(py)?.into_any().unbind(),
                        c.values.clone().into_pyobject(py)?.into_any().unbind(),
                    ])
                })
                .collect()
        })
        .map_err(|e| EvaluatorError::Raised(e.to_string()))?;
        self.tasks(&self.function, args, |k, r| match r.extract::<f64>() {
            // A cost is e plus a bias term: finite and not negative. Anything else is a
            // broken task or cluster, not a candidate's result.
            Ok(x) if x.is_finite() && x >= 0.0 => Ok(Ok(x)),
            Ok(x) => Err(TwinbenchError::new_err(format!(
                "the executor returned {x:?} as the cost of candidate {k} of step {}: a cost is a finite number ≥ 0 (is the task or the cluster broken?)",
                candidates[k].step + 1
            ))),
            Err(_) if r.is_instance_of::<pyo3::types::PyString>() => Ok(Err(failure_of(r)?)),
            Err(_) => Err(TwinbenchError::new_err(format!(
                "the executor returned {} for candidate {k} of step {}: a task returns a cost (a float) or why the run failed (a str)",
                r.repr()?,
                candidates[k].step + 1
            ))),
        })
    }

    fn signals(
        &self,
        points: &[Vec<f64>],
    ) -> Result<Vec<Result<LapSignals, RunError>>, EvaluatorError> {
        let Some(function) = &self.signals else {
            return Err(EvaluatorError::NoSignalsTask);
        };
        let args = Python::attach(|py| -> PyResult<Vec<Vec<Py<PyAny>>>> {
            points
                .iter()
                .map(|x| Ok(vec![x.clone().into_pyobject(py)?.into_any().unbind()]))
                .collect()
        })
        .map_err(|e| EvaluatorError::Raised(e.to_string()))?;
        self.tasks(function, args, |k, r| {
            if r.is_instance_of::<pyo3::types::PyString>() {
                return Ok(Err(failure_of(r)?));
            }
            let series: Vec<(usize, Vec<u8>)> = r.extract().map_err(|_| {
                TwinbenchError::new_err(format!(
                    "the executor returned {} for point {k} of the joint fit: a task returns [(first grid index, float64 bytes)] per lap and signal, or why the run failed (a str)",
                    r.repr().map(|s| s.to_string()).unwrap_or_default()
                ))
            })?;
            series
                .into_iter()
                .map(|(start, bytes)| {
                    if bytes.len() % 8 != 0 {
                        return Err(TwinbenchError::new_err(format!(
                            "the executor returned {} bytes for a signal of point {k}: not whole float64 values",
                            bytes.len()
                        )));
                    }
                    let v = bytes
                        .chunks_exact(8)
                        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                        .collect();
                    Ok((start, v))
                })
                .collect::<PyResult<LapSignals>>()
                .map(Ok)
        })
    }
}

pub(crate) fn cancel(futures: &[Bound<'_, PyAny>]) {
    for f in futures {
        let _ = f.call_method0("cancel");
    }
}

/// Tells a Python callable about every generation (a dict per generation): the study's
/// observer for Python. An exception of the callback stops the study after that generation
/// (its checkpoint kept) and is raised as itself: a broken callback is not silently
/// skipped.
pub(crate) struct PyProgress {
    callback: Py<PyAny>,
    raised: Mutex<Option<PyErr>>,
}

impl StudyObserver for PyProgress {
    /// The refinement, the profiles and the bootstrap: a record per batch of laps. They
    /// have no generation to stop after: an exception the callback raises is raised when
    /// the study returns.
    fn phase(&self, p: &tb_optimize::PhaseProgress<'_>) {
        Python::attach(|py| {
            let d = PyDict::new(py);
            let _ = d.set_item("phase", p.phase);
            let _ = d.set_item("parameters", p.parameters.to_vec());
            let _ = d.set_item("laps", p.laps);
            let _ = d.set_item("seconds", p.seconds);
            let _ = d.set_item("done", p.done);
            if let Err(e) = self.callback.bind(py).call1((d,)) {
                let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
                raised.get_or_insert(e);
            }
        })
    }

    fn generation(&self, g: &GenerationDone<'_>) -> ControlFlow<()> {
        let record = g.record;
        Python::attach(|py| {
            let d = PyDict::new(py);
            let _ = d.set_item("phase", "generation");
            let _ = d.set_item("step", g.step);
            let _ = d.set_item("step_name", g.name);
            let _ = d.set_item("generations", g.generations);
            if let Some(w) = g.workers {
                let _ = d.set_item("workers", w);
            }
            let _ = d.set_item("generation", record.generation);
            let _ = d.set_item("evaluations", record.evaluations);
            let _ = d.set_item("best_cost", record.best_cost);
            let _ = d.set_item("best_x", record.best_x.clone());
            let _ = d.set_item("failures", record.failures);
            match self.callback.bind(py).call1((d,)) {
                Ok(_) => ControlFlow::Continue(()),
                Err(e) => {
                    let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
                    raised.get_or_insert(e);
                    ControlFlow::Break(())
                }
            }
        })
    }
}

/// `optimizer`: ga, cmaes or cma-es.
fn optimizer_kind(o: &str) -> PyResult<OptimizerKind> {
    match o {
        "ga" => Ok(OptimizerKind::Ga),
        "cmaes" | "cma-es" => Ok(OptimizerKind::Cmaes),
        _ => Err(TwinbenchError::new_err(format!(
            "unknown optimiser '{o}' (ga, cmaes)"
        ))),
    }
}

/// Runs the study on a thread of its own while this one, Python's main thread, looks for
/// Ctrl-C (Python sees a signal only where it holds the GIL): a signal sets `interrupt`,
/// and the study stops after the generation under way. The result as JSON.
fn run_watching_signals(
    py: Python<'_>,
    args: &tb_bench::study::StudyRun,
    dyn_evaluator: Option<Arc<dyn Evaluator>>,
    observers: Vec<Arc<dyn StudyObserver>>,
    interrupt: &AtomicBool,
) -> anyhow::Result<String> {
    std::thread::scope(|scope| {
        let study = scope.spawn(move || {
            tb_bench::study::optimize(args, dyn_evaluator, observers)
                .and_then(|o| Ok(serde_json::to_string(&o.result)?))
        });
        while !study.is_finished() {
            py.detach(|| std::thread::sleep(std::time::Duration::from_millis(50)));
            if py.check_signals().is_err() && !interrupt.swap(true, Ordering::SeqCst) {
                eprintln!("interrupt: stopping after the generation under way");
            }
        }
        study.join().unwrap_or_else(|p| {
            Err(anyhow::anyhow!(
                "the study panicked: {}",
                p.downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| p.downcast_ref::<&str>().copied())
                    .unwrap_or("(no message)")
            ))
        })
    })
}

/// Runs a study as `twinbench optimize --json` does (same files in `out`); returns the
/// result as JSON. `executor` and `function`: evaluate the generations there.
#[pyfunction]
#[pyo3(signature = (study, out, threads, resume, generations, optimizer, force, no_report, executor=None, function=None, digest=None, progress=None, profiles=false, signals=None, bootstrap=0))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn optimize(
    py: Python<'_>,
    study: PathBuf,
    out: PathBuf,
    threads: usize,
    resume: bool,
    generations: Option<usize>,
    optimizer: Option<String>,
    force: bool,
    no_report: bool,
    executor: Option<Py<PyAny>>,
    function: Option<Py<PyAny>>,
    digest: Option<String>,
    progress: Option<Py<PyAny>>,
    profiles: bool,
    signals: Option<Py<PyAny>>,
    bootstrap: usize,
) -> PyResult<String> {
    let optimizer = optimizer.map(|o| optimizer_kind(&o)).transpose()?;
    let evaluator = match (executor, function) {
        (Some(executor), Some(function)) => Some(Arc::new(ExecutorEvaluator {
            executor,
            function,
            signals,
            study: study.display().to_string(),
            digest: digest.unwrap_or_default(),
            raised: Mutex::new(None),
        })),
        _ => None,
    };
    let args = tb_bench::study::StudyRun {
        study,
        resume,
        verbose: false,
        threads,
        out,
        optimizer,
        generations,
        no_report,
        force,
        profiles,
        bootstrap,
    };
    let (args_study, args_out, resume) =
        (args.study.clone(), args.out.clone(), args.resume_command());
    let dyn_evaluator = evaluator.clone().map(|e| e as Arc<dyn Evaluator>);
    // The study runs on a thread of its own while this one, Python's main thread, looks
    // for Ctrl-C: Python sees a signal only where it holds the GIL, never inside the
    // study. On KeyboardInterrupt the study stops after the generation under way, its
    // checkpoint kept, and the KeyboardInterrupt says how to resume.
    let interrupt = Arc::new(AtomicBool::new(false));
    let py_progress = progress.map(|callback| {
        Arc::new(PyProgress {
            callback,
            raised: Mutex::new(None),
        })
    });
    // Observers: the callback, then Ctrl-C's stop after the generation (the report last).
    let mut observers: Vec<Arc<dyn StudyObserver>> = Vec::new();
    if let Some(p) = &py_progress {
        observers.push(p.clone());
    }
    observers.push(Arc::new(StopOnFlag(interrupt.clone())));
    let result = run_watching_signals(py, &args, dyn_evaluator, observers, &interrupt);
    if let Some(e) = evaluator.and_then(|e| e.raised.lock().ok().and_then(|mut r| r.take())) {
        return Err(e);
    }
    if let Some(e) = py_progress.and_then(|p| p.raised.lock().ok().and_then(|mut r| r.take())) {
        return Err(e);
    }
    match result {
        Err(e) => match e.downcast_ref::<tb_bench::study::Interrupted>() {
            Some(i) => Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(format!(
                "interrupted: checkpoint kept ({}); resume with study.optimize(..., resume=True) or `{}`",
                i.checkpoint, i.resume
            ))),
            None => Err(error(e)),
        },
        // Ctrl-C came after the last generation's check, while the study finished: its
        // result is complete and written, but a Ctrl-C is never swallowed (Python raises
        // KeyboardInterrupt for it), so it is raised now, saying where the result is.
        Ok(_) if interrupt.load(Ordering::SeqCst) => {
            let checkpoint = checkpoint_of(&args_study, &args_out);
            Err(pyo3::exceptions::PyKeyboardInterrupt::new_err(format!(
                "interrupted: checkpoint kept ({checkpoint}); the study had already finished its last generation, and its result is complete in {} (study.optimize(..., resume=True) or `{resume}` returns it)",
                args_out.display()
            )))
        }
        Ok(r) => Ok(r),
    }
}

/// The checkpoint a study writes into `out` (`<name>.checkpoint.json`), as shown in messages.
pub(crate) fn checkpoint_of(study: &std::path::Path, out: &std::path::Path) -> String {
    let name = Study::load(study).map(|s| s.name()).unwrap_or_default();
    out.join(format!("{name}.checkpoint.json"))
        .display()
        .to_string()
}

/// A study file read and checked (for `twinbench.Study`): its name, the paths of its
/// system and measurement, its fingerprint, penalty and seed.
#[pyfunction]
pub(crate) fn load_study(path: PathBuf) -> PyResult<(String, String, String, String, f64, u64)> {
    let s = Study::load(&path).map_err(error)?;
    Ok((
        s.name(),
        s.system_path.display().to_string(),
        s.measurement_path.display().to_string(),
        s.fingerprint.clone(),
        s.file.penalty,
        s.file.seed,
    ))
}
