//! The worker pool: candidates run on the co-simulated bench. The study's system is
//! compiled once into a plan; a pool of workers, each owning one [`Simulation`] of that
//! plan (its FMU instances are reset and reused between candidates, never
//! re-instantiated) and one comparison [`Workspace`]. A worker is created the first time a
//! thread finds the pool empty, so there are at most as many as evaluations run at once.
//!
//! Every parameter the study touches is resolved to a [`ParamSlot`] once; a candidate is a
//! value for each of them (all of them, on every run: a worker keeps nothing of the
//! candidate it ran before).

use super::study::{Lap, Study};
use crate::error::OptimizeError;
use crate::failure::RunError;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tb_compare::{Comparison, PreparedMeasurement, Table, Workspace};
use tb_cosim::{LoadOptions, ParamSlot, ParamValue, Plan, Simulation, SystemError, SystemFile};
use tb_fmi::FmuCache;

struct Worker {
    sim: Simulation,
    ws: Workspace,
}

/// The system of a study compiled once, with the pool of workers that run candidates on
/// it from several threads.
pub struct WorkerPool {
    plan: Arc<Plan>,
    /// Every parameter the study touches, in the study's order (fixed ones first).
    slots: Vec<ParamSlot>,
    /// Their values before the study (fixed values, else the system's).
    initial: Vec<f64>,
    /// The study's fixed values that are not numbers (strings, integers, booleans).
    fixed: Vec<(ParamSlot, ParamValue)>,
    workers: Mutex<Vec<Worker>>,
    created: AtomicUsize,
    runs: AtomicUsize,
    run_seconds: Mutex<f64>,
}

/// One candidate's simulation compared with the measurement.
pub struct Outcome {
    pub comparison: Comparison,
    /// The recording on its uniform time grid (what the comparison used).
    pub table: Table,
}

impl WorkerPool {
    /// Compiles the study's system (with its record override) and resolves every parameter
    /// the study touches: a bad system or study parameter is an error here, up front.
    pub fn new(study: &Study, cache: Arc<FmuCache>) -> Result<WorkerPool, OptimizeError> {
        Self::for_lap(study, &study.laps[0], cache)
    }

    /// The worker pool of one lap of the study: its system, the study's parameters and the
    /// lap's own values (set on every worker, never part of the assignment: every lap's
    /// pool has the same assignment, in the same order).
    pub fn for_lap(
        study: &Study,
        lap: &Lap,
        cache: Arc<FmuCache>,
    ) -> Result<WorkerPool, OptimizeError> {
        let plan = compile_lap(study, lap, cache)?;
        let mut sim = Simulation::new(plan.clone())?;
        sim.echo_fmu_log = false;
        let (mut slots, mut initial, fixed) = fixed_values(study, lap, &plan)?;
        for (slot, v) in &fixed {
            sim.set(slot, v.clone());
        }
        add_step_parameters(study, &plan, &sim, &mut slots, &mut initial)?;
        let pool = WorkerPool {
            plan,
            slots,
            initial,
            fixed,
            workers: Mutex::new(vec![Worker {
                sim,
                ws: Workspace::new(),
            }]),
            created: AtomicUsize::new(1),
            runs: AtomicUsize::new(0),
            run_seconds: Mutex::new(0.0),
        };
        Ok(pool)
    }

    fn new_worker(&self) -> Result<Worker, SystemError> {
        let mut sim = Simulation::new(self.plan.clone())?;
        sim.echo_fmu_log = false;
        for (slot, v) in &self.fixed {
            sim.set(slot, v.clone());
        }
        self.created.fetch_add(1, Ordering::Relaxed);
        Ok(Worker {
            sim,
            ws: Workspace::new(),
        })
    }

    /// The compiled system.
    pub fn plan(&self) -> &Arc<Plan> {
        &self.plan
    }

    /// Every parameter the study touches, with its value before the study.
    pub fn assignment(&self) -> Vec<(String, f64)> {
        self.slots
            .iter()
            .zip(&self.initial)
            .map(|(s, &x)| (s.name.clone(), x))
            .collect()
    }

    /// The unit of a parameter the study touches (None: it has none, or is not one).
    pub fn parameter_unit(&self, name: &str) -> Option<&str> {
        let slot = self.slots.iter().find(|s| s.name == name)?;
        slot.variable_unit.as_deref()
    }

