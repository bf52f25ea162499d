//! The comparison pipeline (paper §4.2, docs/bench.md, comparing with the vehicle): both the measurement and the
//! simulation are low-pass filtered alike (zero-phase Butterworth, same order and cutoff in
//! Hz, each at its own uniform sample rate, in time), then interpolated onto one linearly
//! spaced distance grid, then compared signal by signal ([`crate::metrics`]).
//!
//! The grid starts at the measurement's first distance and steps by `distance_step_m` to its
//! last. Everything that depends on the measurement only is computed once in
//! [`PreparedMeasurement::new`]; [`PreparedMeasurement::compare`] then filters and resamples
//! the simulation into the reusable buffers of a [`Workspace`] and compares on the grid
//! points that the simulation's distance range covers.
//!
//! Derived signals: `Fz_sum` = fl+fr+rl+rr (Eq. 17), `Fz_front` = fl+fr, `Fz_rear` = rl+rr,
//! computed from the wheel loads where those exist (else a column of that name is used).

use crate::error::{Error, Result};
use crate::filter::{uniform_sample_rate, Butterworth};
use crate::measurement::{check_forward, cumulative_trapezoid_into, Measurement};
use crate::metrics::{metrics, Metrics};
use crate::resample::{interpolate_onto, DistanceGrid};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::Path;
use tb_table::{Table, TableError};

/// Derived signals and the columns they sum.
pub const DERIVED_SIGNALS: [(&str, &[&str]); 3] = [
    ("Fz_sum", &["Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"]),
    ("Fz_front", &["Fz_fl", "Fz_fr"]),
    ("Fz_rear", &["Fz_rl", "Fz_rr"]),
];

/// Settings of the comparison; embeddable in a study TOML (all fields optional there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CompareSettings {
    /// Low-pass cutoff [Hz] (−3 dB of one pass; the zero-phase result is −6 dB there).
    pub cutoff_hz: f64,
    /// Butterworth order of one pass (the forward-backward result has twice the roll-off).
    pub filter_order: usize,
    /// Spacing of the distance grid [m].
    pub distance_step_m: f64,
    /// Least fraction of the measured distance the simulation must cover (0..=1); a
    /// simulation that stops early is an error rather than a flattering partial score.
    pub min_coverage: f64,
    /// Simulation's time column.
    pub time_signal: String,
    /// Simulation's distance column; when absent, distance is integrated from `speed_signal`.
    pub distance_signal: String,
    /// Simulation's speed column [m/s].
    pub speed_signal: String,
}

impl Default for CompareSettings {
    fn default() -> Self {
        Self {
            cutoff_hz: 2.0,
            filter_order: 2,
            distance_step_m: 1.0,
            min_coverage: 0.9,
            time_signal: "time".into(),
            distance_signal: "distance".into(),
            speed_signal: "v".into(),
        }
    }
}

impl CompareSettings {
    /// Checks ranges (the cutoff against the sample rate is checked when filtering).
    pub fn validate(&self) -> Result<()> {
        let positive = self.cutoff_hz.is_finite() && self.cutoff_hz > 0.0;
        require(positive, "cutoff_hz", self.cutoff_hz, "must be positive")?;
        let order = (1..=16).contains(&self.filter_order);
        require(order, "filter_order", self.filter_order, "outside 1..=16")?;
        // At least 1 mm: a finer grid of a lap is tens of millions of points per signal.
        let step = self.distance_step_m;
        let fine = step.is_finite() && step >= 1e-3;
        require(fine, "distance_step_m", step, "must be at least 0.001 m")?;
        let coverage = (0.0..=1.0).contains(&self.min_coverage);
        require(coverage, "min_coverage", self.min_coverage, "outside 0..=1")
    }
}

/// A setting checked: when `ok` is false, the error `name = value rule`.
fn require(ok: bool, name: &str, value: impl std::fmt::Display, rule: &str) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::Settings(format!("{name} = {value} {rule}")))
    }
}

/// One signal's result.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SignalComparison {
    pub signal: String,
    #[serde(flatten)]
    pub metrics: Metrics,
}

