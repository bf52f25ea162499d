//! Reports of an optimisation study: the paper's Tab. 1 as Markdown and JSON, and plots
//! (SVG + PNG): Fz_sum over distance measured / initial / optimised, filtered and unfiltered
//! (Fig. 7); time over distance (Fig. 6); best cost per generation; a_x of twin and car;
//! and report.html, all of it on one self-contained page with every compared signal, the
//! parameters' picture and the inputs' digests ([`html`]).
//! Everything comes from the study's result and the laps it kept: the report simulates
//! nothing.

mod escape;
mod forest;
pub mod html;
mod plots;
mod provenance;
mod signals;
mod truth;

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tb_compare::{Measurement, PreparedMeasurement, Table, Workspace};
use tb_optimize::driver::{ParameterChange, SignalChange};
use tb_optimize::{OptimizeError, Study, StudyResult};
use tb_plot::{Figure, LinePlot, Style};

/// The stretch of the lap the unfiltered wheel loads are drawn over [m].
const UNFILTERED_WINDOW_M: f64 = 500.0;
use tb_table::write_atomic;

#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// Boxed: a study's error carries a run's, and the report's functions return this
    /// one on every path.
    #[error("{0}")]
    Optimize(Box<OptimizeError>),
    #[error("comparison: {0}")]
    Compare(#[from] tb_compare::Error),
    #[error("plot: {0}")]
    Plot(#[from] tb_plot::PlotError),
    #[error("writing {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the study result carries no {0} lap to plot")]
    MissingLap(&'static str),
}

impl From<OptimizeError> for ReportError {
    fn from(e: OptimizeError) -> Self {
        ReportError::Optimize(Box::new(e))
    }
}

/// One row of Tab. 1: a validation signal of a step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableRow {
    /// The lap, in a study of several.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lap: Option<String>,
    pub signal: String,
    pub e_initial: f64,
    pub e_optimized: f64,
    pub slope_initial: f64,
    pub slope_optimized: f64,
    pub r_squared_initial: f64,
    pub r_squared_optimized: f64,
    pub bias_percent_initial: f64,
    pub bias_percent_optimized: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableParameter {
    pub name: String,
    /// The variable's unit (None: dimensionless, or not declared).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// The optimised value's 95 % confidence interval, an open end `None`; absent when
    /// there is none (`interval_statement` says why).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval: Option<(Option<f64>, Option<f64>)>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval_statement: Option<String>,
    /// The interval with the model's share (docs/optimize.md, "The model check"): the one
    /// to quote where the model check finds the twin wanting.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub interval_with_model: Option<(Option<f64>, Option<f64>)>,
    pub initial: f64,
    pub optimized: f64,
    pub change_percent: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TableStep {
    pub step: usize,
    pub name: String,
    pub parameters: Vec<TableParameter>,
    pub signals: Vec<TableRow>,
}

/// Tab. 1 as data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Table1 {
    pub study: String,
    pub steps: Vec<TableStep>,
    /// The study's answer: every parameter from its step's start to the joint refinement,
    /// with its interval, and every signal at the study's start and at the answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint: Option<TableStep>,
    /// The held-out laps: every signal at the study's start and with its answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold_out: Option<TableStep>,
    /// Whether the twin, not the noise, limits the answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_check: Option<tb_optimize::model_check::ModelCheck>,
    /// The moving-block bootstrap of the answer, where asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bootstrap: Option<tb_optimize::bootstrap::Bootstrap>,
    /// The twin's lap time minus the vehicle's [s], with the initial and with the optimised
    /// parameters (over the distance both cover; what `time_over_distance` shows).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lap_time_difference: Option<LapTimeDifference>,
}

/// The twin's lap time minus the measured one [s].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LapTimeDifference {
    pub initial_s: f64,
    pub optimized_s: f64,
    /// The measured lap time [s] over the same distance.
    pub measured_s: f64,
    /// That distance [m]: the stretch both laps cover on the comparison's grid (a little
    /// shorter than the lap, so `measured_s` is a little less than the lap time `lap` reads
    /// from the whole measurement).
    #[serde(default)]
    pub distance_m: f64,
}

/// What Tab. 1's columns mean, printed under it.
pub const TABLE1_LEGEND: &str = "e: the error measure (1 − R²)/2 + |m − 1|/2 of the twin's signal against the measured one, both low-pass filtered and on a 1 m distance grid (0: equal); m: the slope of the regression of the twin's signal on the measured one (1: same scale); bias: the mean relative difference, twin − measurement (0 %: same level); R² (in table1.json): the regression's coefficient of determination. Parameters: change in % (value before → after, in the parameter's unit). Row \"all\": the study's answer, every parameter moved together to the least-squares point of every signal (the joint refinement after the steps, docs/optimize.md), from the value its step started from, with [lo, hi] its 95 % interval of the scatter around the twin's best fit (from the sensitivities there, the residuals' autocorrelation accounted for: what the noise leaves uncertain where the twin is the right model; with --profiles, the profile likelihood's interval instead, its method in table1.json), and \"with the model's share\" the 95 % interval that adds what the twin cannot represent of this car (the model check's terms fitted with the parameters; quote it where the model check finds the twin wanting); \"open\": that end lies beyond the parameter's range; e, m, bias of the row: every signal at the study's start and at the answer.";

/// The report as an observer of a study ([`tb_optimize::StudyObserver`]): Tab. 1 and the
/// plots are written when the study has its result (not after an interruption), and the
/// files written are kept for the caller ([`ReportWriter::files`]).
pub struct ReportWriter {
    study: Study,
    folder: PathBuf,
    written: std::sync::Mutex<Option<ReportFiles>>,
}

impl ReportWriter {
    pub fn new(study: &Study, folder: &Path) -> std::sync::Arc<ReportWriter> {
        std::sync::Arc::new(ReportWriter {
            study: study.clone(),
            folder: folder.to_path_buf(),
            written: std::sync::Mutex::new(None),
        })
    }

    /// What it wrote (None before the study's end).
    pub fn files(&self) -> Option<ReportFiles> {
        self.written
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }
}

impl tb_optimize::StudyObserver for ReportWriter {
    fn finished(&self, result: &StudyResult) -> Result<(), tb_optimize::ObserverError> {
        let files = write_report(&self.study, result, &self.folder).map_err(|e| e.to_string())?;
        *self.written.lock().unwrap_or_else(|p| p.into_inner()) = Some(files);
        Ok(())
    }
}

/// What was written.
#[derive(Clone, Debug)]
pub struct ReportFiles {
    pub folder: PathBuf,
    pub table_markdown: String,
    pub files: Vec<PathBuf>,
}

fn short(name: &str) -> &str {
    name.split_once('.').map_or(name, |(_, v)| v)
}

pub fn table1(result: &StudyResult, lap_time_difference: Option<LapTimeDifference>) -> Table1 {
    let parameter = |p: &ParameterChange, with_interval: bool| TableParameter {
        name: p.name.clone(),
        unit: p.unit.clone().filter(|u| !u.is_empty() && u != "1"),
        interval: p.interval.filter(|_| with_interval),
        interval_statement: p.interval_statement.clone().filter(|_| with_interval),
        interval_with_model: p.interval_with_model.filter(|_| with_interval),
        initial: p.before,
        optimized: p.after,
        change_percent: p.change_percent,
    };
    let row = |e: &SignalChange| TableRow {
        lap: e.lap.clone(),
        signal: e.signal.clone(),
        e_initial: e.before.e,
        e_optimized: e.after.e,
        slope_initial: e.before.slope,
        slope_optimized: e.after.slope,
        r_squared_initial: e.before.r_squared,
        r_squared_optimized: e.after.r_squared,
        bias_percent_initial: 100.0 * e.before.bias,
        bias_percent_optimized: 100.0 * e.after.bias,
    };
    // With a joint answer, the intervals are its (a step's own are conditional on the other
    // steps' values at the time): the steps' rows show their values only.
    let joint = result.joint.as_ref();
    Table1 {
        study: result.study.clone(),
        lap_time_difference,
        model_check: joint.and_then(|j| j.model_check.clone()),
        bootstrap: joint.and_then(|j| j.bootstrap.clone()),
        steps: result
            .steps
            .iter()
            .map(|s| TableStep {
                step: s.step,
                name: s.name.clone(),
                parameters: s
                    .parameters
                    .iter()
                    .map(|p| parameter(p, joint.is_none()))
                    .collect(),
                signals: s.e.iter().map(row).collect(),
            })
            .collect(),
        joint: joint.map(|j| TableStep {
            step: result.steps.len() + 1,
            name: match &j.refinement {
                Some(r) => format!(
                    "all parameters together ({}, {} iterations)",
                    r.method, r.iterations
                ),
                None => "all parameters together (the steps' answer)".into(),
            },
            parameters: j.parameters.iter().map(|p| parameter(p, true)).collect(),
            signals: j.e.iter().map(row).collect(),
        }),
        hold_out: (!result.hold_out.is_empty()).then(|| TableStep {
            step: result.steps.len() + 2,
            name: "held out: run with the answer, not fitted".into(),
            parameters: Vec::new(),
            signals: result.hold_out.iter().map(row).collect(),
        }),
    }
}

/// " m" after a value of a parameter in metres; nothing for one without a unit.
fn unit_suffix(p: &TableParameter) -> String {
    p.unit
        .as_deref()
        .map(|u| format!(" {u}"))
        .unwrap_or_default()
}

/// The sentence under Tab. 1 that names the values to load into the bench, and why the
/// row "all" can fit a signal worse than its step did.
pub fn values_to_load(joint: &TableStep) -> String {
    let values = joint
        .parameters
        .iter()
        .map(|p| format!("{} = {:.4}{}", short(&p.name), p.optimized, unit_suffix(p)))
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "The values to load into the bench are the row \"all\" ({values}; `parameters_final` in result.json, `twinbench run SYSTEM --params result.json` applies them, `twinbench export-twin result.json --out DIR` hands them on as FMUs, SSP and a table). Its e can be higher than a step's: each step minimised e + β·|bias| of its own signals with the other steps' parameters held, the row \"all\" minimises the squared error of every signal with every parameter free, a different objective (docs/optimize.md)."
    )
}

