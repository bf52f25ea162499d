//! The compiled plan: a system file checked once against its FMUs and resolved into what the
//! master needs. Names become slots (instances, value references, exchange buffers), values
//! become typed parameter values, the stop condition a slot and a threshold. Every
//! [`crate::Simulation`] (one per optimiser worker) is built from a shared `Arc<Plan>`
//! without looking at a name again.
//!
//! [`Plan::compile`] checks everything before the first step: names (with suggestions),
//! causality, types, units (converted when compatible, refused when not), parameter types
//! and declared ranges, unconnected inputs, direct-feed-through cycles, the stop condition.

//!
//! The compile runs in stages, each a function of its own input and output, in this order:
//! [`experiment`] (the time axis), [`instances`] (FMUs, backends, replays; and
//! [`instances::Units`], where every name is resolved), [`connections`], [`values`]
//! (parameters), [`readers`] (record, report, checks, replay bases), [`stop`], [`graph`]
//! (feed-through cycles, stepping order).

mod connections;
mod experiment;
mod graph;
mod instances;
mod problems;
mod readers;
mod stop;
pub(crate) mod units;
mod values;

pub use problems::{ConversionError, OrderError};
pub use readers::{Cadence, Reader};
pub use stop::{Condition, Op, Stop};
pub use values::{ParamSlot, ParamValue};

use crate::backend::BackendFactory;
use crate::config::SystemFile;
use crate::isolated::IsolationOptions;
use crate::native::NativeModel;
use crate::replay::ReplaySource;
use crate::{invalid, SystemError};
use instances::Units;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_fmi::import::description::{ModelDescription, ScalarVariable};
use tb_fmi::{FmuCache, LoadedFmu, ScalarType, VarKey};

/// One FMU instance of the system, resolved.
pub struct InstanceDef {
    pub name: String,
    pub fmu: Arc<LoadedFmu>,
    /// Name in the system file -> the FMU's variable name.
    pub ports: BTreeMap<String, String>,
    pub logging: bool,
    /// The FMI interface it runs through (Model Exchange: integrated by twinbench).
    pub interface: tb_fmi::Interface,
    /// The relative tolerance it is given (`toleranceDefined` when Some): the instance's,
    /// else the experiment's, else the FMU's DefaultExperiment tolerance.
    pub tolerance: Option<f64>,
    /// Creates the running unit (in-process FMU by default).
    pub factory: Arc<dyn BackendFactory>,
}

/// How instances are run, chosen when a system is loaded.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Run linked models natively (no FMI boundary); other FMUs stay FMUs (with a warning).
    pub native: bool,
    /// The models linked into the host that `native` may use (the host's model registry).
    pub native_models: Vec<NativeModel>,
    /// Run every FMU instance in a worker process (as `isolate = true` does for one).
    pub isolate: bool,
    /// Watchdog and worker executable of isolated instances.
    pub isolation: IsolationOptions,
    /// The FMI call trace (`--trace-fmi`): `None` wraps nothing, so it costs nothing.
    pub trace: Option<crate::trace::TraceOptions>,
    /// Every FMU's relative tolerance (`run --tolerance`), over the system file's.
    pub tolerance: Option<f64>,
    /// The step size convention (`run --step-convention`), over the system file's.
    pub step_convention: Option<crate::config::StepConvention>,
}

impl InstanceDef {
    pub fn description(&self) -> &ModelDescription {
        &self.fmu.description
    }

    /// Resolve a variable by the name the system file uses (through the port map).
    pub fn variable(&self, name: &str, context: &str) -> Result<&ScalarVariable, SystemError> {
        let fmu_name = self.ports.get(name).map(String::as_str).unwrap_or(name);
        self.description().variable(fmu_name).ok_or_else(|| {
            let elements = self.elements(name);
            if let (Some(first), Some(last)) = (elements.first(), elements.last()) {
                return invalid(
                    context,
                    format!(
                        "'{}.{name}' is an array of {} elements (FMU {}): name one ('{}.{first}' … '{}.{last}'); [record] takes the whole array by its name, and a connection between two arrays of one size connects them element by element",
                        self.name,
                        elements.len(),
                        self.fmu.source.display(),
                        self.name,
                        self.name,
                    ),
                );
            }
            let mut close = self.description().closest_names(fmu_name, 3);
            close.retain(|c| !c.is_empty());
            invalid(
                context,
                format!(
                    "unknown variable '{}.{fmu_name}' (FMU {}); closest names: {}",
                    self.name,
                    self.fmu.source.display(),
                    close.join(", ")
                ),
            )
        })
    }

