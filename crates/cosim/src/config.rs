//! The system description file (TOML): FMUs, instances, connections, parameters, the
//! experiment, what to record, replayed measurement channels, port maps.

use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A whole system file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemFile {
    /// A name for reports.
    #[serde(default)]
    pub name: Option<String>,
    /// FMU files by a short name; relative paths are relative to the system file.
    pub fmus: BTreeMap<String, PathBuf>,
    /// Instances, in the order they are declared (the stepping order's tie-breaker).
    #[serde(rename = "instance", default)]
    pub instances: Vec<InstanceConfig>,
    /// `"a.x -> b.y"`, or a table with a unit or gain override (see [`ConnectionConfig`]).
    #[serde(default)]
    pub connections: Vec<ConnectionConfig>,
    /// `"instance.variable" = value`.
    #[serde(default)]
    pub parameters: BTreeMap<String, toml::Value>,
    pub experiment: ExperimentConfig,
    #[serde(default)]
    pub record: RecordConfig,
    /// Measurement channels replayed as signals (`<name>.<column>`).
    #[serde(default)]
    pub replay: Vec<ReplayConfig>,
    /// Shared libraries to load with RTLD_GLOBAL before any FMU (e.g. libpython for pythonfmu FMUs).
    #[serde(default)]
    pub preload: Vec<PathBuf>,
    /// Consistency checks after initialisation, before the first step.
    #[serde(rename = "check", default)]
    pub checks: Vec<CheckConfig>,
    /// For a system read from an SSP package: the unpacked package, the one folder its
    /// path parameters may name files in (a colleague's package is untrusted input: it
    /// must not make an FMU read `/etc/shadow`). None for a system file.
    #[serde(skip)]
    pub package: Option<PathBuf>,
}

/// One connection: `"a.x -> b.y"`, converted by the units both FMUs declare; or a table
/// for what the declarations cannot give:
/// - `{ from = "a.x", to = "b.y", to_unit = "rpm" }`: the unit taken for one end (or
///   `from_unit`), looked up in that FMU's unit definitions, then in twinbench's table;
/// - `{ from = "a.x", to = "b.y", scale = 9.5493, offset = 0.0 }`: `to = scale·from +
///   offset`, instead of any unit conversion.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ConnectionConfig {
    /// `"a.x -> b.y"` (for a table: built from `from` and `to`).
    pub text: String,
    pub scale: Option<f64>,
    pub offset: Option<f64>,
    pub from_unit: Option<String>,
    pub to_unit: Option<String>,
}

impl ConnectionConfig {
    /// Whether the file overrides what the units would give.
    pub fn overrides(&self) -> bool {
        self.scale.is_some()
            || self.offset.is_some()
            || self.from_unit.is_some()
            || self.to_unit.is_some()
    }
}

impl From<&str> for ConnectionConfig {
    fn from(text: &str) -> Self {
        ConnectionConfig {
            text: text.to_string(),
            ..Default::default()
        }
    }
}

impl<'de> Deserialize<'de> for ConnectionConfig {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Table {
            from: String,
            to: String,
            scale: Option<f64>,
            offset: Option<f64>,
            from_unit: Option<String>,
            to_unit: Option<String>,
        }
        use serde::de::Error;
        match toml::Value::deserialize(d)? {
            toml::Value::String(text) => Ok(ConnectionConfig {
                text,
                ..Default::default()
            }),
            toml::Value::Table(t) => {
                let t = Table::deserialize(toml::Value::Table(t)).map_err(|e| {
                    D::Error::custom(format!(
                        "connection table: {} (allowed keys: from, to, scale, offset, from_unit, to_unit)",
                        e.message()
                    ))
                })?;
                Ok(ConnectionConfig {
                    text: format!("{} -> {}", t.from.trim(), t.to.trim()),
                    scale: t.scale,
                    offset: t.offset,
                    from_unit: t.from_unit,
                    to_unit: t.to_unit,
                })
            }
            other => Err(D::Error::custom(format!(
                "a connection is \"a.x -> b.y\" or {{ from = \"a.x\", to = \"b.y\", ... }}, got a TOML {}",
                other.type_str()
            ))),
        }
    }
}

/// Signals that must agree after initialisation (e.g. the lap lengths of the vehicle's track
/// and the driver's target): otherwise the run stops before its first step.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckConfig {
    /// Two or more `instance.variable` outputs.
    pub equal: Vec<String>,
    /// Largest relative difference |a − b| / max(|a|, |b|) allowed.
    #[serde(default = "half_percent")]
    pub relative_tolerance: f64,
    /// What a failure means, for the message.
    #[serde(default)]
    pub why: Option<String>,
}