/// The intervals' statements (parameter, statement) merged into one line per cause, with
/// the parameters it concerns and what to do next; a statement of no known cause stays as
/// it is, under its parameter. A parameter is named once per cause.
pub fn merged_statements(items: &[(String, String)]) -> Vec<String> {
    // (what the statement says, the line's opening, what to do next)
    const CAUSES: [(&[&str], &str, &str); 3] = [
        (
            &["on its lower bound", "on its upper bound"],
            "On a bound of its range, the optimum beyond it",
            "widen the range in the study where the value beyond is physical; where it is not, the parameter is virtual here (it takes up what the twin misses, see the model check) and its value holds for this twin only",
        ),
        (
            &["not determined"],
            "Not determined by these signals",
            "fit a second lap (a second `[[measurement]]` in the study) or add a signal that sees it; `twinbench validate` on a lap not fitted shows what the answer predicts",
        ),
        (
            &["open below", "open above"],
            "Interval open (any value to the range's end fits)",
            "the signals barely see it: a second lap or another signal closes it",
        ),
    ];
    let mut lines = Vec::new();
    let mut known = vec![false; items.len()];
    for (says, opening, next) in CAUSES {
        let mut names: Vec<String> = Vec::new();
        for (k, (name, why)) in items.iter().enumerate() {
            if let Some(s) = says.iter().find(|s| why.contains(*s)) {
                known[k] = true;
                let which = if s.contains("lower") || s.contains("below") {
                    " (low end)"
                } else if s.contains("upper") || s.contains("above") {
                    " (high end)"
                } else {
                    ""
                };
                let named = format!("{name}{which}");
                if !names.contains(&named) {
                    names.push(named);
                }
            }
        }
        if !names.is_empty() {
            lines.push(format!("- {opening}: {}. Next: {next}.", names.join(", ")));
        }
    }
    for ((name, why), known) in items.iter().zip(known) {
        if !known {
            let line = match why.strip_prefix(&format!("{name}: ")) {
                Some(rest) => format!("- {name}: {rest}"),
                None => format!("- {name}: {why}"),
            };
            if !lines.contains(&line) {
                lines.push(line);
            }
        }
    }
    lines
}

