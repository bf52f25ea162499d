//! Candidates on the co-simulated bench: a pool of workers, each owning one [`Simulation`]
//! (its FMU instances are reset and reused between candidates, never re-instantiated) and
//! one comparison [`Workspace`]. A worker is created the first time a thread finds the
//! pool empty, so there are at most as many as evaluations run at once.

use super::study::Study;
use super::OptimizeError;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tb_compare::{Comparison, PreparedMeasurement, Table, Workspace};
use tb_cosim::{Recording, Simulation, System, SystemError, SystemFile};
use tb_fmi::FmuCache;

struct Worker {
    sim: Simulation,
    ws: Workspace,
}

/// The system of a study, ready to run candidates from several threads.
pub struct Bench {
    file: SystemFile,
    path: std::path::PathBuf,
    cache: Arc<FmuCache>,
    workers: Mutex<Vec<Worker>>,
    created: AtomicUsize,
    runs: AtomicUsize,
    run_seconds: Mutex<f64>,
}

/// One candidate's simulation compared with the measurement.
pub struct Outcome {
    pub comparison: Comparison,
    pub table: Table,
}

/// A failed run, with where it failed.
pub fn describe_failure(e: &SystemError) -> String {
    match e {
        SystemError::Fmu(f) => format!("FMU error: {f}"),
        other => other.to_string(),
    }
}

impl Bench {
    /// Loads the system once (to check it) with the study's record override.
    pub fn new(study: &Study, cache: Arc<FmuCache>) -> Result<Bench, OptimizeError> {
        let mut file = SystemFile::load(&study.system_path)?;
        if let Some(r) = &study.file.record {
            file.record.signals = r.signals.clone();
            file.record.decimation = r.decimation;
        }
        let bench = Bench {
            file,
            path: study.system_path.clone(),
            cache,
            workers: Mutex::new(Vec::new()),
            created: AtomicUsize::new(0),
            runs: AtomicUsize::new(0),
            run_seconds: Mutex::new(0.0),
        };
        // Load once here so that a bad system or study parameter is an error up front.
        let mut w = bench.new_worker()?;
        for (name, x) in &study.file.parameters {
            w.sim.set_parameter(name, toml::Value::Float(*x))?;
        }
        for step in &study.file.steps {
            for p in &step.parameters {
                let v = w.sim.parameter(&p.name).unwrap_or(p.min);
                w.sim.set_parameter(&p.name, toml::Value::Float(v))?;
            }
        }
        bench.workers.lock().unwrap().push(w);
        Ok(bench)
    }

    fn new_worker(&self) -> Result<Worker, SystemError> {
        let system = System::from_file(self.file.clone(), &self.path, self.cache.clone())?;
        let mut sim = Simulation::new(system)?;
        sim.echo_fmu_log = false;
        self.created.fetch_add(1, Ordering::Relaxed);
        Ok(Worker {
            sim,
            ws: Workspace::new(),
        })
    }

    /// Simulations (sets of FMU instances) created so far.
    pub fn workers_created(&self) -> usize {
        self.created.load(Ordering::Relaxed)
    }

    /// Full-lap runs so far and their summed wall time [s].
    pub fn runs(&self) -> (usize, f64) {
        (
            self.runs.load(Ordering::Relaxed),
            *self.run_seconds.lock().unwrap(),
        )
    }

    /// The system's value of a parameter (None: not settable or unknown).
    pub fn parameter(&self, name: &str) -> Option<f64> {
        let w = self.workers.lock().unwrap();
        w.first().and_then(|w| w.sim.parameter(name))
    }

    /// Runs with `params` (`instance.variable`, value) and compares. `keep_table`: return
    /// the recording as a table too (for plots).
    pub fn run(
        &self,
        params: &[(String, f64)],
        prepared: &PreparedMeasurement,
    ) -> Result<Outcome, String> {
        let worker = self.workers.lock().unwrap().pop();
        let mut worker = match worker {
            Some(w) => w,
            None => self.new_worker().map_err(|e| describe_failure(&e))?,
        };
        let result = Self::run_on(&mut worker, params, prepared, &self.runs, &self.run_seconds);
        self.workers.lock().unwrap().push(worker);
        result
    }

    fn run_on(
        w: &mut Worker,
        params: &[(String, f64)],
        prepared: &PreparedMeasurement,
        runs: &AtomicUsize,
        seconds: &Mutex<f64>,
    ) -> Result<Outcome, String> {
        for (name, x) in params {
            w.sim
                .set_parameter(name, toml::Value::Float(*x))
                .map_err(|e| format!("setting {name} = {x}: {}", describe_failure(&e)))?;
        }
        let summary = w.sim.run();
        runs.fetch_add(1, Ordering::Relaxed);
        let summary = summary.map_err(|e| describe_failure(&e))?;
        *seconds.lock().unwrap() += summary.wall_time;
        let table = uniform_table(&w.sim.recording).map_err(|e| e.to_string())?;
        let comparison = prepared
            .compare(&table, &mut w.ws)
            .map_err(|e| format!("comparison: {e}"))?;
        Ok(Outcome { comparison, table })
    }
}

/// The recording as a comparison table, without a last row that is off the decimated time
/// grid (a lap ends between two recorded samples; the filter needs uniform sampling).
pub fn uniform_table(rec: &Recording) -> Result<Table, tb_compare::Error> {
    let n = rec.rows();
    let mut columns = rec.columns.clone();
    if n >= 3 {
        let t = &rec.columns[0];
        let h = t[1] - t[0];
        let last = t[n - 1] - t[n - 2];
        if (last - h).abs() > 1e-6 * h.abs() {
            for c in &mut columns {
                c.truncate(n - 1);
            }
        }
    }
    Table::from_columns("simulation", rec.names.clone(), columns)
}