    /// Position of a parameter in [`WorkerPool::assignment`].
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.slots.iter().position(|s| s.name == name)
    }

    /// Simulations (sets of FMU instances) created so far.
    pub fn workers_created(&self) -> usize {
        self.created.load(Ordering::Relaxed)
    }

    /// Full-lap runs so far and their summed wall time [s].
    pub fn runs(&self) -> (usize, f64) {
        (
            self.runs.load(Ordering::Relaxed),
            *self.run_seconds.lock().unwrap_or_else(|e| e.into_inner()),
        )
    }

    /// Runs with `values` (one per parameter of [`WorkerPool::assignment`], in its order) and
    /// compares with the measurement.
    pub fn run(&self, values: &[f64], prepared: &PreparedMeasurement) -> Result<Outcome, RunError> {
        self.with_worker(values, |w| self.run_on(w, values, prepared))
    }

    /// Runs with `values` and returns the recording on its uniform grid, without comparing
    /// (a first look at a lap that may not match the measurement at all).
    pub fn lap(&self, values: &[f64]) -> Result<Table, RunError> {
        self.with_worker(values, |w| {
            for (slot, &x) in self.slots.iter().zip(values) {
                w.sim.set(slot, slot.real(x)?);
            }
            let summary = w.sim.run();
            self.runs.fetch_add(1, Ordering::Relaxed);
            summary?;
            uniform_table(w.sim.recording()).map_err(|e| RunError::Table(Box::new(e)))
        })
    }

    /// The pool's one sequence: checks that `values` has one value per parameter, takes a
    /// worker (a new one when every worker is busy), runs `job` on it and puts it back,
    /// whatever `job` returned.
    fn with_worker<T>(
        &self,
        values: &[f64],
        job: impl FnOnce(&mut Worker) -> Result<T, RunError>,
    ) -> Result<T, RunError> {
        if values.len() != self.slots.len() {
            return Err(RunError::Count {
                given: values.len(),
                expected: self.slots.len(),
            });
        }
        let worker = self.lock_workers().pop();
        let mut worker = match worker {
            Some(w) => w,
            None => self.new_worker()?,
        };
        let result = job(&mut worker);
        self.lock_workers().push(worker);
        result
    }

    fn lock_workers(&self) -> std::sync::MutexGuard<'_, Vec<Worker>> {
        self.workers.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn run_on(
        &self,
        w: &mut Worker,
        values: &[f64],
        prepared: &PreparedMeasurement,
    ) -> Result<Outcome, RunError> {
        for (slot, &x) in self.slots.iter().zip(values) {
            let v = slot.real(x).map_err(|error| RunError::Setting {
                name: slot.name.clone(),
                value: x,
                error: Box::new(error),
            })?;
            w.sim.set(slot, v);
        }
        let summary = w.sim.run();
        self.runs.fetch_add(1, Ordering::Relaxed);
        let summary = summary?;
        *self.run_seconds.lock().unwrap_or_else(|e| e.into_inner()) += summary.wall_time;
        let table = uniform_table(w.sim.recording()).map_err(|e| RunError::Table(Box::new(e)))?;
        let comparison = prepared
            .compare(&table, &mut w.ws)
            .map_err(|e| RunError::Comparison(Box::new(e)))?;
        Ok(Outcome { comparison, table })
    }
}

/// The lap's system compiled once, with the study's record override.
fn compile_lap(study: &Study, lap: &Lap, cache: Arc<FmuCache>) -> Result<Arc<Plan>, OptimizeError> {
    let mut file = SystemFile::load(&lap.system_path)?;
    if let Some(r) = &study.file.record {
        file.record.signals = r.signals.clone();
        file.record.decimation = r.decimation;
    }
    let plan = Arc::new(Plan::compile(
        file,
        &lap.system_path,
        cache,
        &LoadOptions::default(),
    )?);
    Ok(plan)
}

/// A study cannot set an input that a connection drives: the connection sets it every step.
fn not_connected(plan: &Plan, study: &Study, slot: &ParamSlot) -> Result<(), OptimizeError> {
    match plan.driving_connection(slot) {
        Some(c) => Err(OptimizeError::File {
            path: study.path.clone(),
            message: format!(
                "'{}' is an input connected to {} (\"{}\"): the connection sets it every step, a study cannot",
                slot.name, c.from_name, c.text
            ),
        }),
        None => Ok(()),
    }
}