/// One parameter of Tab. 1 in words: its change, its values and intervals (the Markdown
/// table's cell and the HTML table's, so both say the same).
pub fn parameter_line(p: &TableParameter) -> String {
    let unit = unit_suffix(p);
    let end = |e: Option<f64>| e.map_or("open".to_string(), |x| format!("{x:.4}"));
    let interval = match p.interval {
        Some((lo, hi)) => format!(" [{}, {}]", end(lo), end(hi)),
        None if p.interval_statement.is_some() => " [no interval]".into(),
        None => String::new(),
    };
    let interval = match p.interval_with_model {
        Some((lo, hi)) => format!(
            "{interval}, with the model's share [{}, {}]",
            end(lo),
            end(hi)
        ),
        None => interval,
    };
    format!(
        "{}: {} ({:.4}{unit} → {:.4}{unit}{interval})",
        short(&p.name),
        change_words(p.change_percent, p.initial, p.optimized),
        p.initial,
        p.optimized
    )
}

/// A parameter's change in words: `+12.3 %`; from a start of zero, where no ratio exists,
/// `from 0` (and `unchanged` when it stayed there), never `NaN %`.
pub fn change_words(change_percent: f64, initial: f64, optimized: f64) -> String {
    match change_percent.is_finite() {
        true => format!("{change_percent:+.1} %"),
        false if initial == 0.0 && optimized == 0.0 => "unchanged".into(),
        false if initial == 0.0 => "from 0".into(),
        false => "change not defined".into(),
    }
}

