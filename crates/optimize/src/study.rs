//! The study file (TOML): the system, the measurement, the comparison settings, the
//! optimiser, and the steps (parameters with bounds, validation signals with weights).
//! Paths are relative to the study file.

use super::cmaes::CmaesSettings;
use super::ga::GaSettings;
use crate::error::OptimizeError;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tb_compare::{ChannelMap, CompareSettings};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyFile {
    /// A name for reports and the default checkpoint file.
    #[serde(default)]
    pub name: Option<String>,
    /// The system file (TOML) run for every candidate.
    pub system: PathBuf,
    /// The vehicle measurement: a path (MDF 4 or CSV), or `{ file = "...", channels = {
    /// v = "GPS_Speed", ... } }` with the channel of each twinbench signal; or several laps,
    /// `[[measurement]]` entries, each with its file and its own system, parameters (track,
    /// target, start values) and weight, sharing the study's parameters.
    pub measurement: Measurements,
    /// Seed of every random draw of the study.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Cost of a candidate whose simulation or comparison fails.
    #[serde(default = "default_penalty")]
    pub penalty: f64,
    /// Weight of |bias| next to e in the cost (per signal); see docs/optimize.md.
    #[serde(default)]
    pub bias_weight: f64,
    /// Comparison settings (tb-compare), all optional.
    #[serde(default)]
    pub compare: CompareSettings,
    /// Overrides of the system's `[record]` (fewer signals, coarser decimation: faster).
    #[serde(default)]
    pub record: Option<RecordOverride>,
    /// Fixed parameter values applied to every run (`"instance.variable" = value`: a
    /// number, an integer, a boolean or a string; a `*_file` path relative to the study).
    #[serde(default)]
    pub parameters: std::collections::BTreeMap<String, toml::Value>,
    pub optimizer: OptimizerConfig,
    #[serde(rename = "step")]
    pub steps: Vec<StepConfig>,
    /// Identifiability: a direction is reported as not seen when its eigenvalue of JᵀJ is
    /// below this fraction of the largest.
    #[serde(default = "default_null_ratio")]
    pub null_ratio: f64,
    /// Checks on the first run that measurement and twin belong together.
    #[serde(default)]
    pub plausibility: Plausibility,
    /// After the steps, move all their parameters together to the least-squares point of
    /// all their signals (Levenberg–Marquardt, `tb_optimize::fit`), where the intervals are
    /// centred. `false`: the steps' answer stands, and its intervals are centred on it.
    #[serde(default = "yes")]
    pub refine: bool,
    /// Profile likelihood of every parameter after the refinement (`tb_optimize::profile`;
    /// `twinbench optimize --profiles` asks for it too).
    #[serde(default)]
    pub profiles: bool,
    /// Refits of a moving-block bootstrap of the joint answer (`tb_optimize::bootstrap`;
    /// `twinbench optimize --bootstrap N` asks for it too); 0: none.
    #[serde(default)]
    pub bootstrap: usize,
}

fn yes() -> bool {
    true
}

/// Before optimising, the first run of the twin is checked against the measurement: a
/// measurement of another circuit, or a track that is not the measured one, is an error
/// (`twinbench optimize --force` runs anyway).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plausibility {
    /// Largest relative difference of the twin's and the measured lap length.
    #[serde(default = "one_percent")]
    pub lap_length: f64,
    /// Largest relative difference of the twin's and the measured lap time.
    #[serde(default = "five_percent")]
    pub lap_time: f64,
    /// Least R² of the twin's speed against the measured one over distance.
    #[serde(default = "r_squared_v")]
    pub r_squared_v: f64,
}

impl Default for Plausibility {
    fn default() -> Self {
        Plausibility {
            lap_length: one_percent(),
            lap_time: five_percent(),
            r_squared_v: r_squared_v(),
        }
    }
}

fn one_percent() -> f64 {
    0.01
}
fn five_percent() -> f64 {
    0.05
}
fn r_squared_v() -> f64 {
    0.9
}

/// One lap (`measurement = ...`, `[measurement]`) or several (`[[measurement]]`).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Measurements {
    One(MeasurementConfig),
    Laps(Vec<LapConfig>),
}

// By the value's shape, so that a mistake inside a `[[measurement]]` entry (an unknown key,
// a weight that is not a number) is named, not "did not match any variant".
impl<'de> Deserialize<'de> for Measurements {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let value = toml::Value::deserialize(d)?;
        match value {
            toml::Value::Array(_) => Vec::<LapConfig>::deserialize(value)
                .map(Measurements::Laps)
                .map_err(|e| D::Error::custom(format!("[[measurement]]: {e}"))),
            other => MeasurementConfig::deserialize(other)
                .map(Measurements::One)
                .map_err(|e| D::Error::custom(format!("measurement: {e}"))),
        }
    }
}

