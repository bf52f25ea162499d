//! `twinbench validate RESULT.json MEASUREMENT`: the fitted twin on a lap it was not fitted
//! on. The lap is prepared as `twinbench lap` prepares one (target speed, track, start values
//! from the measurement; the RLS/v bench of the packed FMUs), the study's fitted parameters
//! are set, the twin runs the lap once, and every validation signal of the study's steps is
//! compared with the measurement as the study compared them (its filter and grid): e, m,
//! R² and bias per signal, beside the values the fitted lap reached, and a plot.

use crate::lap::{LapError, LapOptions};
use crate::report::points;
use serde::Serialize;
use std::path::{Path, PathBuf};
use tb_compare::{ChannelMap, Measurement, Metrics, PreparedMeasurement, Workspace};
use tb_optimize::StudyResult;

#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error("{path}: {message}")]
    Result { path: PathBuf, message: String },
    #[error(transparent)]
    Lap(#[from] LapError),
    #[error(transparent)]
    Compare(#[from] tb_compare::Error),
    #[error(transparent)]
    System(#[from] tb_cosim::SystemError),
    #[error(transparent)]
    Run(#[from] anyhow::Error),
    #[error("plot: {0}")]
    Plot(#[from] tb_plot::PlotError),
    #[error("writing {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// The measurement's errors as the comparison's (`Compare`), as they were before the
/// reader moved below it.
impl From<tb_compare::measurement::Error> for ValidateError {
    fn from(e: tb_compare::measurement::Error) -> Self {
        ValidateError::Compare(e.into())
    }
}

/// What `validate` is given.
#[derive(Clone, Debug)]
pub struct ValidateOptions {
    /// A study's `result.json` (`twinbench optimize` writes it).
    pub result: PathBuf,
    /// The lap not fitted: MDF 4 or CSV, with `channels` mapping its channels.
    pub measurement: PathBuf,
    pub channels: ChannelMap,
    /// Its circuit's track (None: derived from the measurement, as `lap` does).
    pub track: Option<PathBuf>,
    /// Where the lap's files, the table and the plot go.
    pub out: PathBuf,
}

/// One validation signal on the lap not fitted, beside the fitted lap's values.
#[derive(Clone, Debug, Serialize)]
pub struct ValidationRow {
    pub step: usize,
    pub signal: String,
    /// e of the same twin (the study's final parameters) on the lap it was fitted on (the
    /// first, in a study of several).
    pub e_fitted: f64,
    /// A study of several laps: the lowest and highest e its answer reached over the fitted
    /// laps (from the result).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub e_fitted_range: Option<(f64, f64)>,
    pub e: f64,
    pub slope: f64,
    pub r_squared: f64,
    pub bias_percent: f64,
}

/// What `validate` found and wrote.
#[derive(Clone, Debug, Serialize)]
pub struct Validation {
    pub result: PathBuf,
    pub measurement: PathBuf,
    /// The parameters set, as the study fitted them.
    pub parameters: Vec<(String, f64)>,
    pub rows: Vec<ValidationRow>,
    /// The twin's lap time minus the vehicle's over the compared distance [s].
    pub lap_time_difference_s: f64,
    pub system: PathBuf,
    pub files: Vec<PathBuf>,
    /// The comparison settings were not in the result (an older one): the defaults used.
    pub default_settings: bool,
    pub notes: Vec<String>,
}

/// Reads a study's result.
pub fn read_result(path: &Path) -> Result<StudyResult, ValidateError> {
    let bad = |message: String| ValidateError::Result {
        path: path.to_path_buf(),
        message,
    };
    let text = tb_files::input::read_to_string(path, tb_files::Limit::CONFIG)
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    let r: StudyResult = serde_json::from_str(&text).map_err(|e| {
        bad(format!(
            "not a study result (the result.json `twinbench optimize` writes): {e}"
        ))
    })?;
    if r.parameters_final.is_empty() || r.steps.is_empty() {
        return Err(bad("a study result without fitted parameters".into()));
    }
    Ok(r)
}

/// The twin of `system` (the lap's, of twinbench's own FMUs) with `parameters` set, run
/// once: its recording.
fn run_twin(
    system: &Path,
    parameters: &[(String, f64)],
    result: &Path,
) -> Result<tb_compare::Table, ValidateError> {
    let cache =
        std::sync::Arc::new(tb_fmi::FmuCache::temporary(false).map_err(anyhow::Error::from)?);
    let plan = std::sync::Arc::new(tb_cosim::Plan::load_with(
        system,
        cache,
        &tb_cosim::LoadOptions::default(),
    )?);
    let mut sim = tb_cosim::Simulation::new(plan.clone())?;
    sim.echo_fmu_log = false;
    for (name, value) in parameters {
        crate::bench::set_parameter(&plan, &mut sim, name, &toml::Value::Float(*value)).map_err(
            |e| ValidateError::Result {
                path: result.to_path_buf(),
                message: format!(
                    "parameter '{name}' cannot be set on {}: {e:#}",
                    system.display()
                ),
            },
        )?;
    }
    sim.run()?;
    Ok(sim.recording().clone())
}

/// Prepares the lap, runs the fitted twin on it and compares.
pub fn validate(o: &ValidateOptions) -> Result<Validation, ValidateError> {
    let result = read_result(&o.result)?;
    let lap = crate::lap::prepare(&LapOptions {
        measurement: o.measurement.clone(),
        channels: o.channels.clone(),
        track: o.track.clone(),
        out: o.out.join("lap"),
        fmu_dir: None,
        // The chassis the fitted parameters belong to.
        chassis: crate::lap::Chassis::of_parameters(
            result.parameters_final.iter().map(|(n, _)| n.as_str()),
        ),
    })?;
    let table = run_twin(&lap.system, &result.parameters_final, &o.result)?;
    let measurement = Measurement::load(&o.measurement, &o.channels)?;
    let default_settings = result.compare.is_none();
    let settings = result.compare.clone().unwrap_or_default();
    let signals = validation_signals(&result);
    let mut names: Vec<&str> = signals.iter().map(|s| s.1.as_str()).collect();
    if !names.contains(&"Fz_sum") {
        names.push("Fz_sum");
    }
    let prepared = PreparedMeasurement::new(&measurement, &names, &settings)?;
    let mut ws = Workspace::new();
    let cmp = prepared.compare(&table, &mut ws)?;
    let (rows, notes) = rows(&result, &signals, &cmp);
    // The lap times over the distance both cover, and Fz_sum over distance.
    let (rm, m) = prepared.on_grid(measurement.table(), "time", false, &mut ws)?;
    let (ro, t) = prepared.on_grid(&table, "time", false, &mut ws)?;
    let end = rm.end.min(ro.end);
    let lap_time_difference_s = (t[end - 1 - ro.start] - t[0]) - (m[end - 1 - rm.start] - m[0]);
    let stem = o.out.join("validation_fz_sum");
    plot_fz_sum(
        &prepared,
        measurement.table(),
        &table,
        settings.cutoff_hz,
        &stem,
        &mut ws,
    )?;
    let mut v = Validation {
        result: o.result.clone(),
        measurement: o.measurement.clone(),
        parameters: result.parameters_final.clone(),
        rows,
        lap_time_difference_s,
        system: lap.system.clone(),
        files: vec![stem.with_extension("svg"), stem.with_extension("png")],
        default_settings,
        notes,
    };
    let md = markdown(&v);
    for (name, bytes) in [
        ("validation.md", md.into_bytes()),
        (
            "validation.json",
            serde_json::to_vec_pretty(&v).expect("serialises"),
        ),
    ] {
        let path = o.out.join(name);
        tb_table::write_atomic(&path, &bytes).map_err(|source| ValidateError::Io {
            path: path.clone(),
            source,
        })?;
        v.files.push(path);
    }
    Ok(v)
}

/// Every validation signal of the study, in step order, each once: (step, signal, its e
/// after that step).
fn validation_signals(result: &StudyResult) -> Vec<(usize, String, f64)> {
    let mut signals: Vec<(usize, String, f64)> = Vec::new();
    for s in &result.steps {
        for e in &s.e {
            if !signals.iter().any(|(_, n, _)| *n == e.signal) {
                signals.push((s.step, e.signal.clone(), e.after.e));
            }
        }
    }
    signals
}

/// The table's rows: each validation signal's e on this lap beside its e on the fitted lap
/// (the answer's, from the result), with a note when the result has no joint answer.
fn rows(
    result: &StudyResult,
    signals: &[(usize, String, f64)],
    cmp: &tb_compare::Comparison,
) -> (Vec<ValidationRow>, Vec<String>) {
    // The same twin on the lap it was fitted on: the answer's e as the study computed it
    // (with its own channel map), from the result. Nothing the result names is run or read
    // again: a result file is data, and the system and measurement it names may come from
    // anyone (a colleague, a supplier, a cluster).
    let fitted: Option<Vec<(String, f64)>> = result.joint.as_ref().map(|j| {
        let mut first: Vec<(String, f64)> = Vec::new();
        for e in &j.e {
            if !first.iter().any(|(n, _)| *n == e.signal) {
                first.push((e.signal.clone(), e.after.e));
            }
        }
        first
    });
    let mut notes = Vec::new();
    if fitted.is_none() {
        notes.push(
            "the result has no joint answer (written by an older twinbench): each step's e after the step is shown as the fitted lap's".to_string(),
        );
    }
    let rows: Vec<ValidationRow> = signals
        .iter()
        .map(|(step, name, e_step)| {
            let m: &Metrics = cmp.get(name).expect("compared above");
            let e_fitted = fitted
                .as_ref()
                .and_then(|f| f.iter().find(|(n, _)| n == name))
                .map_or(*e_step, |(_, e)| *e);
            let laps: Vec<f64> = result
                .joint
                .iter()
                .flat_map(|j| &j.e)
                .filter(|e| e.lap.is_some() && e.signal == *name)
                .map(|e| e.after.e)
                .collect();
            let e_fitted_range = (!laps.is_empty()).then(|| {
                laps.iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &e| {
                        (a.min(e), b.max(e))
                    })
            });
            ValidationRow {
                step: *step,
                signal: name.clone(),
                e_fitted,
                e_fitted_range,
                e: m.e,
                slope: m.slope,
                r_squared: m.r_squared,
                bias_percent: 100.0 * m.bias,
            }
        })
        .collect();
    (rows, notes)
}

/// Fz_sum of the vehicle and the fitted twin over distance, filtered as compared.
fn plot_fz_sum(
    prepared: &PreparedMeasurement,
    measured: &tb_table::Table,
    table: &tb_table::Table,
    cutoff_hz: f64,
    stem: &Path,
    ws: &mut Workspace,
) -> Result<(), ValidateError> {
    let grid = prepared.grid();
    let (rm, fm) = prepared.on_grid(measured, "Fz_sum", true, ws)?;
    let (ro, fo) = prepared.on_grid(table, "Fz_sum", true, ws)?;
    let plot = tb_plot::LinePlot::new(
        format!(
            "Sum of the four wheel loads on a lap not fitted, low-pass filtered at {} Hz: vehicle against the fitted twin",
            cutoff_hz
        ),
        "distance [m]",
        "Fz_sum [N]",
    )
    .series("twin, fitted parameters", &points(grid, ro, &fo))
    .reference("vehicle (measured)", &points(grid, rm, &fm));
    plot.save_both(stem)?;
    Ok(())
}

/// The table as Markdown, as Tab. 1 has it.
pub fn markdown(v: &Validation) -> String {
    let mut s = format!(
        "Validation of {} on a lap not fitted ({})\n\n| step | validation signal | e fitted lap | e this lap | m | R² | bias |\n|---|---|---:|---:|---:|---:|---:|\n",
        v.result.display(),
        v.measurement.display()
    );
    for r in &v.rows {
        let fitted = match r.e_fitted_range {
            Some((lo, hi)) => format!("{lo:.4} … {hi:.4}"),
            None => format!("{:.4}", r.e_fitted),
        };
        s.push_str(&format!(
            "| {} | {} | {fitted} | {:.4} | {:.4} | {:.4} | {:+.2} % |\n",
            r.step, r.signal, r.e, r.slope, r.r_squared, r.bias_percent
        ));
    }
    s.push_str(&format!(
        "\nLap time, twin − vehicle: {:+.3} s.\n",
        v.lap_time_difference_s
    ));
    for n in &v.notes {
        s.push_str(&format!("\nNote: {n}\n"));
    }
    if v.default_settings {
        s.push_str("\nThe result carries no comparison settings (written by an older twinbench): the defaults were used (2 Hz, order 2, 1 m).\n");
    }
    s.push_str(&format!("\n{VALIDATION_LEGEND}\n"));
    s
}

/// What the validation table's columns mean (its own: it has no parameters and no row
/// "all").
pub const VALIDATION_LEGEND: &str = "The twin with the study's answer (`parameters_final`) on a lap it was not fitted on, each signal compared as the study compared it (the same filter and distance grid). e: the error measure (1 − R²)/2 + |m − 1|/2 of the twin's signal against the measured one (0: equal); e fitted lap: the same signal's e on the lap the study fitted, with the answer (a range where the study's steps gave several); m: the slope of the regression of the twin's signal on the measured one (1: same scale); R²: the regression's coefficient of determination; bias: the mean relative difference, twin − measurement. An e much above the fitted lap's says the answer does not carry over to this lap (docs/optimize.md, 'On a lap not fitted').";