/// The intervals' statements of every parameter of Tab. 1, merged per cause.
pub fn table1_statements(t: &Table1) -> Vec<String> {
    merged_statements(
        &t.steps
            .iter()
            .chain(&t.joint)
            .flat_map(|st| &st.parameters)
            .filter_map(|p| Some((short(&p.name).to_string(), p.interval_statement.clone()?)))
            .collect::<Vec<_>>(),
    )
}

/// Tab. 1 as Markdown (parameters listed on a step's first row, as in the paper).
pub fn table1_markdown(t: &Table1) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "Tab. 1 ({}): quality of the twin against the vehicle measurement before and after \
         the optimisation\n\n",
        t.study
    ));
    s.push_str("| step | validation signal | optimised parameters | e initial | e optimised | m initial | m optimised | bias initial | bias optimised |\n");
    s.push_str("|---|---|---|---:|---:|---:|---:|---:|---:|\n");
    for (label, st) in t
        .steps
        .iter()
        .map(|st| (st.step.to_string(), st))
        .chain(t.joint.iter().map(|st| ("all".to_string(), st)))
        .chain(t.hold_out.iter().map(|st| ("held out".to_string(), st)))
    {
        let params = st
            .parameters
            .iter()
            .map(parameter_line)
            .collect::<Vec<_>>()
            .join("<br>");
        for (k, r) in st.signals.iter().enumerate() {
            s.push_str(&format!(
                "| {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:+.2} % | {:+.2} % |\n",
                if k == 0 { label.as_str() } else { "" },
                match &r.lap {
                    Some(lap) => format!("{} ({lap})", r.signal),
                    None => r.signal.clone(),
                },
                if k == 0 { params.as_str() } else { "" },
                r.e_initial,
                r.e_optimized,
                r.slope_initial,
                r.slope_optimized,
                r.bias_percent_initial,
                r.bias_percent_optimized
            ));
        }
    }
    let statements = table1_statements(t);
    if let Some(j) = &t.joint {
        s.push_str(&format!("\n{}\n", values_to_load(j)));
    }
    if let Some(c) = &t.model_check {
        s.push_str(&format!("\nModel check ({}): {}.\n", c.method, c.detail));
    }
    if let Some(b) = &t.bootstrap {
        s.push_str(&format!(
            "\n{} (1: the sandwich's intervals are as wide as the refits scatter; the refits see only the noise, not the twin's share).\n",
            b.summary(|n| short(n).to_string())
        ));
    }
    if !statements.is_empty() {
        s.push_str("\nAbout the intervals:\n");
        s.push_str(&statements.join("\n"));
        s.push('\n');
    }
    if let Some(d) = t.lap_time_difference {
        s.push_str(&format!(
            "\nLap time, twin − vehicle: {:+.3} s initial, {:+.3} s optimised (measured {:.3} s over the {:.0} m both cover on the comparison's grid).\n",
            d.initial_s, d.optimized_s, d.measured_s, d.distance_m
        ));
    }
    s.push_str(&format!("\n{TABLE1_LEGEND}\n"));
    s
}

