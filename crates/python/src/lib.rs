//! `twinbench._native`: the Rust side of the Python package (`python/twinbench`). Each
//! function is a thin call into the same library code the command line runs, with the GIL
//! released while it simulates; errors are `twinbench.TwinbenchError` with the command
//! line's message. The Python modules add the types, docstrings and numpy/pandas views.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyList};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tb_cosim::config::StopConfig;
use tb_cosim::{LoadOptions, Plan, Simulation};
use tb_fmi::FmuCache;
use tb_optimize::optimizer::{to_bounds, to_unit};
use tb_optimize::{
    Candidate, Cmaes, Evaluator, Ga, GenerationDone, LapSignals, OptimizerKind, StopOnFlag, Study,
    StudyEvaluator, StudyObserver,
};

// Declared in the module `twinbench`, where the package exports it: Python shows it as
// `twinbench.TwinbenchError`.
create_exception!(
    twinbench,
    TwinbenchError,
    PyException,
    "An error of twinbench: a bad file, a wrong name, a failed run (the message is the command line's)."
);

/// An error as the command line prints it (the whole chain, `error: ` left off).
fn error(e: impl Into<anyhow::Error>) -> PyErr {
    TwinbenchError::new_err(twinbench::bench::message(&e.into()))
}

/// A Python value as the TOML value `--set` would give the same text.
fn toml_value(v: &Bound<'_, PyAny>, name: &str) -> PyResult<toml::Value> {
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(v.extract()?));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(toml::Value::Integer(i));
    }
    if let Ok(x) = v.extract::<f64>() {
        return Ok(toml::Value::Float(x));
    }
    if let Ok(s) = v.extract::<String>() {
        return Ok(toml::Value::String(s));
    }
    Err(TwinbenchError::new_err(format!(
        "parameter \"{name}\": expected a number, a boolean or a string, got {}",
        v.get_type().name()?
    )))
}