/// A `[[measurement]]` entry: a lap of its own, fitted with the others (its cost summed
/// with its weight) or held out (run with the answer and compared, never fitted).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LapConfig {
    /// A name for Tab. 1 (default: the file's stem).
    #[serde(default)]
    pub name: Option<String>,
    pub file: PathBuf,
    #[serde(default)]
    pub channels: ChannelMap,
    /// The lap's system file (default: the study's `system`).
    #[serde(default)]
    pub system: Option<PathBuf>,
    /// Values for this lap only (its track and target files, its start values), over the
    /// study's `[parameters]`; never a parameter the study fits.
    #[serde(default)]
    pub parameters: std::collections::BTreeMap<String, toml::Value>,
    /// The lap's weight in the cost (its cost times weight, summed, over the summed
    /// weights of the fitted laps).
    #[serde(default = "unit_weight")]
    pub weight: f64,
    /// Not fitted: run with the study's answer and compared (prediction on a lap not
    /// fitted).
    #[serde(default)]
    pub hold_out: bool,
}

fn unit_weight() -> f64 {
    1.0
}

/// `measurement = "lap.mf4"` or `[measurement] file = "lap.mf4"` with `[measurement.channels]`.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum MeasurementConfig {
    Path(PathBuf),
    Mapped {
        file: PathBuf,
        #[serde(default)]
        channels: ChannelMap,
    },
}

/// `[measurement]` as a table: its keys checked (a misspelt `file` or a `weight`, which
/// belongs to `[[measurement]]` entries, is named rather than ignored).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MappedMeasurement {
    file: PathBuf,
    #[serde(default)]
    channels: ChannelMap,
}

// By the value's shape, so that a mistake in the table is named, not "did not match any
// variant".
impl<'de> Deserialize<'de> for MeasurementConfig {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        match toml::Value::deserialize(d)? {
            toml::Value::String(s) => Ok(MeasurementConfig::Path(PathBuf::from(s))),
            t @ toml::Value::Table(_) => MappedMeasurement::deserialize(t)
                .map(|m| MeasurementConfig::Mapped {
                    file: m.file,
                    channels: m.channels,
                })
                .map_err(|e| D::Error::custom(e.to_string().trim_end().to_string())),
            other => Err(D::Error::custom(format!(
                "expected a file name (measurement = \"lap.mf4\") or a table with `file` and `channels` ([measurement]), found {}",
                other.type_str()
            ))),
        }
    }
}

impl MeasurementConfig {
    pub fn file(&self) -> &Path {
        match self {
            MeasurementConfig::Path(p) => p,
            MeasurementConfig::Mapped { file, .. } => file,
        }
    }