fn write(path: &Path, bytes: &[u8], files: &mut Vec<PathBuf>) -> Result<(), ReportError> {
    write_atomic(path, bytes).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    files.push(path.to_path_buf());
    Ok(())
}

/// A signal on the comparison's grid as (distance, value) points, for a plot.
pub(crate) fn points(
    grid: &tb_compare::DistanceGrid,
    range: std::ops::Range<usize>,
    y: &[f64],
) -> Vec<(f64, f64)> {
    range.zip(y).map(|(g, &v)| (grid.at(g), v)).collect()
}

/// The three laps a report draws (the measurement, the twin with the initial and with the
/// optimised parameters) and the comparison that puts them on its distance grid.
struct Laps<'a> {
    prepared: &'a PreparedMeasurement,
    meas: &'a Table,
    initial: &'a Table,
    optimised: &'a Table,
}

impl Laps<'_> {
    fn grid(&self) -> &tb_compare::DistanceGrid {
        self.prepared.grid()
    }
}

/// The twin's lap time minus the vehicle's, with the initial and the optimised parameters,
/// over the distance both cover on the comparison's grid.
fn lap_time_difference(
    laps: &Laps<'_>,
    ws: &mut Workspace,
) -> Result<LapTimeDifference, ReportError> {
    let (prepared, grid) = (laps.prepared, laps.grid());
    let (rm, m) = prepared.on_grid(laps.meas, "time", false, ws)?;
    let mut lap_gap = |lap: &Table| -> Result<(f64, f64, f64), ReportError> {
        let (ro, o) = prepared.on_grid(lap, "time", false, ws)?;
        let end = rm.end.min(ro.end);
        let (measured, twin) = (m[end - 1 - rm.start] - m[0], o[end - 1 - ro.start] - o[0]);
        Ok((
            twin - measured,
            measured,
            grid.at(end - 1) - grid.at(rm.start),
        ))
    };
    let (initial_gap, ..) = lap_gap(laps.initial)?;
    let (optimized_gap, measured_s, distance_m) = lap_gap(laps.optimised)?;
    Ok(LapTimeDifference {
        initial_s: initial_gap,
        optimized_s: optimized_gap,
        measured_s,
        distance_m,
    })
}

/// What the lap plots are drawn from and where they go: the laps, the comparison's cutoff
/// [Hz], the folder, the workspace of the grid values and the list of files written.
struct LapPlots<'a, 'l> {
    laps: &'a Laps<'l>,
    cutoff: f64,
    folder: &'a Path,
    ws: &'a mut Workspace,
    files: &'a mut Vec<PathBuf>,
}

/// Saves a plot as `stem`.svg and .png in `folder` and lists both.
fn save_plot(
    save: impl FnOnce(&Path) -> Result<(), tb_plot::PlotError>,
    folder: &Path,
    stem: &str,
    files: &mut Vec<PathBuf>,
) -> Result<(), ReportError> {
    let stem = folder.join(stem);
    save(&stem)?;
    files.push(stem.with_extension("svg"));
    files.push(stem.with_extension("png"));
    Ok(())
}