/// Runs a system; returns a dict with `names`, `units`, `columns` (little-endian float64
/// bytes per column), `text` (the String columns) and `summary`.
/// `observer` is called as `observer(time, values)` at the start, every `every` s of
/// simulated time (default: each recorded row's interval) and at the end.
#[pyfunction]
#[pyo3(signature = (system, parameters=None, stop=None, observer=None, every=None))]
fn run(
    py: Python<'_>,
    system: PathBuf,
    parameters: Option<Vec<(String, Bound<'_, PyAny>)>>,
    stop: Option<Bound<'_, PyAny>>,
    observer: Option<Py<PyAny>>,
    every: Option<f64>,
) -> PyResult<Py<PyAny>> {
    if let Some(e) = every.filter(|e| !(e.is_finite() && *e > 0.0)) {
        return Err(TwinbenchError::new_err(format!(
            "every = {e}: expected a positive time in s (how often the observer is called)"
        )));
    }
    let raised: Arc<Mutex<Option<PyErr>>> = Arc::default();
    let observer_raised = raised.clone();
    let parameters: Vec<(String, toml::Value)> = parameters
        .unwrap_or_default()
        .into_iter()
        .map(|(n, v)| toml_value(&v, &n).map(|t| (n, t)))
        .collect::<PyResult<_>>()?;
    let stop = match stop {
        None => None,
        Some(s) if s.is_instance_of::<PyBool>() => {
            return Err(TwinbenchError::new_err(
                "stop: expected a time in s or a condition such as \"vehicle.lap >= 1\"",
            ))
        }
        Some(s) => Some(match s.extract::<f64>() {
            Ok(t) => StopConfig::Time(t),
            Err(_) => StopConfig::Word(s.extract::<String>().map_err(|_| {
                TwinbenchError::new_err(
                    "stop: expected a time in s or a condition such as \"vehicle.lap >= 1\"",
                )
            })?),
        }),
    };
    let outcome = py.detach(move || -> anyhow::Result<_> {
        let cache = Arc::new(FmuCache::temporary(false)?);
        // One FMU, run on its own as `twinbench run model.fmu` runs it (its default
        // experiment, every output, its own variable names).
        let alone = twinbench::cli::run_fmu::is_fmu(&system);
        let (mut file, instance) = if alone {
            use clap::{Args, FromArgMatches};
            let path = system.to_string_lossy().into_owned();
            let matches = twinbench::cli::run::RunArgs::augment_args(clap::Command::new("run"))
                .try_get_matches_from(["run", path.as_str()])?;
            let args = twinbench::cli::run::RunArgs::from_arg_matches(&matches)?;
            let (file, instance) = twinbench::cli::run_fmu::system(&args, &cache)?;
            (file, Some(instance))
        } else {
            (Plan::read_system(&system, &cache)?, None)
        };
        if let Some(s) = stop {
            file.experiment.stop = s;
        }
        let options = LoadOptions {
            native_models: twinbench::registry::native_models(),
            ..LoadOptions::default()
        };
        let plan = Arc::new(Plan::compile(file, &system, cache, &options)?);
        let mut sim = Simulation::new(plan.clone())?;
        sim.echo_fmu_log = false;
        if let Some(instance) = &instance {
            twinbench::cli::run_fmu::own_names(sim.recording_mut(), instance)?;
        }
        for (name, value) in &parameters {
            // One FMU: its own variable names, as the command line's --set takes them.
            let name = match &instance {
                Some(i) if plan.parameter(name).is_err() => format!("{i}.{name}"),
                _ => name.clone(),
            };
            let name = &name;
            twinbench::bench::set_parameter(&plan, &mut sim, name, value)
                .map_err(|e| e.context(format!("parameters[\"{name}\"]")))?;
        }
        // Ctrl-C while the run goes on: KeyboardInterrupt after the step under way.
        sim.observe(Box::new(PySignals {
            interval: tb_cosim::observe::WallClockInterval::default(),
            raised: observer_raised.clone(),
        }));
        if let Some(callback) = observer {
            sim.observe(Box::new(PyRunObserver::new(
                &plan,
                callback,
                every,
                observer_raised,
            )));
        }
        let summary = sim.run();
        drop(sim.take_observers());
        let summary = summary?;
        let lap_time = twinbench::bench::lap_time(&summary, &plan);
        let order: Vec<String> = plan
            .order
            .iter()
            .map(|&k| plan.unit_name(k).to_string())
            .collect();
        Ok((summary, lap_time, order, plan.warnings.clone(), sim))
    });
    // An exception of the observer is raised as itself.
    if let Some(e) = raised.lock().unwrap_or_else(|p| p.into_inner()).take() {
        return Err(e);
    }
    let (summary, lap_time, order, warnings, sim) = outcome.map_err(error)?;
    let rec = sim.recording();
    let d = PyDict::new(py);
    d.set_item("names", rec.names().to_vec())?;
    d.set_item("units", rec.units().map(|u| u.to_vec()))?;
    let columns = PyList::empty(py);
    let text = PyDict::new(py);
    for (k, name) in rec.names().iter().enumerate() {
        let bytes: Vec<u8> = rec
            .column_at(k)
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        columns.append(PyBytes::new(py, &bytes))?;
        if let Some(t) = rec.text_at(k) {
            text.set_item(name, t.to_vec())?;
        }
    }
    d.set_item("columns", columns)?;
    d.set_item("text", text)?;
    let s = PyDict::new(py);
    s.set_item("system", system_name(&sim))?;
    s.set_item("steps", summary.steps)?;
    s.set_item("simulated_time", summary.simulated_time)?;
    s.set_item("wall_time", summary.wall_time)?;
    s.set_item("lap_time", lap_time)?;
    s.set_item("stopped_by", summary.stopped_by.clone())?;
    s.set_item("reported", summary.reported.clone())?;
    s.set_item("order", order)?;
    s.set_item("warnings", warnings)?;
    d.set_item("summary", s)?;
    Ok(d.into_any().unbind())
}

/// Asks Python whether a signal came (Ctrl-C) about once per millisecond of wall time of a
/// run: its exception (KeyboardInterrupt) fails the run and is raised as itself.
struct PySignals {
    interval: tb_cosim::observe::WallClockInterval,
    raised: Arc<Mutex<Option<PyErr>>>,
}

impl tb_cosim::RunObserver for PySignals {
    fn step_interval(&self) -> u64 {
        self.interval.steps()
    }

    fn observe(
        &mut self,
        now: &mut tb_cosim::RunView<'_>,
    ) -> Result<ControlFlow<String>, tb_cosim::SystemError> {
        self.interval.called();
        Python::attach(|py| {
            py.check_signals().inspect_err(|e| {
                // Where the run was stopped, on the exception itself (Python 3.11+).
                let note = format!(
                    "twinbench.run: stopped after the step to t = {} s",
                    tb_files::number(now.time())
                );
                let _ = e.value(py).call_method1("add_note", (note,));
            })
        })
        .map_err(|e| {
            let message = format!("{e} at t = {} s", tb_files::number(now.time()));
            let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
            raised.get_or_insert(e);
            tb_cosim::SystemError::Stop(message)
        })?;
        Ok(ControlFlow::Continue(()))
    }
}

/// Calls a Python callable with the time and the recorded signals' values during a run (a
/// live plot, a progress display, a condition of one's own). It returns None or True to go
/// on, False or a reason (str) to end the run there; an exception fails the run and is
/// raised as itself.
struct PyRunObserver {
    callback: Py<PyAny>,
    /// The recorded signals: name, slot, text.
    signals: Vec<(String, usize, bool)>,
    /// Called every this many steps.
    every_steps: u64,
    raised: Arc<Mutex<Option<PyErr>>>,
    /// The time of the last call (the end is not told twice).
    last_call: Option<f64>,
}

impl PyRunObserver {
    fn new(
        plan: &Plan,
        callback: Py<PyAny>,
        every: Option<f64>,
        raised: Arc<Mutex<Option<PyErr>>>,
    ) -> PyRunObserver {
        let h = plan.file.experiment.step;
        let every_steps = match every {
            Some(e) => (e / h).round().max(1.0) as u64,
            None => plan.file.record.decimation as u64,
        };
        let signals = plan
            .record
            .iter()
            .zip(&plan.record_names)
            .map(|(&slot, name)| (name.clone(), slot, plan.signals.signals[slot].is_text()))
            .collect();
        PyRunObserver {
            callback,
            signals,
            every_steps: every_steps.max(1),
            raised,
            last_call: None,
        }
    }

    fn call(
        &mut self,
        now: &mut tb_cosim::RunView<'_>,
    ) -> Result<ControlFlow<String>, tb_cosim::SystemError> {
        let t = now.time();
        self.last_call = Some(t);
        let values = now.signals()?.to_vec();
        let texts = match self.signals.iter().any(|s| s.2) {
            true => now.texts()?.to_vec(),
            false => Vec::new(),
        };
        Python::attach(|py| {
            let answer = (|| -> PyResult<ControlFlow<String>> {
                // Ctrl-C while Python watches: KeyboardInterrupt, raised as itself.
                py.check_signals()?;
                let d = PyDict::new(py);
                for (name, slot, text) in &self.signals {
                    match text {
                        true => d.set_item(name, &texts[*slot])?,
                        false => d.set_item(name, values[*slot])?,
                    }
                }
                let r = self.callback.bind(py).call1((t, d))?;
                if r.is_none() {
                    return Ok(ControlFlow::Continue(()));
                }
                if let Ok(b) = r.cast::<PyBool>() {
                    return Ok(match b.is_true() {
                        true => ControlFlow::Continue(()),
                        false => ControlFlow::Break(format!(
                            "the observer at t = {} s",
                            tb_files::number(t)
                        )),
                    });
                }
                match r.extract::<String>() {
                    Ok(reason) => Ok(ControlFlow::Break(reason)),
                    Err(_) => Err(pyo3::exceptions::PyTypeError::new_err(format!(
                        "the run's observer returned {}: expected None or True (go on), False or a reason (str) to end the run",
                        r.repr().map(|s| s.to_string()).unwrap_or_default()
                    ))),
                }
            })();
            answer.map_err(|e| {
                let message = format!("the observer raised {e} at t = {} s", tb_files::number(t));
                let mut raised = self.raised.lock().unwrap_or_else(|p| p.into_inner());
                raised.get_or_insert(e);
                tb_cosim::SystemError::Stop(message)
            })
        })
    }
}

impl tb_cosim::RunObserver for PyRunObserver {
    fn step_interval(&self) -> u64 {
        self.every_steps
    }

    fn observe(
        &mut self,
        now: &mut tb_cosim::RunView<'_>,
    ) -> Result<ControlFlow<String>, tb_cosim::SystemError> {
        match now.moment() {
            tb_cosim::Moment::Start => self.call(now),
            // Every `every_steps`-th step (`step_interval`).
            tb_cosim::Moment::Step { .. } => self.call(now),
            _ => Ok(ControlFlow::Continue(())),
        }
    }

    fn finished(
        &mut self,
        now: &mut tb_cosim::RunView<'_>,
        _how: &tb_cosim::Ended,
    ) -> Result<(), tb_cosim::SystemError> {
        if self.last_call != Some(now.time()) {
            // The run has ended: a reason to end it changes nothing.
            let _ = self.call(now)?;
        }
        Ok(())
    }
}

fn system_name(sim: &Simulation) -> String {
    sim.plan().path.display().to_string()
}

/// Compares named columns (little-endian float64 bytes each) with a measurement file;
/// returns the comparison as JSON.
#[pyfunction]
#[pyo3(signature = (names, columns, measurement, signals, cutoff_hz, filter_order, distance_step_m, min_coverage, channels=None))]
#[allow(clippy::too_many_arguments)]
fn compare(
    py: Python<'_>,
    names: Vec<String>,
    columns: Vec<Vec<u8>>,
    measurement: PathBuf,
    signals: Vec<String>,
    cutoff_hz: f64,
    filter_order: usize,
    distance_step_m: f64,
    min_coverage: f64,
    channels: Option<PathBuf>,
) -> PyResult<String> {
    py.detach(move || -> anyhow::Result<String> {
        let columns: Vec<Vec<f64>> = columns
            .iter()
            .map(|b| {
                b.chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect()
            })
            .collect();
        let sim = tb_table::Table::from_columns("simulation", names, columns)?;
        let settings = tb_compare::CompareSettings {
            cutoff_hz,
            filter_order,
            distance_step_m,
            min_coverage,
            ..tb_compare::CompareSettings::default()
        };
        let cmp = twinbench::bench::compare_table(
            &sim,
            &measurement,
            channels.as_deref(),
            &signals,
            &settings,
        )?;
        Ok(serde_json::to_string(&cmp)?)
    })
    .map_err(error)
}

/// Hands a study's generations to a `concurrent.futures.Executor`: one task per candidate,
/// `function(study_path, digest_json, step, values)` returning the cost or the reason it
/// failed; and the joint fit's laps, one task per point, `signals(study_path, digest_json,
/// values)` returning the filtered signals or the reason the run failed. A Python
/// exception (a lost cluster, Ctrl-C) stops the study; it is kept and raised as itself
/// once the study has returned.
struct ExecutorEvaluator {
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
    ) -> Result<Vec<T>, String> {
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
                text
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

    fn evaluate(&self, candidates: &[Candidate]) -> Result<Vec<Result<f64, String>>, String> {
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
        .map_err(|e| e.to_string())?;
        self.tasks(&self.function, args, |k, r| match r.extract::<f64>() {
            // A cost is e plus a bias term: finite and not negative. Anything else is a
            // broken task or cluster, not a candidate's result.
            Ok(x) if x.is_finite() && x >= 0.0 => Ok(Ok(x)),
            Ok(x) => Err(TwinbenchError::new_err(format!(
                "the executor returned {x:?} as the cost of candidate {k} of step {}: a cost is a finite number ≥ 0 (is the task or the cluster broken?)",
                candidates[k].step + 1
            ))),
            Err(_) if r.is_instance_of::<pyo3::types::PyString>() => Ok(Err(r.str()?.to_string())),
            Err(_) => Err(TwinbenchError::new_err(format!(
                "the executor returned {} for candidate {k} of step {}: a task returns a cost (a float) or why the run failed (a str)",
                r.repr()?,
                candidates[k].step + 1
            ))),
        })
    }

    fn signals(&self, points: &[Vec<f64>]) -> Result<Vec<Result<LapSignals, String>>, String> {
        let Some(function) = &self.signals else {
            return Err("no signals task was given with the executor".into());
        };
        let args = Python::attach(|py| -> PyResult<Vec<Vec<Py<PyAny>>>> {
            points
                .iter()
                .map(|x| Ok(vec![x.clone().into_pyobject(py)?.into_any().unbind()]))
                .collect()
        })
        .map_err(|e| e.to_string())?;
        self.tasks(function, args, |k, r| {
            if r.is_instance_of::<pyo3::types::PyString>() {
                return Ok(Err(r.str()?.to_string()));
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

fn cancel(futures: &[Bound<'_, PyAny>]) {
    for f in futures {
        let _ = f.call_method0("cancel");
    }
}

/// Tells a Python callable about every generation (a dict per generation): the study's
/// observer for Python. An exception of the callback stops the study after that generation
/// (its checkpoint kept) and is raised as itself: a broken callback is not silently
/// skipped.
struct PyProgress {
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

/// Runs a study as `twinbench optimize --json` does (same files in `out`); returns the
/// result as JSON. `executor` and `function`: evaluate the generations there.
#[pyfunction]
#[pyo3(signature = (study, out, threads, resume, generations, optimizer, force, no_report, executor=None, function=None, digest=None, progress=None, profiles=false, signals=None, bootstrap=0))]
#[allow(clippy::too_many_arguments)]
fn optimize(
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
    let optimizer = optimizer
        .map(|o| match o.as_str() {
            "ga" => Ok(OptimizerKind::Ga),
            "cmaes" | "cma-es" => Ok(OptimizerKind::Cmaes),
            _ => Err(TwinbenchError::new_err(format!(
                "unknown optimiser '{o}' (ga, cmaes)"
            ))),
        })
        .transpose()?;
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
    let args = twinbench::study::StudyRun {
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
    let result = std::thread::scope(|scope| {
        let study = scope.spawn(move || {
            twinbench::study::optimize(&args, dyn_evaluator, observers)
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
    });
    if let Some(e) = evaluator.and_then(|e| e.raised.lock().ok().and_then(|mut r| r.take())) {
        return Err(e);
    }
    if let Some(e) = py_progress.and_then(|p| p.raised.lock().ok().and_then(|mut r| r.take())) {
        return Err(e);
    }
    match result {
        Err(e) => match e.downcast_ref::<twinbench::study::Interrupted>() {
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
fn checkpoint_of(study: &std::path::Path, out: &std::path::Path) -> String {
    let name = Study::load(study).map(|s| s.name()).unwrap_or_default();
    out.join(format!("{name}.checkpoint.json"))
        .display()
        .to_string()
}

/// A step as Python sees it: name, parameter names, bounds, start values.
type StepInfo = (String, Vec<String>, Vec<(f64, f64)>, Vec<Option<f64>>);

/// A study loaded for evaluating candidates: in a worker process (kept between tasks) or
/// for the ask/tell loop of an optimiser of the user's own.
#[pyclass(frozen)]
struct StudyEvaluatorPy {
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
            Err(why) => why.into_pyobject(py)?.into_any().unbind(),
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
                move || -> Result<Vec<Result<f64, String>>, tb_optimize::OptimizeError> {
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
fn outcome_object(py: Python<'_>, r: Result<f64, String>) -> PyResult<Py<PyAny>> {
    Ok(match r {
        Ok(c) => c.into_pyobject(py)?.into_any().unbind(),
        Err(s) => s.into_pyobject(py)?.into_any().unbind(),
    })
}

/// One of twinbench's optimisers, ask/tell, in the problem's own units (its bounds).
#[pyclass]
struct OptimizerPy {
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

/// A study file read and checked (for `twinbench.Study`): its name, the paths of its
/// system and measurement, its fingerprint, penalty and seed.
#[pyfunction]
fn load_study(path: PathBuf) -> PyResult<(String, String, String, String, f64, u64)> {
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

/// Packs twinbench's FMUs (`vehicle`, `driver`, `dyno`, `edu`, or those named) into `out`
/// (default: the folder `twinbench pack` writes to); returns their paths.
#[pyfunction]
#[pyo3(signature = (out=None, models=None))]
fn pack(
    py: Python<'_>,
    out: Option<PathBuf>,
    models: Option<Vec<String>>,
) -> PyResult<Vec<PathBuf>> {
    let out = out.unwrap_or_else(twinbench::pack::default_fmu_dir);
    let models = models.unwrap_or_default();
    py.detach(|| twinbench::pack::pack(&models, &out))
        .map_err(error)
}

/// The fitted twin of the study result at `result` handed on into `out` (as `twinbench
/// export-twin`): FMUs with the answer as start values (FMI `versions`, 2 and/or 3), SSP,
/// SSV, the system file and the parameter table; returns the summary as JSON.
#[pyfunction]
#[pyo3(signature = (result, out, versions))]
fn export_twin(
    py: Python<'_>,
    result: PathBuf,
    out: PathBuf,
    versions: Vec<u32>,
) -> PyResult<String> {
    let mut v = Vec::new();
    for x in versions {
        v.push(
            twinbench::pack::FmiVersion::parse(&x.to_string()).ok_or_else(|| {
                TwinbenchError::new_err(format!("fmi: {x} is not an FMI version (2 or 3)"))
            })?,
        );
    }
    v.sort();
    v.dedup();
    let ex = py
        .detach(|| {
            twinbench::export_twin::export_twin(
                &result,
                &out,
                &twinbench::export_twin::ExportOptions { versions: v },
            )
        })
        .map_err(error)?;
    serde_json::to_string(&ex).map_err(error)
}

/// `twinbench realtime-check` of an FMU, or of every FMU of a bench (a `.toml` system):
/// the report as JSON (a list of `{instance, report}` for a bench). `worker` is the
/// `twinbench` executable the FMU runs in (only it counts allocations).
#[pyfunction]
#[pyo3(signature = (fmu, worker, step=None, duration=None, input=None, passes=10, budget=None, instructions=false, isolate="confined", timeout=600.0, preload=Vec::new()))]
#[allow(clippy::too_many_arguments)]
fn realtime_check(
    py: Python<'_>,
    fmu: PathBuf,
    worker: PathBuf,
    step: Option<f64>,
    duration: Option<f64>,
    input: Option<PathBuf>,
    passes: u32,
    budget: Option<f64>,
    instructions: bool,
    isolate: &str,
    timeout: f64,
    preload: Vec<PathBuf>,
) -> PyResult<String> {
    let mode = match isolate {
        "confined" => tb_cosim::isolated::confine::Mode::Confined,
        "crash-only" => tb_cosim::isolated::confine::Mode::CrashOnly,
        other => {
            return Err(TwinbenchError::new_err(format!(
                "isolate={other:?}: expected \"confined\" or \"crash-only\""
            )))
        }
    };
    let o = twinbench::realtime_check::Options {
        fmu: fmu.clone(),
        step,
        duration,
        input,
        passes,
        budget,
        instructions,
        mode,
        timeout,
        preload,
        worker_exe: Some(worker),
    };
    let json = py.detach(|| -> anyhow::Result<String> {
        if fmu.extension().is_some_and(|e| e == "toml") {
            Ok(serde_json::to_string(
                &twinbench::realtime_check::check_bench(&fmu, &o)?,
            )?)
        } else {
            Ok(serde_json::to_string(&twinbench::realtime_check::check(
                &o,
            )?)?)
        }
    });
    json.map_err(error)
}

/// Every warning of the Rust code (`log::warn!`), kept until the call returns to Python,
/// whose package turns each into a `warnings.warn` (`TwinbenchWarning`): none is dropped
/// (M13), and no Python is called from the simulation's threads.
struct KeptWarnings;

static KEPT: Mutex<Vec<String>> = Mutex::new(Vec::new());
/// At most this many kept between two returns to Python (a flood is said, not kept).
const KEPT_MAX: usize = 1000;

impl log::Log for KeptWarnings {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Warn
    }
    fn log(&self, r: &log::Record) {
        if !self.enabled(r.metadata()) {
            return;
        }
        let mut kept = KEPT.lock().unwrap_or_else(|p| p.into_inner());
        match kept.len() {
            n if n < KEPT_MAX => kept.push(r.args().to_string()),
            KEPT_MAX => kept.push(format!(
                "more than {KEPT_MAX} warnings; the rest is not shown"
            )),
            _ => {}
        }
    }
    fn flush(&self) {}
}

static KEPT_WARNINGS: KeptWarnings = KeptWarnings;

/// The warnings kept since the last call (and forgets them).
#[pyfunction]
fn take_warnings() -> Vec<String> {
    std::mem::take(&mut *KEPT.lock().unwrap_or_else(|p| p.into_inner()))
}

/// Take `root` as a mirror of the coordinator's files (a cluster worker's copy of a
/// study, each file at the coordinator's absolute path below it): names in the files
/// below it resolve inside it, and digests name the files as the coordinator does.
#[pyfunction]
fn register_mirror(root: PathBuf) {
    tb_files::register_mirror(&root);
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    // A host that installed its own logger keeps it.
    if log::set_logger(&KEPT_WARNINGS).is_ok() {
        log::set_max_level(log::LevelFilter::Warn);
    }
    m.add_function(wrap_pyfunction!(take_warnings, m)?)?;
    m.add("TwinbenchError", m.py().get_type::<TwinbenchError>())?;
    // The package's version is the workspace's (the wheel's metadata says the same).
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(pack, m)?)?;
    m.add_function(wrap_pyfunction!(export_twin, m)?)?;
    m.add_function(wrap_pyfunction!(realtime_check, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(optimize, m)?)?;
    m.add_function(wrap_pyfunction!(load_study, m)?)?;
    m.add_function(wrap_pyfunction!(register_mirror, m)?)?;
    m.add_class::<StudyEvaluatorPy>()?;
    m.add_class::<OptimizerPy>()?;
    Ok(())
}