/// The study's fixed values and the lap's own, resolved: the slots and values that join
/// the assignment, and the values set once on every worker.
type Resolved = (Vec<ParamSlot>, Vec<f64>, Vec<(ParamSlot, ParamValue)>);

/// The study's fixed values, then the lap's own (a lap's value replaces the study's).
fn fixed_values(study: &Study, lap: &Lap, plan: &Plan) -> Result<Resolved, OptimizeError> {
    let mut slots: Vec<ParamSlot> = Vec::new();
    let mut initial = Vec::new();
    // Fixed values: numbers join the assignment (reported with the results); other
    // types are set once on every worker.
    let mut fixed = Vec::new();
    let study_dir = tb_files::folder_of(&study.path);
    for (name, value) in &study.file.parameters {
        let ctx = format!("{}: parameter \"{name}\"", study.path.display());
        let slot = plan.parameter(name)?;
        not_connected(plan, study, &slot)?;
        let v = slot.resolve_path(slot.value_from_toml(value, &ctx)?, &study_dir);
        // A value some lap sets for itself is fixed on every lap's workers, never part
        // of the assignment (which is the same on every lap).
        let per_lap = study.laps.iter().any(|l| l.parameters.contains_key(name));
        match v {
            ParamValue::Real(x) if !per_lap => {
                slots.push(slot);
                initial.push(x);
            }
            other => fixed.push((slot, other)),
        }
    }
    for (name, value) in &lap.parameters {
        let ctx = format!(
            "{}: lap '{}': parameter \"{name}\"",
            study.path.display(),
            lap.name
        );
        let slot = plan.parameter(name)?;
        not_connected(plan, study, &slot)?;
        let v = slot.resolve_path(slot.value_from_toml(value, &ctx)?, &study_dir);
        fixed.retain(|(s, _)| s.name != slot.name);
        fixed.push((slot, v));
    }
    Ok((slots, initial, fixed))
}

/// The steps' parameters the study does not fix join the assignment, each at the value
/// `sim` has for it (its system's, with the fixed values set).
fn add_step_parameters(
    study: &Study,
    plan: &Plan,
    sim: &Simulation,
    slots: &mut Vec<ParamSlot>,
    initial: &mut Vec<f64>,
) -> Result<(), OptimizeError> {
    for step in &study.file.steps {
        for p in &step.parameters {
            if slots.iter().any(|s| s.name == p.name) {
                continue;
            }
            let slot = plan.parameter(&p.name)?;
            not_connected(plan, study, &slot)?;
            // The bounds within the variable's declared range (else every candidate
            // outside it fails, and the best point cannot be evaluated).
            if slot.min.is_some_and(|m| p.min < m) || slot.max.is_some_and(|m| p.max > m) {
                return Err(OptimizeError::File {
                    path: study.path.clone(),
                    message: format!(
                        "step '{}': the bounds [{}, {}] of '{}' leave its declared range [{}, {}]",
                        step.name,
                        tb_files::number(p.min),
                        tb_files::number(p.max),
                        p.name,
                        slot.min.map_or("-inf".into(), tb_files::number),
                        slot.max.map_or("inf".into(), tb_files::number)
                    ),
                });
            }
            let x = sim.value_of(&slot).unwrap_or(p.min);
            slot.real(x)?;
            slots.push(slot);
            initial.push(x);
        }
    }
    Ok(())
}

/// The recording as a comparison table, without a last row that is off the decimated time
/// grid (a lap ends between two recorded samples; the filter needs uniform sampling).
pub fn uniform_table(rec: &Table) -> Result<Table, tb_compare::Error> {
    let n = rec.len();
    let mut table =
        Table::from_columns("simulation", rec.names().to_vec(), rec.columns().to_vec())?;
    if n >= 3 {
        let t = rec.column_at(0);
        let h = t[1] - t[0];
        let last = t[n - 1] - t[n - 2];
        if (last - h).abs() > 1e-6 * h.abs() {
            table.truncate(n - 1);
        }
    }
    Ok(table)
}