/// The sum of the wheel loads (the lift coefficients' signal): the whole lap filtered, as
/// the comparison sees it; unfiltered over the first stretch, where the road's excitation
/// is readable (over a whole lap it is a band).
fn plot_fz_sum(out: &mut LapPlots<'_, '_>) -> Result<(), ReportError> {
    let (laps, cutoff, ws) = (out.laps, out.cutoff, &mut *out.ws);
    let (prepared, grid) = (laps.prepared, laps.grid());
    for (filtered, stem, title, window) in [
        (
            true,
            "fz_sum_filtered",
            format!("Sum of the four wheel loads over the lap, low-pass filtered at {cutoff} Hz: vehicle against twin"),
            None,
        ),
        (
            false,
            "fz_sum_unfiltered",
            format!("Sum of the four wheel loads, unfiltered, first {UNFILTERED_WINDOW_M} m of the lap: vehicle against twin"),
            Some(UNFILTERED_WINDOW_M),
        ),
    ] {
        let (rm, m) = prepared.on_grid(laps.meas, "Fz_sum", filtered, ws)?;
        let (ri, i) = prepared.on_grid(laps.initial, "Fz_sum", filtered, ws)?;
        let (ro, o) = prepared.on_grid(laps.optimised, "Fz_sum", filtered, ws)?;
        let within = |p: Vec<(f64, f64)>| match window {
            Some(w) => p.into_iter().filter(|q| q.0 <= w).collect(),
            None => p,
        };
        let plot = LinePlot::new(title, "distance [m]", "Fz_sum [N]")
            .styled("twin, initial parameters", &within(points(grid, ri, &i)), Style::Faint)
            .series("twin, optimised parameters", &within(points(grid, ro, &o)))
            .reference("vehicle (measured)", &within(points(grid, rm, &m)));
        save_plot(|stem| plot.save_both(stem), out.folder, stem, out.files)?;
    }
    Ok(())
}

/// Time over distance, and below it the twin's time minus the vehicle's: the lap times'
/// difference is a fraction of a percent, invisible on the lap's scale.
fn plot_time_over_distance(out: &mut LapPlots<'_, '_>) -> Result<(), ReportError> {
    let (laps, ws) = (out.laps, &mut *out.ws);
    let (prepared, grid) = (laps.prepared, laps.grid());
    let (rm, m) = prepared.on_grid(laps.meas, "time", false, ws)?;
    let (ro, o) = prepared.on_grid(laps.optimised, "time", false, ws)?;
    let vehicle = points(grid, rm.clone(), &m);
    let twin = points(grid, ro.clone(), &o);
    let gap: Vec<(f64, f64)> = {
        let (a, b) = (rm.start.max(ro.start), rm.end.min(ro.end));
        (a..b)
            .map(|g| {
                (
                    grid.at(g),
                    (o[g - ro.start] - o[0]) - (m[g - rm.start] - m[0]),
                )
            })
            .collect()
    };
    let end_gap = gap.last().map(|q| q.1).unwrap_or(f64::NAN);
    let figure = Figure::new(1200)
        .panel(
            LinePlot::new(
                "Time over distance: vehicle against the twin (bench) with the optimised parameters",
                "distance [m]",
                "time [s]",
            )
            .series("twin (bench), optimised parameters", &twin)
            .reference("vehicle (measured)", &vehicle),
            500,
        )
        .panel(
            LinePlot::new(
                format!("Twin's time minus the vehicle's over distance ({end_gap:+.2} s at the end of the lap)"),
                "distance [m]",
                "time difference [s]",
            )
            .series("twin − vehicle", &gap),
            300,
        );
    save_plot(
        |stem| figure.save_both(stem),
        out.folder,
        "time_over_distance",
        out.files,
    )
}

/// a_x of twin and car.
fn plot_a_x(out: &mut LapPlots<'_, '_>) -> Result<(), ReportError> {
    let (laps, cutoff, ws) = (out.laps, out.cutoff, &mut *out.ws);
    let (prepared, grid) = (laps.prepared, laps.grid());
    let (rm, m) = prepared.on_grid(laps.meas, "a_x", true, ws)?;
    let (ro, o) = prepared.on_grid(laps.optimised, "a_x", true, ws)?;
    let plot = LinePlot::new(
        format!("Longitudinal acceleration over distance, low-pass filtered at {cutoff} Hz: vehicle against twin"),
        "distance [m]",
        "a_x [m/s²]",
    )
    .series("twin (bench), optimised parameters", &points(grid, ro, &o))
    .reference("vehicle (measured)", &points(grid, rm, &m));
    save_plot(
        |stem| plot.save_both(stem),
        out.folder,
        "a_x_over_distance",
        out.files,
    )
}