    /// FMI 3.0: the names of the elements of the array `name` (`name[1]`, `name[2,1]`, …,
    /// row-major, as the description lists them); empty when `name` is a variable or no
    /// array's name. (An array is taken by the FMU's name: the port map renames scalars.)
    pub fn elements(&self, name: &str) -> Vec<String> {
        if self.description().variable(name).is_some() || self.ports.contains_key(name) {
            return Vec::new();
        }
        self.description()
            .variables
            .iter()
            .filter(|v| {
                v.name
                    .strip_prefix(name)
                    .is_some_and(|rest| rest.starts_with('[') && rest.ends_with(']'))
            })
            .map(|v| v.name.clone())
            .collect()
    }
}

/// A signal source: an FMU variable or a replayed column.
#[derive(Clone, Debug, PartialEq)]
pub enum Endpoint {
    Fmu {
        unit: usize,
        vr: u32,
        ty: ScalarType,
        unit_name: Option<String>,
    },
    Replay {
        unit: usize,
        column: usize,
        unit_name: String,
    },
}

/// A checked connection with its unit conversion `to = scale·from + offset`.
#[derive(Clone, Debug)]
pub struct ConnectionDef {
    pub text: String,
    pub from: Endpoint,
    /// The exchange slot of the source.
    pub from_slot: usize,
    pub from_name: String,
    pub to_unit: usize,
    pub to_vr: u32,
    pub to_ty: ScalarType,
    pub to_name: String,
    pub scale: f64,
    pub offset: f64,
}

impl ConnectionDef {
    /// The input's [`VarKey`]: (value space, value reference).
    pub fn to_key(&self) -> VarKey {
        (self.to_ty.value_space(), self.to_vr)
    }
}

/// The most macro steps a run may have (10¹²: days of a 1 µs step; more is a mistake).
pub const MAX_STEPS: f64 = 1e12;

/// Signals that must agree after initialisation, within a relative tolerance.
#[derive(Clone, Debug)]
pub struct Check {
    pub signals: Vec<(String, Endpoint)>,
    pub tolerance: f64,
    /// What a failure means.
    pub why: Option<String>,
}

/// One exchange slot: a value the master reads from a unit and others use.
#[derive(Clone, Debug, PartialEq)]
pub struct Signal {
    /// `instance.variable` as the system file wrote it first.
    pub name: String,
    /// Its unit ("" when the FMU declares none).
    pub unit: String,
    pub source: Endpoint,
}

/// The exchange slots, one per distinct source.
#[derive(Clone, Debug, Default)]
pub struct SignalTable {
    pub signals: Vec<Signal>,
    /// (replay?, unit, value space, value reference or column).
    index: HashMap<(bool, usize, Option<ScalarType>, u64), usize>,
}

impl Signal {
    /// A String signal (exchanged as text, recorded as a text column).
    pub fn is_text(&self) -> bool {
        matches!(
            self.source,
            Endpoint::Fmu {
                ty: ScalarType::String,
                ..
            }
        )
    }
}

impl SignalTable {
    /// The slot of a source (a new one the first time).
    pub fn slot(&mut self, e: &Endpoint, name: &str) -> usize {
        let key = match e {
            Endpoint::Fmu { unit, vr, ty, .. } => {
                (false, *unit, Some(ty.value_space()), *vr as u64)
            }
            Endpoint::Replay { unit, column, .. } => (true, *unit, None, *column as u64),
        };
        if let Some(&k) = self.index.get(&key) {
            return k;
        }
        let unit = match e {
            Endpoint::Fmu { unit_name, .. } => unit_name.clone().unwrap_or_default(),
            Endpoint::Replay { unit_name, .. } => unit_name.clone(),
        };
        self.signals.push(Signal {
            name: name.to_string(),
            unit,
            source: e.clone(),
        });
        self.index.insert(key, self.signals.len() - 1);
        self.signals.len() - 1
    }

    pub fn len(&self) -> usize {
        self.signals.len()
    }

    pub fn is_empty(&self) -> bool {
        self.signals.is_empty()
    }
}

/// The loaded, checked and resolved system.
pub struct Plan {
    pub file: SystemFile,
    pub path: PathBuf,
    /// FMU instances first (indices 0..n), then replays (n..).
    pub instances: Vec<InstanceDef>,
    pub replays: Vec<ReplaySource>,
    pub connections: Vec<ConnectionDef>,
    /// The exchange slots.
    pub signals: SignalTable,
    /// Slots recorded every `decimation` steps, in column order.
    pub record: Vec<usize>,
    /// The recorded columns' names, as listed (an FMI 3.0 alias shares its original's
    /// slot but keeps its own column name).
    pub record_names: Vec<String>,
    /// Parameters of the system file, typed, applied before every run.
    pub parameters: Vec<(ParamSlot, ParamValue)>,
    pub stop: Stop,
    /// Signals read at the end of a run for its summary.
    pub report: Vec<(String, Endpoint)>,
    /// Signals that must agree after initialisation.
    pub checks: Vec<Check>,
    /// Per replay: the slot of the signal giving its basis (distance mode).
    pub replay_basis: Vec<Option<usize>>,
    /// What reads the slots while a run goes on, and when (the master fetches a Real
    /// output every step only for an [`Cadence::EveryStep`] reader).
    pub readers: Vec<Reader>,
    /// Stepping order over units (FMU instances and replays).
    pub order: Vec<usize>,
    pub warnings: Vec<String>,
    /// What a reader of the run's log should know (unit conventions bridged, overrides).
    pub notes: Vec<String>,
    /// Keeps the unpacked FMUs alive (and removes them at the end).
    pub cache: Arc<FmuCache>,
}