fn half_percent() -> f64 {
    0.005
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceConfig {
    pub name: String,
    /// Key of `[fmus]`.
    pub fmu: String,
    /// Port map for a swapped unit: the name used in this file -> the FMU's own variable name.
    #[serde(default)]
    pub ports: BTreeMap<String, String>,
    /// Ask the FMU for debug logging.
    #[serde(default)]
    pub logging: bool,
    /// Run this instance in a worker process (a crash or hang of the FMU ends the run
    /// with an error instead of taking twinbench down).
    #[serde(default)]
    pub isolate: bool,
    /// With `isolate`: the longest wait for one call of this instance [s] (default 10 s).
    #[serde(default)]
    pub watchdog: Option<f64>,
    /// The relative tolerance of this FMU's internal solver (default: the experiment's,
    /// else the FMU's DefaultExperiment tolerance).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// The FMI interface: `"co-simulation"` or `"model-exchange"` (twinbench integrates
    /// the FMU with CVODE). Default: Co-Simulation when the FMU has it, else Model
    /// Exchange. Refused when the FMU lacks the interface.
    #[serde(default, deserialize_with = "interface")]
    pub interface: Option<tb_fmi::Interface>,
}

fn interface<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Option<tb_fmi::Interface>, D::Error> {
    let name = String::deserialize(d)?;
    tb_fmi::Interface::from_name(&name)
        .map(Some)
        .map_err(serde::de::Error::custom)
}

/// The master algorithm a system runs with. Its names are one list ([`Algorithm::ALL`],
/// [`Algorithm::name`]): the system file, the master, SSP export and import and
/// `tools/fmpy_cosim.py` (tested against it) read them from here.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Algorithm {
    #[default]
    GaussSeidel,
    Jacobi,
}

impl Algorithm {
    pub const ALL: [Algorithm; 2] = [Algorithm::GaussSeidel, Algorithm::Jacobi];

    /// The name in system files, SSP packages and messages.
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::GaussSeidel => "gauss-seidel",
            Algorithm::Jacobi => "jacobi",
        }
    }

    /// The algorithm of a name; the error lists the names there are.
    pub fn from_name(name: &str) -> Result<Algorithm, UnknownName> {
        Algorithm::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| UnknownName::Algorithm { name: name.into() })
    }

    /// `gauss-seidel, jacobi`.
    pub fn names() -> String {
        Algorithm::ALL.map(Algorithm::name).join(", ")
    }
}

impl<'de> Deserialize<'de> for Algorithm {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        Algorithm::from_name(&name).map_err(serde::de::Error::custom)
    }
}

/// The communication step size each `fmi2DoStep` is given.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum StepConvention {
    /// `h` itself, every step (the last one to a stop time aside): what the system file
    /// says, the same bits at every step.
    #[default]
    H,
    /// `t[n+1] − t[n]` of the grid `t[n] = start + n·h`, as FMPy passes it: an ulp off `h`
    /// at some steps, so that an FMU that counts its own time from the step sizes lands on
    /// the grid's times exactly.
    Grid,
}

impl StepConvention {
    pub const ALL: [StepConvention; 2] = [StepConvention::H, StepConvention::Grid];

    pub fn name(self) -> &'static str {
        match self {
            StepConvention::H => "h",
            StepConvention::Grid => "grid",
        }
    }

    pub fn from_name(name: &str) -> Result<Self, UnknownName> {
        Self::ALL
            .into_iter()
            .find(|c| c.name() == name)
            .ok_or_else(|| UnknownName::StepConvention { name: name.into() })
    }
}

impl<'de> Deserialize<'de> for StepConvention {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        StepConvention::from_name(&name).map_err(serde::de::Error::custom)
    }
}

/// A name of the system file's that names nothing: the error lists the names there are.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum UnknownName {
    #[error("unknown algorithm \"{name}\" ({})", Algorithm::names())]
    Algorithm { name: String },
    #[error("step_convention = \"{name}\" is not one of \"h\" (the step h itself) or \"grid\" (t[n+1] - t[n], as FMPy)")]
    StepConvention { name: String },
}