/// Writes Tab. 1 (Markdown, JSON), the result JSON and the plots into `folder`, from the
/// result and its laps.
pub fn write_report(
    study: &Study,
    result: &StudyResult,
    folder: &Path,
) -> Result<ReportFiles, ReportError> {
    std::fs::create_dir_all(folder).map_err(|source| ReportError::Io {
        path: folder.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    write(
        &folder.join("result.json"),
        &serde_json::to_vec_pretty(result).expect("serialises"),
        &mut files,
    )?;

    // How the optimiser converged, and the profiles where run (plots.rs).
    plots::convergence(result, folder, &mut files)?;
    plots::profiles(result, folder, &mut files)?;

    // The laps with the initial and the optimised parameters, as the study ran them.
    let initial = result
        .laps
        .initial
        .as_ref()
        .ok_or(ReportError::MissingLap("initial"))?;
    let optimised = result
        .laps
        .optimized
        .as_ref()
        .ok_or(ReportError::MissingLap("optimised"))?;
    let measurement = Measurement::load(&study.measurement_path, &study.channels)
        .map_err(tb_compare::Error::from)?;
    let prepared = PreparedMeasurement::new(&measurement, &["Fz_sum", "a_x"], &study.file.compare)?;
    let mut ws = Workspace::new();
    let meas: &Table = measurement.table();

    // Tab. 1, with the lap times' difference the time plot below shows.
    let laps = Laps {
        prepared: &prepared,
        meas,
        initial,
        optimised,
    };
    let t = table1(result, Some(lap_time_difference(&laps, &mut ws)?));
    let md = table1_markdown(&t);
    write(&folder.join("table1.md"), md.as_bytes(), &mut files)?;
    write(
        &folder.join("table1.json"),
        &serde_json::to_vec_pretty(&t).expect("serialises"),
        &mut files,
    )?;

    let mut out = LapPlots {
        laps: &laps,
        cutoff: study.file.compare.cutoff_hz,
        folder,
        ws: &mut ws,
        files: &mut files,
    };
    plot_fz_sum(&mut out)?;
    plot_time_over_distance(&mut out)?;
    plot_a_x(&mut out)?;

    // All of it on one page to hand on, with every compared signal and the parameters'
    // picture (html.rs).
    let laps = [meas, initial, optimised];
    let signals = signals::figures(study, &prepared, laps, &mut ws)?;
    let page = html::page(&html::Page {
        study,
        result,
        table: &t,
        signals: &signals,
        plots: &files,
    })?;
    write(&folder.join("report.html"), page.as_bytes(), &mut files)?;

    Ok(ReportFiles {
        folder: folder.to_path_buf(),
        table_markdown: md,
        files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tb_testkit::assert_contains;

    /// Statements of one cause make one line naming every parameter it concerns, with
    /// what to do next; one of no known cause stays under its parameter.
    #[test]
    fn a_change_from_zero_is_said_in_words_not_as_nan_percent() {
        assert_eq!(change_words(12.34, 1.0, 1.1234), "+12.3 %");
        assert_eq!(change_words(f64::NAN, 0.0, 0.5), "from 0");
        assert_eq!(change_words(f64::NAN, 0.0, 0.0), "unchanged");
        assert_eq!(change_words(-50.0, 2.0, 1.0), "-50.0 %");
    }

    #[test]
    fn statements_are_merged_per_cause_with_what_to_do_next() {
        let items: Vec<(String, String)> = [
            ("c_lift_front", "on its lower bound (0.2): the optimum is not inside the range, so no interval; the data want it beyond [0.2, 2.5]"),
            ("l", "on its upper bound (4.5): the optimum is not inside the range"),
            ("b_front", "not determined by these signals within [0.9, 2]"),
            ("b_rear", "b_rear: not determined by these signals within [0.9, 2] m"),
            ("c_lift_rear", "open above: any value up to the bound 2.5 fits"),
            ("mass", "mass: the profile stopped: a lap failed"),
        ]
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
        let lines = merged_statements(&items);
        assert_eq!(lines.len(), 4, "{lines:#?}");
        assert!(
            lines[0].starts_with("- On a bound of its range"),
            "{}",
            lines[0]
        );
        assert_contains(
            &lines[0],
            &["c_lift_front (low end), l (high end)", "virtual"],
        );
        assert_contains(
            &lines[1],
            &["b_front, b_rear", "second lap", "twinbench validate"],
        );
        assert_contains(&lines[2], &["c_lift_rear (high end)"]);
        assert_eq!(lines[3], "- mass: the profile stopped: a lap failed");
        // Nothing to say, nothing said.
        assert!(merged_statements(&[]).is_empty());
    }
}