/// The result of comparing one simulation with the prepared measurement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// Per signal, in the order prepared.
    pub signals: Vec<SignalComparison>,
    /// Distance range compared [m] (grid points within it).
    pub distance_range_m: [f64; 2],
    /// Fraction of the measured distance range that the simulation covers.
    pub coverage: f64,
}

impl Comparison {
    /// The metrics of `signal`.
    pub fn get(&self, signal: &str) -> Option<&Metrics> {
        self.signals
            .iter()
            .find(|s| s.signal == signal)
            .map(|s| &s.metrics)
    }
}

/// Reusable buffers for [`PreparedMeasurement::compare`]: one per worker thread. After the
/// first call with a given simulation length, a comparison allocates only its result.
#[derive(Debug, Default)]
pub struct Workspace {
    filter: Option<Butterworth>,
    distance: Vec<f64>,
    raw: Vec<f64>,
    filtered: Vec<f64>,
    scratch: Vec<f64>,
    resampled: Vec<f64>,
}

impl Workspace {
    pub fn new() -> Self {
        Self::default()
    }
}

#[derive(Debug, Clone)]
struct PreparedSignal {
    name: String,
    values: Vec<f64>,
}

/// The measurement filtered and resampled onto the distance grid, for the chosen signals.
/// `Send + Sync`: share one between worker threads.
#[derive(Debug, Clone)]
pub struct PreparedMeasurement {
    settings: CompareSettings,
    grid: DistanceGrid,
    sample_rate_hz: f64,
    signals: Vec<PreparedSignal>,
}

/// How a signal is obtained from a table.
enum Source {
    Column(usize),
    Sum([usize; 4], usize),
}

fn resolve(table: &Table, name: &str) -> Result<Source> {
    if let Some((_, parts)) = DERIVED_SIGNALS.iter().find(|(n, _)| *n == name) {
        let mut idx = [0usize; 4];
        let mut all = true;
        for (k, p) in parts.iter().enumerate() {
            match table.find(p)? {
                Some(i) => idx[k] = i,
                None => all = false,
            }
        }
        if all {
            return Ok(Source::Sum(idx, parts.len()));
        }
        if let Some(i) = table.find(name)? {
            return Ok(Source::Column(i));
        }
        // Name the first missing part.
        for p in parts.iter() {
            table.require(p)?;
        }
    }
    match table.find(name)? {
        Some(i) => Ok(Source::Column(i)),
        // Unknown: the closest of the table's columns and the derived signals.
        None => {
            let names = table
                .names()
                .iter()
                .map(String::as_str)
                .chain(DERIVED_SIGNALS.iter().map(|(n, _)| *n));
            let closest = tb_files::names::closest(name, names, 3);
            Err(Error::UnknownSignal {
                file: table.source().into(),
                signal: name.into(),
                closest: closest.join(", "),
                available: table.names().join(", "),
            })
        }
    }
}

/// The signal's values: a column slice, or the sum written into `buf`. Non-finite values are
/// an error naming the line and column.
fn materialise<'a>(table: &'a Table, src: &Source, buf: &'a mut Vec<f64>) -> Result<&'a [f64]> {
    match *src {
        Source::Column(i) => {
            table.check_finite(i)?;
            Ok(table.column_at(i))
        }
        Source::Sum(idx, n) => {
            for &i in &idx[..n] {
                table.check_finite(i)?;
            }
            buf.clear();
            buf.extend_from_slice(table.column_at(idx[0]));
            for &i in &idx[1..n] {
                for (b, v) in buf.iter_mut().zip(table.column_at(i)) {
                    *b += v;
                }
            }
            Ok(buf)
        }
    }
}

fn sample_rate(table: &Table, time_col: usize) -> Result<f64> {
    let t = table.column_at(time_col);
    table.check_finite(time_col)?;
    crate::measurement::check_increasing_time(table, time_col)?;
    uniform_sample_rate(t).map_err(|(i, step, expected)| {
        if t.len() < 2 {
            Error::TooShort {
                file: table.source().into(),
                samples: t.len(),
                needed: "at least 2 are needed for a sample rate".into(),
            }
        } else {
            Error::NonUniformSampling {
                file: table.source().into(),
                row: table.line_of(i),
                column: table.name_at(time_col).into(),
                step,
                expected,
            }
        }
    })
}