/// `stop = 100.0` (a time, s) or `stop = "vehicle.lap >= 1"` (a condition on a signal);
/// `stop = "lap"` is the older spelling of `"<lap_signal> >= <lap_count>"`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum StopConfig {
    Time(f64),
    Word(String),
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    #[serde(default)]
    pub start: f64,
    /// Macro step [s].
    pub step: f64,
    pub stop: StopConfig,
    /// With the older `stop = "lap"`: the condition `lap_signal >= lap_count` ends the run.
    #[serde(default)]
    pub lap_signal: Option<String>,
    #[serde(default = "one")]
    pub lap_count: f64,
    /// With a stop condition: give up after this simulated time [s].
    #[serde(default = "default_max_time")]
    pub max_time: f64,
    /// Signals whose values at the end of a run the run summary reports (e.g. a lap time).
    #[serde(default)]
    pub report: Vec<String>,
    #[serde(default)]
    pub algorithm: Algorithm,
    /// Explicit stepping order (instance names); default: derived from the connections.
    #[serde(default)]
    pub order: Vec<String>,
    /// The relative tolerance passed to every FMU (`fmi2SetupExperiment`,
    /// `fmi3EnterInitializationMode`), for FMUs with an internal variable-step solver,
    /// and to CVODE for Model Exchange instances; default: each FMU's DefaultExperiment
    /// tolerance (as FMPy), else none (Model Exchange: 1e-5, FMPy's).
    #[serde(default)]
    pub tolerance: Option<f64>,
    /// The step size each `fmi2DoStep` is given: `"h"` (default) or `"grid"` (as FMPy).
    #[serde(default)]
    pub step_convention: StepConvention,
}

fn one() -> f64 {
    1.0
}
fn default_max_time() -> f64 {
    600.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordConfig {
    /// `instance.variable` names; empty: every output.
    #[serde(default)]
    pub signals: Vec<String>,
    /// Record every n-th macro step.
    #[serde(default = "one_usize")]
    pub decimation: usize,
}

impl Default for RecordConfig {
    fn default() -> Self {
        RecordConfig {
            signals: Vec::new(),
            decimation: 1,
        }
    }
}

fn one_usize() -> usize {
    1
}

#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ReplayBasis {
    Time,
    Distance,
}

/// How a replay finds values between its rows.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum Interpolation {
    #[default]
    Auto,
    Linear,
    Hold,
}

/// Replay of measurement columns, by time or by a distance signal of the system.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayConfig {
    pub name: String,
    /// A measurement CSV (data/README.md format); relative to the system file.
    pub file: PathBuf,
    pub basis: ReplayBasis,
    /// For `basis = "distance"`: the system signal giving the distance (e.g. `vehicle.distance`).
    #[serde(default)]
    pub by: Option<String>,
    /// The replayed columns; empty: every numeric column of a time-based file.
    #[serde(default)]
    pub columns: Vec<String>,
    /// How values between rows are found: `"linear"`, `"hold"` (the last row at or before),
    /// or `"auto"` (the default: hold for the inputs FMPy holds, Integer, Boolean,
    /// Enumeration and discrete or tunable Reals; linear for continuous Reals).
    #[serde(default)]
    pub interpolation: Interpolation,
    /// Unit of each column (default: the column's SI unit from data/README.md, else "1").
    #[serde(default)]
    pub units: BTreeMap<String, String>,
}

impl SystemFile {
    /// Read and parse; relative paths are resolved against the file's folder.
    pub fn load(path: &Path) -> Result<SystemFile, super::SystemError> {
        // A regular file within the limit of a configuration file.
        let bytes = tb_files::input::read(path, tb_files::Limit::CONFIG).map_err(|e| {
            super::SystemError::File {
                path: path.to_path_buf(),
                message: tb_files::input::reason(&e, path),
            }
        })?;
        let text = String::from_utf8(bytes).map_err(|e| super::SystemError::File {
            path: path.to_path_buf(),
            message: match e.as_bytes().starts_with(b"PK\x03\x04") {
                true => "is a ZIP archive (an FMU?), not a system file: `run` takes a system file (TOML), an SSP 1.0 package (.ssp) or an FMU named .fmu (run on its own)".into(),
                false => format!(
                    "is not a text file (byte {} is not UTF-8): a system file is TOML",
                    e.utf8_error().valid_up_to()
                ),
            },
        })?;
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<SystemFile, super::SystemError> {
        let mut sys: SystemFile = toml::from_str(text).map_err(|e| super::SystemError::File {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // Names in the file are relative to its folder, whatever the working directory.
        let base = tb_files::folder_of(path);
        for p in sys.fmus.values_mut() {
            *p = tb_files::resolve(&base, p);
        }
        for r in &mut sys.replay {
            r.file = tb_files::resolve(&base, &r.file);
        }
        for p in &mut sys.preload {
            // A bare library name is looked up by the loader, as dlopen does.
            if p.is_absolute() || p.components().count() > 1 {
                *p = tb_files::resolve(&base, p);
            }
        }
        Ok(sys)
    }
}