impl Plan {
    /// Load a system file (TOML, or an SSP package) and compile it.
    pub fn load(path: &Path, cache: Arc<FmuCache>) -> Result<Plan, SystemError> {
        Self::load_with(path, cache, &LoadOptions::default())
    }

    /// [`Plan::load`] with a choice of backends. `path` is a TOML system file or an SSP 1.0
    /// package (`.ssp`, unpacked into `cache`'s folder: see [`crate::ssp_import`]).
    pub fn load_with(
        path: &Path,
        cache: Arc<FmuCache>,
        options: &LoadOptions,
    ) -> Result<Plan, SystemError> {
        let file = Self::read_system(path, &cache)?;
        Self::compile(file, path, cache, options)
    }

    /// A system file (TOML) or SSP package read, not yet compiled (to change it first).
    pub fn read_system(path: &Path, cache: &FmuCache) -> Result<SystemFile, SystemError> {
        if crate::ssp_import::is_ssp(path) {
            Ok(crate::ssp_import::load(path, cache)?)
        } else {
            SystemFile::load(path)
        }
    }

    /// [`Plan::compile`] with the default backends.
    pub fn from_file(
        file: SystemFile,
        path: &Path,
        cache: Arc<FmuCache>,
    ) -> Result<Plan, SystemError> {
        Self::compile(file, path, cache, &LoadOptions::default())
    }

    /// Check a parsed system file against its FMUs and resolve it, stage by stage (see the
    /// module's documentation). `path` is the file it came from (messages name it).
    pub fn compile(
        file: SystemFile,
        path: &Path,
        cache: Arc<FmuCache>,
        options: &LoadOptions,
    ) -> Result<Plan, SystemError> {
        // Named as the user named it, without `a/..` steps.
        let path = tb_files::normalize(path);
        let mut file = file;
        if let Some(t) = options.tolerance {
            file.experiment.tolerance = Some(t);
            file.instances.iter_mut().for_each(|i| i.tolerance = None);
        }
        if let Some(c) = options.step_convention {
            file.experiment.step_convention = c;
        }
        let ctx = path.display().to_string();
        experiment::check(&file, &ctx)?;
        let loaded = instances::load_fmus(&file, &ctx, &cache)?;
        // This plan's isolated instances share one list of the files they may read.
        let mut options = options.clone();
        options.isolation.readable = Arc::default();
        let options = &options;
        let (instances, native_fallback) = instances::instances(&file, &loaded, &ctx, options)?;
        instances::preload(&file, &instances)?;
        let mut replays = instances::replays(&file, &instances, &ctx)?;
        let units = Units {
            instances: &instances,
            replays: &replays,
        };
        // The exchange slots, connection sources first.
        let mut signals = SignalTable::default();
        let (connections, notes) = connections::connections(&file, units, &mut signals, &ctx)?;
        let to_hold = connections::replayed_columns(&connections, units, &ctx)?;
        let parameters = values::parameters(&file, &instances, &path, &ctx)?;
        *options
            .isolation
            .readable
            .write()
            .unwrap_or_else(|e| e.into_inner()) = path_parameters(&parameters);
        let (record, record_names) = readers::record(&file, units, &mut signals, &ctx)?;
        let stop = stop::stop(&file.experiment, units, &mut signals, &ctx)?;
        let report = readers::report(&file, units, &ctx)?;
        let checks = readers::checks(&file, units, &ctx)?;
        let replay_basis = readers::replay_basis(units, &mut signals, &ctx)?;
        let mut warnings = native_fallback;
        warnings.extend(structure_gaps(&loaded));
        warnings.extend(connections::unconnected_inputs(&file, units, &connections));
        graph::check_feedthrough_cycles(&instances, &connections, &mut warnings).map_err(
            |error| SystemError::Order {
                context: ctx.clone(),
                error,
            },
        )?;
        let order = graph::stepping_order(&file, units, &connections).map_err(|error| {
            SystemError::Order {
                context: ctx.clone(),
                error,
            }
        })?;
        for w in &warnings {
            log::warn!("{ctx}: {w}");
        }
        for n in &notes {
            log::info!("{ctx}: {n}");
        }
        for (r, column) in to_hold {
            replays[r].hold[column] = true;
        }
        let readers = readers::readers(&connections, &stop, &replay_basis, &record);
        Ok(Plan {
            file,
            path,
            instances,
            replays,
            connections,
            signals,
            record,
            record_names,
            parameters,
            stop,
            report,
            checks,
            replay_basis,
            readers,
            order,
            warnings,
            notes,
            cache,
        })
    }