fn too_short(table: &Table, e: Error) -> Error {
    match e {
        Error::TooShort {
            samples, needed, ..
        } => Error::TooShort {
            file: table.source().into(),
            samples,
            needed,
        },
        e => e,
    }
}

impl PreparedMeasurement {
    /// Filters and resamples the measurement's `signals` (column names or derived names).
    pub fn new<S: AsRef<str>>(
        measurement: &Measurement,
        signals: &[S],
        settings: &CompareSettings,
    ) -> Result<Self> {
        settings.validate()?;
        if signals.is_empty() {
            return Err(Error::Settings("no signals to compare".into()));
        }
        let table = measurement.table();
        let fs = sample_rate(table, table.require_index("time")?)?;
        let filter = Butterworth::lowpass(settings.filter_order, settings.cutoff_hz, fs)?;
        let d = measurement.distance();
        let grid = DistanceGrid::over(d[0], d[d.len() - 1], settings.distance_step_m)?;
        let mut buf = Vec::new();
        let mut filtered = Vec::new();
        let mut scratch = Vec::new();
        let mut prepared = Vec::with_capacity(signals.len());
        for s in signals {
            let name = s.as_ref();
            if prepared.iter().any(|p: &PreparedSignal| p.name == name) {
                continue;
            }
            let src = resolve(table, name)?;
            let raw = materialise(table, &src, &mut buf)?;
            filter
                .filtfilt(raw, &mut filtered, &mut scratch)
                .map_err(|e| too_short(table, e))?;
            let mut values = Vec::new();
            interpolate_onto(d, &filtered, &grid, 0..grid.len(), &mut values);
            prepared.push(PreparedSignal {
                name: name.into(),
                values,
            });
        }
        Ok(Self {
            settings: settings.clone(),
            grid,
            sample_rate_hz: fs,
            signals: prepared,
        })
    }

    /// Reads the measurement file and prepares it.
    pub fn from_path<S: AsRef<str>>(
        path: impl AsRef<Path>,
        signals: &[S],
        settings: &CompareSettings,
    ) -> Result<Self> {
        Self::new(&Measurement::read_path(path)?, signals, settings)
    }

    pub fn settings(&self) -> &CompareSettings {
        &self.settings
    }

    /// The distance grid (over the whole measurement).
    pub fn grid(&self) -> &DistanceGrid {
        &self.grid
    }

    /// The measurement's sample rate [Hz].
    pub fn sample_rate_hz(&self) -> f64 {
        self.sample_rate_hz
    }

    /// The prepared signal names, in order.
    pub fn signal_names(&self) -> impl Iterator<Item = &str> {
        self.signals.iter().map(|s| s.name.as_str())
    }

    /// The filtered measured signal on the whole grid.
    pub fn measured(&self, signal: &str) -> Option<&[f64]> {
        self.signals
            .iter()
            .find(|s| s.name == signal)
            .map(|s| s.values.as_slice())
    }

    /// Compares a simulation result (columns: time, distance or speed, the signals, found by
    /// exact name or as `instance.name`) with every prepared signal.
    pub fn compare(&self, sim: &Table, ws: &mut Workspace) -> Result<Comparison> {
        let run = self.prepare_run(sim, ws)?;
        let Workspace {
            filter,
            distance,
            raw,
            filtered,
            scratch,
            resampled,
        } = ws;
        let filter = filter.as_ref().expect("set by prepare_run");
        let dist: &[f64] = match run.distance_col {
            Some(i) => sim.column_at(i),
            None => distance,
        };
        let mut out = Vec::with_capacity(self.signals.len());
        for p in &self.signals {
            let src = resolve(sim, &p.name)?;
            let x = materialise(sim, &src, raw)?;
            filter
                .filtfilt(x, filtered, scratch)
                .map_err(|e| too_short(sim, e))?;
            interpolate_onto(dist, filtered, &self.grid, run.range.clone(), resampled);
            let m = metrics(&p.name, &p.values[run.range.clone()], resampled)?;
            out.push(SignalComparison {
                signal: p.name.clone(),
                metrics: m,
            });
        }
        Ok(Comparison {
            signals: out,
            distance_range_m: [
                self.grid.at(run.range.start),
                self.grid.at(run.range.end - 1),
            ],
            coverage: run.coverage,
        })
    }

