//! `run`: a system simulated, with a Python observer of its moments.

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyList};
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use tb_cosim::config::StopConfig;
use tb_cosim::{LoadOptions, Plan, Simulation};
use tb_fmi::FmuCache;

use crate::errors::{error, toml_value, TwinbenchError};

/// Runs a system; returns a dict with `names`, `units`, `columns` (little-endian float64
/// bytes per column), `text` (the String columns) and `summary`.
/// `observer` is called as `observer(time, values)` at the start, every `every` s of
/// simulated time (default: each recorded row's interval) and at the end.
#[pyfunction]
#[pyo3(signature = (system, parameters=None, stop=None, observer=None, every=None))]
pub(crate) fn run(
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
    let stop = stop_condition(stop)?;
    let outcome = py.detach(move || -> anyhow::Result<_> {
        let cache = Arc::new(FmuCache::temporary(false)?);
        let (mut file, instance) = system_file(&system, &cache)?;
        if let Some(s) = stop {
            file.experiment.stop = s;
        }
        let options = LoadOptions {
            native_models: tb_bench::registry::native_models(),
            ..LoadOptions::default()
        };
        let plan = Arc::new(Plan::compile(file, &system, cache, &options)?);
        let mut sim = Simulation::new(plan.clone())?;
        sim.echo_fmu_log = false;
        if let Some(instance) = &instance {
            tb_bench::run_fmu::own_names(sim.recording_mut(), instance)?;
        }
        for (name, value) in &parameters {
            // One FMU: its own variable names, as the command line's --set takes them.
            let name = match &instance {
                Some(i) if plan.parameter(name).is_err() => format!("{i}.{name}"),
                _ => name.clone(),
            };
            let name = &name;
            tb_bench::bench::set_parameter(&plan, &mut sim, name, value)
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
        let lap_time = tb_bench::bench::lap_time(&summary, &plan);
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
    result_dict(py, &sim, &summary, lap_time, order, warnings)
}

/// `stop`: a time in s or a condition as the system file's, never a boolean.
fn stop_condition(stop: Option<Bound<'_, PyAny>>) -> PyResult<Option<StopConfig>> {
    Ok(match stop {
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
    })
}

/// The system file of `system`; one FMU is run on its own as `twinbench run model.fmu` runs
/// it (its default experiment, every output, its own variable names), and its instance's
/// name comes with it.
fn system_file(
    system: &std::path::Path,
    cache: &Arc<FmuCache>,
) -> anyhow::Result<(tb_cosim::config::SystemFile, Option<String>)> {
    let alone = tb_bench::run_fmu::is_fmu(system);
    Ok(if alone {
        let options = tb_bench::run_fmu::FmuRun::new(system);
        let (file, instance) = tb_bench::run_fmu::system(&options, cache)?;
        (file, Some(instance))
    } else {
        (Plan::read_system(system, cache)?, None)
    })
}

/// The run as Python's `twinbench.run` returns it: names, units, the columns as bytes, the
/// String columns and the summary.
fn result_dict(
    py: Python<'_>,
    sim: &Simulation,
    summary: &tb_cosim::RunSummary,
    lap_time: Option<f64>,
    order: Vec<String>,
    warnings: Vec<String>,
) -> PyResult<Py<PyAny>> {
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
    s.set_item("system", system_name(sim))?;
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
pub(crate) struct PySignals {
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
pub(crate) struct PyRunObserver {
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

pub(crate) fn system_name(sim: &Simulation) -> String {
    sim.plan().path.display().to_string()
}