    /// The slots some reader needs after every step (indexed by slot): the Real outputs
    /// the master fetches every step; the other Real outputs only at recorded steps.
    pub fn read_every_step(&self) -> Vec<bool> {
        let mut every_step = vec![false; self.signals.len()];
        for r in self
            .readers
            .iter()
            .filter(|r| r.cadence == Cadence::EveryStep)
        {
            for &s in &r.slots {
                every_step[s] = true;
            }
        }
        every_step
    }

    pub fn unit_name(&self, k: usize) -> &str {
        if k < self.instances.len() {
            &self.instances[k].name
        } else {
            &self.replays[k - self.instances.len()].name
        }
    }

    /// Every file a run of this system reads: the system file, the FMUs, the replayed
    /// measurements, the preloaded libraries and the files named by `*_file` parameters.
    /// (A result must replace none of them; a remote worker checks it has the same ones.)
    pub fn input_files(&self) -> Vec<PathBuf> {
        let mut files = vec![self.path.clone()];
        files.extend(self.file.fmus.values().cloned());
        files.extend(self.file.replay.iter().map(|r| r.file.clone()));
        files.extend(self.file.preload.iter().cloned());
        files.extend(path_parameters(&self.parameters));
        files
    }

    /// Resolve a parameter or input by its system name (`instance.variable`, through the
    /// port map), for setting it between runs.
    pub fn parameter(&self, name: &str) -> Result<ParamSlot, SystemError> {
        instances::parameter_slot(&self.instances, name, &format!("parameter \"{name}\""))
    }

    /// The connection that drives this input every step, if it is a connected input (a value
    /// set for it would be overwritten at once).
    pub fn driving_connection(&self, slot: &ParamSlot) -> Option<&ConnectionDef> {
        self.connections
            .iter()
            .find(|c| c.to_unit == slot.unit && c.to_key() == slot.key())
    }

    /// A signal the system can read (`instance.variable` or `replay.column`).
    pub fn endpoint(&self, name: &str) -> Result<Endpoint, SystemError> {
        let units = Units {
            instances: &self.instances,
            replays: &self.replays,
        };
        units.endpoint(&self.path.display().to_string(), name)
    }

    /// The exchange slot of a signal by name (`instance.variable` or a replay's column), for
    /// an observer of a run: a recorded name, else a signal the plan exchanges. An output
    /// that is neither recorded nor connected has no slot (the master does not read it): to
    /// watch it, record it (`[record] signals`).
    pub fn slot_of(&self, name: &str) -> Option<usize> {
        let recorded = self.record_names.iter().position(|n| n == name);
        recorded
            .map(|k| self.record[k])
            .or_else(|| self.signals.signals.iter().position(|s| s.name == name))
    }

    /// Names and units of the recorded columns (time first).
    pub fn record_columns(&self) -> (Vec<String>, Vec<String>) {
        let mut names = vec!["time".to_string()];
        let mut units = vec!["s".to_string()];
        for (k, &s) in self.record.iter().enumerate() {
            names.push(self.record_names[k].clone());
            units.push(self.signals.signals[s].unit.clone());
        }
        (names, units)
    }
}

/// A warning for every FMU whose ModelStructure leaves outputs' dependencies out.
fn structure_gaps(loaded: &HashMap<String, Arc<LoadedFmu>>) -> Vec<String> {
    let mut keys: Vec<&String> = loaded.keys().collect();
    keys.sort();
    let mut warnings = Vec::new();
    for key in keys {
        let fmu = &loaded[key];
        for gap in fmu.description.model_structure_gaps() {
            warnings.push(format!(
                "FMU '{key}' ({}): {gap}; twinbench assumes they depend on every input, other importers may refuse the FMU",
                fmu.source.display()
            ));
        }
    }
    warnings
}

/// The files named by `*_file` parameters.
fn path_parameters(parameters: &[(ParamSlot, ParamValue)]) -> Vec<PathBuf> {
    parameters
        .iter()
        .filter_map(|(slot, value)| match value {
            ParamValue::String(v) if slot.is_path && !v.is_empty() && !v.starts_with("file:") => {
                Some(PathBuf::from(v))
            }
            _ => None,
        })
        .collect()
}