    /// One signal of any table with time and distance/speed (a simulation, or the
    /// measurement's own table) on the grid points it covers, filtered like the comparison
    /// or not; for plots (Fig. 7). Returns the grid index range and the values.
    pub fn on_grid(
        &self,
        table: &Table,
        signal: &str,
        filtered: bool,
        ws: &mut Workspace,
    ) -> Result<(Range<usize>, Vec<f64>)> {
        let run = self.prepare_run(table, ws)?;
        let dist: &[f64] = match run.distance_col {
            Some(i) => table.column_at(i),
            None => &ws.distance,
        };
        let src = resolve(table, signal)?;
        let x = materialise(table, &src, &mut ws.raw)?;
        let y = if filtered {
            ws.filter
                .as_ref()
                .expect("set by prepare_run")
                .filtfilt(x, &mut ws.filtered, &mut ws.scratch)
                .map_err(|e| too_short(table, e))?;
            &ws.filtered
        } else {
            x
        };
        let mut out = Vec::new();
        interpolate_onto(dist, y, &self.grid, run.range.clone(), &mut out);
        Ok((run.range, out))
    }

    /// Time base, filter, distance and covered grid range of a table.
    fn prepare_run(&self, sim: &Table, ws: &mut Workspace) -> Result<Run> {
        let s = &self.settings;
        let tcol = sim.require_index(&s.time_signal)?;
        let fs = sample_rate(sim, tcol)?;
        let reuse = ws
            .filter
            .as_ref()
            .is_some_and(|f| (f.sample_rate_hz() - fs).abs() <= 1e-9 * fs);
        if !reuse {
            ws.filter = Some(Butterworth::lowpass(s.filter_order, s.cutoff_hz, fs)?);
        }
        let distance_col = sim.find(&s.distance_signal)?;
        let d: &[f64] = match distance_col {
            Some(i) => {
                sim.check_finite(i)?;
                sim.column_at(i)
            }
            None => {
                let v = sim.require_index(&s.speed_signal).map_err(|_| {
                    Error::Table(TableError::MissingColumn {
                        file: sim.source().into(),
                        column: format!("{}` or `{}", s.distance_signal, s.speed_signal),
                        available: sim.names().join(", "),
                    })
                })?;
                sim.check_finite(v)?;
                cumulative_trapezoid_into(sim.column_at(tcol), sim.column_at(v), &mut ws.distance);
                &ws.distance
            }
        };
        let dcol_name = distance_col.map_or_else(
            || format!("distance integrated from `{}`", s.speed_signal),
            |i| sim.name_at(i).to_owned(),
        );
        check_forward(d, |i| {
            (sim.source().into(), sim.line_of(i), dcol_name.clone())
        })?;
        let (lo, hi) = (d[0], d[d.len() - 1]);
        let range = self.grid.range_within(lo, hi);
        let total = self.grid.at(self.grid.len() - 1) - self.grid.start();
        let covered =
            (hi.min(self.grid.at(self.grid.len() - 1)) - lo.max(self.grid.start())).max(0.0);
        let coverage = if total > 0.0 { covered / total } else { 0.0 };
        if coverage < s.min_coverage || range.len() < 3 {
            return Err(Error::InsufficientOverlap {
                file: sim.source().into(),
                coverage,
                min_coverage: s.min_coverage,
                covered_m: covered,
                total_m: total,
            });
        }
        Ok(Run {
            distance_col,
            range,
            coverage,
        })
    }
}

struct Run {
    distance_col: Option<usize>,
    range: Range<usize>,
    coverage: f64,
}

/// Reads both files and compares (for the CLI and one-off use; the optimiser should keep a
/// [`PreparedMeasurement`] and a [`Workspace`]).
pub fn compare_files<S: AsRef<str>>(
    sim: impl AsRef<Path>,
    measurement: impl AsRef<Path>,
    signals: &[S],
    settings: &CompareSettings,
) -> Result<Comparison> {
    let prepared = PreparedMeasurement::from_path(measurement, signals, settings)?;
    let sim = Table::read_path(sim)?;
    prepared.compare(&sim, &mut Workspace::new())
}