    pub fn channels(&self) -> ChannelMap {
        match self {
            MeasurementConfig::Path(_) => ChannelMap::default(),
            MeasurementConfig::Mapped { channels, .. } => channels.clone(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordOverride {
    pub signals: Vec<String>,
    #[serde(default = "one")]
    pub decimation: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum OptimizerKind {
    #[default]
    Ga,
    Cmaes,
}

impl OptimizerKind {
    pub fn name(self) -> &'static str {
        match self {
            OptimizerKind::Ga => "ga",
            OptimizerKind::Cmaes => "cmaes",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OptimizerConfig {
    #[serde(default)]
    pub kind: OptimizerKind,
    /// Generations per step (a step may override it).
    pub generations: usize,
    #[serde(default)]
    pub ga: GaSettings,
    #[serde(default)]
    pub cmaes: CmaesSettings,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepConfig {
    pub name: String,
    #[serde(rename = "parameter")]
    pub parameters: Vec<ParameterConfig>,
    /// Validation signals (measurement columns or Fz_sum, Fz_front, Fz_rear).
    pub signals: Vec<String>,
    /// Weights of the signals (default: all 1).
    #[serde(default)]
    pub weights: Option<Vec<f64>>,
    #[serde(default)]
    pub generations: Option<usize>,
    /// Overrides the study's `bias_weight` for this step.
    #[serde(default)]
    pub bias_weight: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterConfig {
    /// `instance.variable`.
    pub name: String,
    pub min: f64,
    pub max: f64,
    /// Start value; default: the value after earlier steps, else the system's.
    #[serde(default)]
    pub start: Option<f64>,
}

fn default_seed() -> u64 {
    1
}
fn default_penalty() -> f64 {
    10.0
}
fn default_null_ratio() -> f64 {
    5e-3
}
fn one() -> usize {
    1
}

/// A lap of a study with its paths resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct Lap {
    pub name: String,
    pub system_path: PathBuf,
    pub measurement_path: PathBuf,
    pub channels: ChannelMap,
    /// The lap's own parameter values (over the study's).
    pub parameters: std::collections::BTreeMap<String, toml::Value>,
    pub weight: f64,
    pub hold_out: bool,
}

/// A study file read and checked, with its paths resolved.
#[derive(Clone, Debug)]
pub struct Study {
    pub file: StudyFile,
    pub path: PathBuf,
    /// The first fitted lap's system, measurement and channels (the only ones of a study
    /// of one lap).
    pub system_path: PathBuf,
    pub measurement_path: PathBuf,
    /// The channel of each twinbench signal in the measurement file.
    pub channels: ChannelMap,
    /// Every lap: the fitted ones first, in the file's order, then the held-out ones.
    pub laps: Vec<Lap>,
    /// Hash of the study text: a checkpoint of another study is refused.
    pub fingerprint: String,
}

impl StepConfig {
    pub fn weights(&self) -> Vec<f64> {
        self.weights
            .clone()
            .unwrap_or_else(|| vec![1.0; self.signals.len()])
    }

    pub fn parameter_names(&self) -> Vec<String> {
        self.parameters.iter().map(|p| p.name.clone()).collect()
    }
}

impl Study {
    /// The signals of the joint fit with their weights: every step's, each once (its
    /// first step's weight), in the steps' order.
    pub fn joint_signals(&self) -> (Vec<String>, Vec<f64>) {
        let (mut signals, mut weights) = (Vec::new(), Vec::new());
        for step in &self.file.steps {
            for (s, w) in step.signals.iter().zip(step.weights()) {
                if !signals.contains(s) {
                    signals.push(s.clone());
                    weights.push(w);
                }
            }
        }
        (signals, weights)
    }

    pub fn load(path: &Path) -> Result<Study, OptimizeError> {
        let text = tb_files::input::read_to_string(path, tb_files::Limit::CONFIG).map_err(|e| {
            OptimizeError::File {
                path: path.to_path_buf(),
                message: tb_files::input::reason(&e, path),
            }
        })?;
        Self::parse(&text, path)
    }

    pub fn parse(text: &str, path: &Path) -> Result<Study, OptimizeError> {
        let file: StudyFile = toml::from_str(text).map_err(|e| OptimizeError::File {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        // Names in the study are relative to its folder, whatever the working directory.
        let dir = tb_files::folder_of(path);
        let system = tb_files::resolve(&dir, &file.system);
        let stem = |p: &Path| {
            p.file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "lap".into())
        };
        let mut laps: Vec<Lap> = match &file.measurement {
            Measurements::One(m) => vec![Lap {
                name: stem(m.file()),
                system_path: system.clone(),
                measurement_path: tb_files::resolve(&dir, m.file()),
                channels: m.channels(),
                parameters: Default::default(),
                weight: 1.0,
                hold_out: false,
            }],
            Measurements::Laps(laps) => laps
                .iter()
                .map(|l| Lap {
                    name: l.name.clone().unwrap_or_else(|| stem(&l.file)),
                    system_path: l
                        .system
                        .as_ref()
                        .map_or(system.clone(), |s| tb_files::resolve(&dir, s)),
                    measurement_path: tb_files::resolve(&dir, &l.file),
                    channels: l.channels.clone(),
                    parameters: l.parameters.clone(),
                    weight: l.weight,
                    hold_out: l.hold_out,
                })
                .collect(),
        };
        laps.sort_by_key(|l| l.hold_out);
        let first = laps
            .iter()
            .find(|l| !l.hold_out)
            .unwrap_or(&laps[0])
            .clone();
        use sha2::Digest;
        let fingerprint = format!("{:x}", sha2::Sha256::digest(text.as_bytes()));
        let study = Study {
            file,
            path: tb_files::normalize(path),
            system_path: first.system_path,
            measurement_path: first.measurement_path,
            channels: first.channels,
            laps,
            fingerprint,
        };
        study.validate()?;
        Ok(study)
    }

    pub fn name(&self) -> String {
        self.file.name.clone().unwrap_or_else(|| {
            self.path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "study".into())
        })
    }

    fn validate(&self) -> Result<(), OptimizeError> {
        let f = &self.file;
        if f.steps.is_empty() {
            return Err(self.bad("no [[step]]".into()));
        }
        if let Measurements::Laps(laps) = &f.measurement {
            self.validate_laps(laps)?;
        }
        self.validate_settings()?;
        self.validate_sizes()?;
        let p = &f.plausibility;
        if ![p.lap_length, p.lap_time, p.r_squared_v]
            .iter()
            .all(|x| x.is_finite() && *x >= 0.0)
        {
            return Err(self.bad("[plausibility]: bounds must be finite numbers ≥ 0".into()));
        }
        for s in &f.steps {
            self.validate_step(s)?;
        }
        Ok(())
    }

    /// An error in the study file, with its path.
    fn bad(&self, m: String) -> OptimizeError {
        OptimizeError::File {
            path: self.path.clone(),
            message: m,
        }
    }

    /// The `[[measurement]]` laps: at least one fitted (several only with the joint fit),
    /// each with a finite weight > 0, none setting a fitted parameter, each name once.
    fn validate_laps(&self, laps: &[LapConfig]) -> Result<(), OptimizeError> {
        let bad = |m: String| self.bad(m);
        let f = &self.file;
        if laps.iter().all(|l| l.hold_out) {
            return Err(bad(
                "every [[measurement]] is held out: at least one lap must be fitted".into(),
            ));
        }
        if laps.iter().filter(|l| !l.hold_out).count() > 1 && !f.refine {
            return Err(bad(
                "several fitted laps need refine = true: their intervals come from the joint fit over all laps".into(),
            ));
        }
        let fitted: Vec<String> = f.steps.iter().flat_map(|s| s.parameter_names()).collect();
        let mut names = Vec::new();
        for (k, l) in laps.iter().enumerate() {
            let name = l.name.clone().unwrap_or_else(|| {
                l.file
                    .file_stem()
                    .map_or("lap".into(), |s| s.to_string_lossy().into_owned())
            });
            if !(l.weight.is_finite() && l.weight > 0.0) {
                return Err(bad(format!(
                    "[[measurement]] {} ({name}): weight = {}: a lap's weight must be a finite number > 0 (hold it out with hold_out = true)",
                    k + 1,
                    l.weight
                )));
            }
            if let Some(p) = l.parameters.keys().find(|p| fitted.contains(p)) {
                return Err(bad(format!(
                    "[[measurement]] {} ({name}): '{p}' is a parameter the study fits: a lap can set only values of its own (track, target, start values)",
                    k + 1
                )));
            }
            if names.contains(&name) {
                return Err(bad(format!(
                    "[[measurement]] {}: the name '{name}' is taken by another lap (give each a name = \"...\")",
                    k + 1
                )));
            }
            names.push(name);
        }
        Ok(())
    }

    /// The study's settings: profiles need the joint fit; the comparison's settings; at
    /// least one generation; a finite penalty above any real cost; a finite bias weight
    /// ≥ 0 and null ratio > 0.
    fn validate_settings(&self) -> Result<(), OptimizeError> {
        let bad = |m: String| self.bad(m);
        let f = &self.file;
        if f.profiles && !f.refine {
            return Err(bad(
                "profiles = true needs refine = true: a profile is measured from the joint least-squares point the refinement finds".into(),
            ));
        }
        f.compare
            .validate()
            .map_err(|e| bad(format!("[compare]: {e}")))?;
        if f.optimizer.generations == 0 {
            return Err(bad("optimizer.generations must be at least 1".into()));
        }
        if !(f.penalty.is_finite() && f.penalty > 0.0) {
            return Err(bad(format!(
                "penalty = {:?}: the cost a failed run gets must be a positive number, larger than any real cost (a cost near or below zero would make failures look best)",
                f.penalty
            )));
        }
        if !(f.penalty.is_finite()
            && f.bias_weight.is_finite()
            && f.bias_weight >= 0.0
            && f.null_ratio.is_finite()
            && f.null_ratio > 0.0)
        {
            return Err(bad(format!(
                "penalty must be finite, bias_weight a finite number ≥ 0, null_ratio a finite number > 0 (got {}, {}, {})",
                f.penalty, f.bias_weight, f.null_ratio
            )));
        }
        Ok(())
    }

    /// The optimiser's sizes: a CMA-ES population of at least 4, at most
    /// `MAX_POPULATION` candidates per generation and `MAX_GENERATIONS` generations.
    fn validate_sizes(&self) -> Result<(), OptimizeError> {
        let bad = |m: String| self.bad(m);
        let f = &self.file;
        // Sizes that would exhaust memory or never finish are refused up front.
        const MAX_POPULATION: usize = 10_000;
        const MAX_GENERATIONS: usize = 1_000_000;
        if f.optimizer.cmaes.population.is_some_and(|p| p < 4) {
            return Err(bad(format!(
                "optimizer.cmaes.population = {}: CMA-ES needs at least 4 candidates per generation",
                f.optimizer.cmaes.population.unwrap_or_default()
            )));
        }
        if f.optimizer.ga.population > MAX_POPULATION
            || f.optimizer
                .cmaes
                .population
                .is_some_and(|p| p > MAX_POPULATION)
        {
            return Err(bad(format!(
                "optimizer population: at most {MAX_POPULATION} candidates per generation"
            )));
        }
        let too_many = |g: usize| g > MAX_GENERATIONS;
        if too_many(f.optimizer.generations)
            || f.steps.iter().any(|s| s.generations.is_some_and(too_many))
        {
            return Err(bad(format!("generations: at most {MAX_GENERATIONS}")));
        }
        Ok(())
    }

    /// One step: parameters and signals, one non-negative weight per signal with a finite
    /// sum above zero, a finite bias weight ≥ 0, at least one generation, its parameters
    /// (each once).
    fn validate_step(&self, s: &StepConfig) -> Result<(), OptimizeError> {
        let bad = |m: String| self.bad(m);
        let ctx = format!("step '{}'", s.name);
        if s.parameters.is_empty() || s.signals.is_empty() {
            return Err(bad(format!("{ctx}: needs parameters and signals")));
        }
        if s.weights().len() != s.signals.len()
            || s.weights().iter().any(|w| !w.is_finite() || *w < 0.0)
        {
            return Err(bad(format!(
                "{ctx}: weights must be one non-negative number per signal"
            )));
        }
        // The cost divides by the sum: zero, or a sum that overflows (two weights of
        // 1e308), would make every candidate's cost 0 or NaN.
        let sum = s.weights().iter().sum::<f64>();
        if sum <= 0.0 {
            return Err(bad(format!("{ctx}: the weights sum to zero")));
        }
        if !sum.is_finite() {
            return Err(bad(format!(
                "{ctx}: the weights sum to {sum} (they overflow a double): scale them down, only their ratios matter"
            )));
        }
        if let Some(b) = s.bias_weight {
            if !(b.is_finite() && b >= 0.0) {
                return Err(bad(format!(
                    "{ctx}: bias_weight must be a finite number ≥ 0, got {b}"
                )));
            }
        }
        if s.generations == Some(0) {
            return Err(bad(format!("{ctx}: generations must be at least 1")));
        }
        for p in &s.parameters {
            self.validate_parameter(&ctx, p)?;
        }
        let mut names = s.parameter_names();
        names.sort();
        names.dedup();
        if names.len() != s.parameters.len() {
            return Err(bad(format!("{ctx}: a parameter appears twice")));
        }
        Ok(())
    }

    /// One of a step's parameters (`ctx` names the step): instance.variable, bounds that
    /// are an interval, a start within them.
    fn validate_parameter(&self, ctx: &str, p: &ParameterConfig) -> Result<(), OptimizeError> {
        let bad = |m: String| self.bad(m);
        if tb_cosim::split_name(&p.name).is_none() {
            return Err(bad(format!(
                "{ctx}: parameter '{}' is not instance.variable",
                p.name
            )));
        }
        if !(p.min.is_finite() && p.max.is_finite() && p.min < p.max) {
            return Err(bad(format!(
                "{ctx}: parameter '{}': bounds [{}, {}] are not an interval",
                p.name, p.min, p.max
            )));
        }
        if let Some(x) = p.start {
            if !(p.min..=p.max).contains(&x) {
                return Err(bad(format!(
                    "{ctx}: parameter '{}': start {x} outside [{}, {}]",
                    p.name, p.min, p.max
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_study_file_that_cannot_be_read_is_named_once() {
        let path = std::env::temp_dir().join("tb-optimize-no-such-study.toml");
        let e = Study::load(&path).unwrap_err();
        assert!(
            matches!(&e, OptimizeError::File { path: p, .. } if *p == path),
            "{e}"
        );
        let text = e.to_string();
        assert!(text.contains(": cannot read: "), "{text}");
        assert_eq!(
            text.matches("tb-optimize-no-such-study.toml").count(),
            1,
            "{text}"
        );
    }
}
