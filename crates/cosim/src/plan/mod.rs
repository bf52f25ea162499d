//! The compiled plan: a system file checked once against its FMUs and resolved into what the
//! master needs. Names become slots (instances, value references, exchange buffers), values
//! become typed parameter values, the stop condition a slot and a threshold. Every
//! [`crate::Simulation`] (one per optimiser worker) is built from a shared `Arc<Plan>`
//! without looking at a name again.
//!
//! [`Plan::compile`] checks everything before the first step: names (with suggestions),
//! causality, types, units (converted when compatible, refused when not), parameter types
//! and declared ranges, unconnected inputs, direct-feed-through cycles, the stop condition.

mod graph;
pub(crate) mod units;
mod values;

pub use values::{Condition, Op, ParamSlot, ParamValue, Stop};

use crate::backend::{BackendFactory, FmuFactory};
use crate::config::{StopConfig, SystemFile};
use crate::isolated::{IsolatedFactory, IsolationOptions};
use crate::native::{NativeFactory, NativeModel};
use crate::replay::ReplaySource;
use crate::{invalid, split_name, SystemError};
use graph::{check_feedthrough_cycles, stepping_order};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_fmi::description::{ModelDescription, ScalarVariable};
use tb_fmi::{Causality, FmuCache, LoadedFmu, ScalarType, Variability};
use units::{unit_conversion, Conversion};

/// One FMU instance of the system, resolved.
pub struct InstanceDef {
    pub name: String,
    pub fmu: Arc<LoadedFmu>,
    /// Name in the system file -> the FMU's variable name.
    pub ports: BTreeMap<String, String>,
    pub logging: bool,
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
}

impl InstanceDef {
    pub fn description(&self) -> &ModelDescription {
        &self.fmu.description
    }

    /// Resolve a variable by the name the system file uses (through the port map).
    pub fn variable(&self, name: &str, context: &str) -> Result<&ScalarVariable, SystemError> {
        let fmu_name = self.ports.get(name).map(String::as_str).unwrap_or(name);
        self.description().variable(fmu_name).ok_or_else(|| {
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
    index: HashMap<(bool, usize, u64), usize>,
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
            Endpoint::Fmu { unit, vr, .. } => (false, *unit, *vr as u64),
            Endpoint::Replay { unit, column, .. } => (true, *unit, *column as u64),
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

    /// Check a parsed system file against its FMUs and resolve it. `path` is the file it
    /// came from (messages name it).
    pub fn compile(
        file: SystemFile,
        path: &Path,
        cache: Arc<FmuCache>,
        options: &LoadOptions,
    ) -> Result<Plan, SystemError> {
        // Named as the user named it, without `a/..` steps.
        let path = &tb_files::normalize(path);
        let ctx_file = path.display().to_string();
        if !(file.experiment.step > 0.0 && file.experiment.step.is_finite()) {
            return Err(invalid(
                &ctx_file,
                format!(
                    "experiment.step must be positive, got {}",
                    file.experiment.step
                ),
            ));
        }
        if !file.experiment.start.is_finite() {
            return Err(invalid(
                &ctx_file,
                format!(
                    "experiment.start must be a finite time, got {}",
                    file.experiment.start
                ),
            ));
        }
        // The step count of the run (the stop time, or max_time with a condition) must be
        // a number the master can count: a step count beyond it would wrap and run nothing.
        let span = match &file.experiment.stop {
            StopConfig::Time(t) => t - file.experiment.start,
            StopConfig::Word(_) => file.experiment.max_time,
        };
        let steps = span / file.experiment.step;
        if steps.is_finite() && steps > MAX_STEPS {
            return Err(invalid(
                &ctx_file,
                format!(
                    "experiment.step = {} s over {span} s is {steps:.3e} macro steps, more than {MAX_STEPS:.0e}: a larger step",
                    file.experiment.step
                ),
            ));
        }
        match &file.experiment.stop {
            StopConfig::Time(t) if !t.is_finite() => {
                return Err(invalid(
                    &ctx_file,
                    format!("experiment.stop must be a finite time, got {t}"),
                ))
            }
            StopConfig::Time(t) if *t <= file.experiment.start || t.is_nan() => {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "experiment.stop {t} is not after start {}",
                        file.experiment.start
                    ),
                ))
            }
            _ => {}
        }
        if file.record.decimation == 0 {
            return Err(invalid(&ctx_file, "record.decimation must be at least 1"));
        }
        // FMUs and instances.
        let mut loaded: HashMap<&str, Arc<LoadedFmu>> = HashMap::new();
        for (key, p) in &file.fmus {
            if std::fs::symlink_metadata(p).is_err() {
                return Err(missing_fmu(&ctx_file, key, p));
            }
            loaded.insert(key, cache.load(p)?);
        }
        let mut instances = Vec::new();
        let mut native_fallback = Vec::new();
        for inst in &file.instances {
            let fmu = loaded.get(inst.fmu.as_str()).ok_or_else(|| {
                invalid(
                    format!("{ctx_file}: instance '{}'", inst.name),
                    format!(
                        "fmu '{}' is not in [fmus] (known: {})",
                        inst.fmu,
                        file.fmus.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
            if instances.iter().any(|i: &InstanceDef| i.name == inst.name)
                || inst.name.contains('.')
                || !valid_unit_name(&inst.name)
            {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "instance name '{}' is repeated, empty, or contains a '.', a quote, a separator or a control character",
                        inst.name
                    ),
                ));
            }
            if fmu
                .description
                .co_simulation
                .as_ref()
                .is_some_and(|c| c.can_be_instantiated_only_once_per_process)
                && file.instances.iter().filter(|i| i.fmu == inst.fmu).count() > 1
            {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "FMU '{}' can be instantiated only once per process",
                        inst.fmu
                    ),
                ));
            }
            let factory: Arc<dyn BackendFactory> = match options.native {
                true => match NativeFactory::for_fmu(fmu, &options.native_models) {
                    Ok(f) => Arc::new(f),
                    Err(why) => {
                        native_fallback
                            .push(format!("instance '{}' runs as an FMU: {why}", inst.name));
                        Arc::new(FmuFactory(fmu.clone()))
                    }
                },
                false => Arc::new(FmuFactory(fmu.clone())),
            };
            // Isolation (of this instance, or of all) wins over the in-process choices.
            let factory: Arc<dyn BackendFactory> = if inst.isolate || options.isolate {
                let mut iso = options.isolation.clone();
                iso.preload.extend(file.preload.iter().cloned());
                if let Some(w) = inst.watchdog {
                    iso.timeout = crate::isolated::watchdog(w)
                        .map_err(|m| invalid(format!("{ctx_file}: instance '{}'", inst.name), m))?;
                }
                Arc::new(IsolatedFactory {
                    fmu: fmu.clone(),
                    options: iso,
                })
            } else {
                factory
            };
            let factory: Arc<dyn BackendFactory> = match &options.trace {
                Some(t) if t.instances.is_empty() || t.instances.contains(&inst.name) => {
                    Arc::new(crate::trace::TracedFactory {
                        inner: factory,
                        sink: t.sink.clone(),
                        fmu: fmu.clone(),
                    })
                }
                _ => factory,
            };
            let def = InstanceDef {
                name: inst.name.clone(),
                fmu: fmu.clone(),
                ports: inst.ports.clone(),
                logging: inst.logging,
                factory,
            };
            for theirs in inst.ports.values() {
                if def.description().variable(theirs).is_none() {
                    def.variable(theirs, &format!("{ctx_file}: port map of '{}'", inst.name))?;
                }
            }
            instances.push(def);
        }
        if let Some(t) = &options.trace {
            let names: Vec<&str> = instances.iter().map(|i| i.name.as_str()).collect();
            if let Some(unknown) = t.instances.iter().find(|n| !names.contains(&n.as_str())) {
                return Err(invalid(
                    "--trace-instances",
                    format!(
                        "no instance named '{unknown}' in {ctx_file} (instances: {})",
                        names.join(", ")
                    ),
                ));
            }
        }
        // The preloads serve in-process FMU libraries; isolated ones get them in their
        // worker, so a system of isolated instances loads nothing into this process.
        if instances.iter().any(|i| i.factory.kind() != "isolated") {
            for lib in &file.preload {
                tb_fmi::library::preload_global(lib)?;
            }
        }
        let n_fmu = instances.len();
        let mut replays = Vec::new();
        for r in &file.replay {
            if !valid_unit_name(&r.name) || r.name.contains('.') {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "replay name '{}' is empty, or contains a '.', a quote, a separator or a control character",
                        r.name
                    ),
                ));
            }
            if instances.iter().any(|i| i.name == r.name) {
                return Err(invalid(
                    &ctx_file,
                    format!("replay name '{}' is also an instance name", r.name),
                ));
            }
            replays.push(ReplaySource::load(r)?);
        }
        let unit_index = |name: &str| -> Option<usize> {
            instances.iter().position(|i| i.name == name).or_else(|| {
                replays
                    .iter()
                    .position(|r| r.name == name)
                    .map(|k| n_fmu + k)
            })
        };
        let unknown_unit =
            |ctx: &str, name: &str| unknown_instance(&instances, &replays, ctx, name);
        // A signal the system can read.
        let resolve_source =
            |ctx: &str, full: &str| resolve_endpoint(&instances, &replays, ctx, full);
        // The exchange slots, connection sources first.
        let mut signals = SignalTable::default();
        // Connections.
        let mut connections: Vec<ConnectionDef> = Vec::new();
        let mut notes = Vec::new();
        for conn in &file.connections {
            let text = &conn.text;
            let ctx = format!("{ctx_file}: connection \"{text}\"");
            let (a, b) = text
                .split_once("->")
                .ok_or_else(|| invalid(&ctx, "expected \"instance.output -> instance.input\""))?;
            let (a, b) = (a.trim(), b.trim());
            let from = resolve_source(&ctx, a)?;
            let (tu, tv) = split_name(b).ok_or_else(|| {
                invalid(&ctx, format!("'{b}' is not of the form instance.variable"))
            })?;
            let to_unit = unit_index(tu).ok_or_else(|| unknown_unit(&ctx, tu))?;
            if to_unit >= n_fmu {
                return Err(invalid(
                    &ctx,
                    format!("'{b}' is a replayed channel; it cannot be an input"),
                ));
            }
            let to_def = &instances[to_unit];
            let to_sv = to_def.variable(tv, &ctx)?;
            if to_sv.causality != Causality::Input {
                return Err(invalid(
                    &ctx,
                    format!(
                        "'{b}' is {} {}, not an input: it cannot be connected to",
                        to_sv.variability, to_sv.causality
                    ),
                ));
            }
            let (from_unit_name, from_md): (Option<String>, Option<&ModelDescription>) = match &from
            {
                Endpoint::Fmu {
                    unit,
                    vr,
                    unit_name,
                    ..
                } => {
                    let sv = instances[*unit]
                        .description()
                        .variables
                        .iter()
                        .find(|v| v.value_reference == *vr)
                        .unwrap();
                    if sv.causality != Causality::Output {
                        return Err(invalid(
                            &ctx,
                            format!(
                                "'{a}' is {} {}, not an output",
                                sv.variability, sv.causality
                            ),
                        ));
                    }
                    (unit_name.clone(), Some(instances[*unit].description()))
                }
                Endpoint::Replay { unit_name, .. } => (Some(unit_name.clone()), None),
            };
            let from_ty = match &from {
                Endpoint::Fmu { ty, .. } => *ty,
                Endpoint::Replay { .. } => ScalarType::Real,
            };
            // A replayed column drives any numeric input (held for the discrete ones; its
            // values are checked against the input's type below).
            let replayed =
                matches!(from, Endpoint::Replay { .. }) && to_sv.ty != ScalarType::String;
            let type_ok = replayed
                || from_ty == to_sv.ty
                || (to_sv.ty == ScalarType::Real
                    && matches!(
                        from_ty,
                        ScalarType::Integer | ScalarType::Boolean | ScalarType::Enumeration
                    ))
                || (matches!(to_sv.ty, ScalarType::Integer | ScalarType::Enumeration)
                    && matches!(from_ty, ScalarType::Integer | ScalarType::Enumeration));
            if !type_ok {
                return Err(invalid(
                    &ctx,
                    format!(
                        "type mismatch: '{a}' is {}, '{b}' is {}",
                        from_ty.name(),
                        to_sv.ty.name()
                    ),
                ));
            }
            let empty = ModelDescription::default();
            let from_md = from_md.unwrap_or(&empty);
            let to_md = to_def.description();
            let conversion = connection_conversion(
                conn,
                (from_md, from_unit_name.as_deref()),
                (to_md, to_md.unit_of(to_sv)),
                to_sv.ty,
            )
            .map_err(|m| invalid(&ctx, m))?;
            if let Some(note) = &conversion.note {
                notes.push(format!("connection \"{text}\": {note}"));
            }
            let (scale, offset) = (conversion.scale, conversion.offset);
            if connections
                .iter()
                .any(|c| c.to_unit == to_unit && c.to_vr == to_sv.value_reference)
            {
                return Err(invalid(&ctx, format!("'{b}' is already connected")));
            }
            connections.push(ConnectionDef {
                text: text.clone(),
                from_slot: signals.slot(&from, a),
                from,
                from_name: a.to_string(),
                to_unit,
                to_vr: to_sv.value_reference,
                to_ty: to_sv.ty,
                to_name: b.to_string(),
                scale,
                offset,
            });
        }
        // Replayed columns: held or interpolated, and their values fit the inputs they drive.
        let mut to_hold = Vec::new();
        for c in &connections {
            let Endpoint::Replay { unit, column, .. } = c.from else {
                continue;
            };
            let to = &instances[c.to_unit];
            let sv = to
                .description()
                .variables
                .iter()
                .find(|v| v.value_reference == c.to_vr && v.causality == Causality::Input)
                .expect("resolved above");
            let r = &replays[unit - n_fmu];
            let discrete = sv.ty != ScalarType::Real
                || matches!(sv.variability, Variability::Discrete | Variability::Tunable);
            if r.interpolation == crate::config::Interpolation::Auto && discrete {
                to_hold.push((unit - n_fmu, column));
            }
            let values = r.values(column);
            let ctx = format!("{ctx_file}: connection \"{}\"", c.text);
            let bad = |k: usize, why: String| {
                invalid(
                    &ctx,
                    format!(
                        "{}, row {}: value {} {why}",
                        r.path.display(),
                        k + 1,
                        values[k]
                    ),
                )
            };
            match sv.ty {
                ScalarType::Integer | ScalarType::Enumeration => {
                    if let Some(k) = values.iter().position(|x| {
                        x.fract() != 0.0 || *x < i32::MIN as f64 || *x > i32::MAX as f64
                    }) {
                        return Err(bad(
                            k,
                            format!(
                                "is not a 32-bit integer for {} '{}'",
                                sv.ty.name(),
                                c.to_name
                            ),
                        ));
                    }
                    if let Some(items) = to.description().enumeration_items(sv) {
                        if let Some(k) = values
                            .iter()
                            .position(|x| !items.iter().any(|(_, v)| *v as f64 == *x))
                        {
                            return Err(bad(
                                k,
                                format!("is not an item of the Enumeration '{}'", c.to_name),
                            ));
                        }
                    }
                }
                ScalarType::Boolean => {
                    if let Some(k) = values.iter().position(|x| *x != 0.0 && *x != 1.0) {
                        return Err(bad(
                            k,
                            format!("is not 0 or 1 for the Boolean '{}'", c.to_name),
                        ));
                    }
                }
                _ => {}
            }
        }
        // Parameters: typed and range-checked once, here.
        let mut parameters = Vec::new();
        for (name, value) in &file.parameters {
            let ctx = format!("{ctx_file}: parameter \"{name}\"");
            let slot = parameter_slot(&instances, name, &ctx)?;
            let value = slot.value_from_toml(value, &ctx)?;
            let value = slot.resolve_path(value, &tb_files::folder_of(path));
            parameters.push((slot, value));
        }
        // Recorded signals: as listed, or every output and replayed column.
        let record_names = match file.record.signals.is_empty() {
            false => file.record.signals.clone(),
            true => default_record(&instances, &replays),
        };
        let mut record = Vec::with_capacity(record_names.len());
        for (k, n) in record_names.iter().enumerate() {
            if record_names[..k].contains(n) || n == "time" {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "record: '{n}' is listed twice (a result file has one column per name)"
                    ),
                ));
            }
            let e = resolve_source(&format!("{ctx_file}: record"), n)?;
            record.push(signals.slot(&e, n));
        }
        // The stop condition.
        let stop = match &file.experiment.stop {
            StopConfig::Time(t) => Stop::Time(*t),
            StopConfig::Word(w) => {
                let (ctx, text) = if w == "lap" {
                    let signal = file.experiment.lap_signal.as_deref().ok_or_else(|| {
                        invalid(
                            &ctx_file,
                            "stop = \"lap\" needs lap_signal (or write the condition: stop = \"vehicle.lap >= 1\")",
                        )
                    })?;
                    (
                        "experiment.lap_signal",
                        format!("{signal} >= {}", file.experiment.lap_count),
                    )
                } else {
                    ("experiment.stop", w.clone())
                };
                let (signal, op, threshold) = Condition::parse(&text).ok_or_else(|| {
                    invalid(
                        &ctx_file,
                        format!(
                            "experiment.stop must be a time in s or a condition such as \"vehicle.lap >= 1\", got \"{w}\""
                        ),
                    )
                })?;
                let max_time = file.experiment.max_time;
                if !(max_time.is_finite() && max_time > 0.0) {
                    return Err(invalid(
                        &ctx_file,
                        format!("experiment.max_time must be a positive number of seconds, got {max_time}"),
                    ));
                }
                let e = resolve_source(&format!("{ctx_file}: {ctx}"), &signal)?;
                if let Endpoint::Fmu {
                    ty: ScalarType::String,
                    ..
                } = e
                {
                    return Err(invalid(
                        format!("{ctx_file}: {ctx}"),
                        format!("'{signal}' is a String; a stop condition compares a number"),
                    ));
                }
                Stop::When {
                    condition: Condition {
                        slot: signals.slot(&e, &signal),
                        signal,
                        op,
                        threshold,
                    },
                    max_time,
                }
            }
        };
        // Values reported at the end of a run.
        let mut report = Vec::new();
        for n in &file.experiment.report {
            let ctx = format!("{ctx_file}: experiment.report");
            let e = resolve_source(&ctx, n)?;
            match &e {
                Endpoint::Fmu {
                    ty: ScalarType::String,
                    ..
                } => return Err(invalid(&ctx, format!("'{n}' is a String, not a number"))),
                Endpoint::Replay { .. } => {
                    return Err(invalid(
                        &ctx,
                        format!("'{n}' is a replayed column; report FMU variables"),
                    ))
                }
                Endpoint::Fmu { .. } => {}
            }
            report.push((n.clone(), e));
        }
        // Consistency checks after initialisation.
        let mut checks = Vec::new();
        for (k, c) in file.checks.iter().enumerate() {
            let ctx = format!("{ctx_file}: check {}", k + 1);
            if c.equal.len() < 2 {
                return Err(invalid(&ctx, "`equal` needs two or more signals"));
            }
            if !(c.relative_tolerance.is_finite() && c.relative_tolerance >= 0.0) {
                return Err(invalid(
                    &ctx,
                    format!(
                        "relative_tolerance must be a non-negative number, got {}",
                        c.relative_tolerance
                    ),
                ));
            }
            let mut signals = Vec::new();
            for n in &c.equal {
                let e = resolve_source(&ctx, n)?;
                match &e {
                    Endpoint::Fmu {
                        ty: ScalarType::Real | ScalarType::Integer | ScalarType::Enumeration,
                        ..
                    } => {}
                    _ => {
                        return Err(invalid(
                            &ctx,
                            format!("'{n}' is not a numeric FMU variable"),
                        ))
                    }
                }
                signals.push((n.clone(), e));
            }
            checks.push(Check {
                signals,
                tolerance: c.relative_tolerance,
                why: c.why.clone(),
            });
        }
        // Replay bases.
        let mut replay_basis = Vec::with_capacity(replays.len());
        for r in &replays {
            replay_basis.push(match &r.by {
                Some(by) => {
                    let ctx = format!("{ctx_file}: replay '{}'", r.name);
                    let e = resolve_source(&ctx, by)?;
                    if let Endpoint::Replay { .. } = e {
                        return Err(invalid(&ctx, "a replay cannot be driven by another replay"));
                    }
                    if let Endpoint::Fmu {
                        ty: ScalarType::String,
                        ..
                    } = e
                    {
                        return Err(invalid(&ctx, format!("'{by}' is a String, not a distance")));
                    }
                    Some(signals.slot(&e, by))
                }
                None => None,
            });
        }
        let mut warnings = native_fallback;
        for key in file.fmus.keys() {
            let fmu = &loaded[key.as_str()];
            for gap in fmu.description.model_structure_gaps() {
                warnings.push(format!(
                    "FMU '{key}' ({}): {gap}; twinbench assumes they depend on every input, other importers may refuse the FMU",
                    fmu.source.display()
                ));
            }
        }
        // Unconnected inputs without a start value.
        for (k, inst) in instances.iter().enumerate() {
            for v in inst
                .description()
                .variables
                .iter()
                .filter(|v| v.causality == Causality::Input)
            {
                let connected = connections
                    .iter()
                    .any(|c| c.to_unit == k && c.to_vr == v.value_reference);
                let set = file
                    .parameters
                    .contains_key(&format!("{}.{}", inst.name, v.name))
                    || inst.ports.iter().any(|(ours, theirs)| {
                        theirs == &v.name
                            && file
                                .parameters
                                .contains_key(&format!("{}.{ours}", inst.name))
                    });
                if !connected && !set && v.start.is_none() {
                    warnings.push(format!(
                        "input '{}.{}' is not connected and has no start value",
                        inst.name, v.name
                    ));
                }
            }
        }
        check_feedthrough_cycles(&instances, &connections, &mut warnings)
            .map_err(|m| invalid(&ctx_file, m))?;
        let unit_names: Vec<String> = instances
            .iter()
            .map(|i| i.name.clone())
            .chain(replays.iter().map(|r| r.name.clone()))
            .collect();
        let order = stepping_order(
            &file,
            &unit_names,
            n_fmu,
            &connections,
            &replays,
            &instances,
        )
        .map_err(|m| invalid(&ctx_file, m))?;
        for w in &warnings {
            log::warn!("{ctx_file}: {w}");
        }
        for n in &notes {
            log::info!("{ctx_file}: {n}");
        }
        for (r, column) in to_hold {
            replays[r].hold[column] = true;
        }
        Ok(Plan {
            file,
            path: path.to_path_buf(),
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
            order,
            warnings,
            notes,
            cache,
        })
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
        for (slot, value) in &self.parameters {
            if let ParamValue::String(v) = value {
                if slot.is_path && !v.is_empty() && !v.starts_with("file:") {
                    files.push(PathBuf::from(v));
                }
            }
        }
        files
    }

    /// Resolve a parameter or input by its system name (`instance.variable`, through the
    /// port map), for setting it between runs.
    pub fn parameter(&self, name: &str) -> Result<ParamSlot, SystemError> {
        parameter_slot(&self.instances, name, &format!("parameter \"{name}\""))
    }

    /// The connection that drives this input every step, if it is a connected input (a value
    /// set for it would be overwritten at once).
    pub fn driving_connection(&self, slot: &ParamSlot) -> Option<&ConnectionDef> {
        self.connections
            .iter()
            .find(|c| c.to_unit == slot.unit && c.to_vr == slot.vr)
    }

    /// A signal the system can read (`instance.variable` or `replay.column`).
    pub fn endpoint(&self, name: &str) -> Result<Endpoint, SystemError> {
        resolve_endpoint(
            &self.instances,
            &self.replays,
            &self.path.display().to_string(),
            name,
        )
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

/// A name that can head a result column as it is: no quote, no separator, no control
/// character, not empty.
fn valid_unit_name(name: &str) -> bool {
    !name.is_empty()
        && !name
            .chars()
            .any(|c| c.is_control() || matches!(c, '"' | ',' | ';' | '\t'))
}

/// Every output of every instance (under the system's names) and every replayed column.
fn default_record(instances: &[InstanceDef], replays: &[ReplaySource]) -> Vec<String> {
    let mut names = Vec::new();
    for inst in instances {
        for v in inst
            .description()
            .variables
            .iter()
            .filter(|v| v.causality == Causality::Output)
        {
            let ours = inst
                .ports
                .iter()
                .find(|(_, t)| *t == &v.name)
                .map(|(o, _)| o.clone())
                .unwrap_or(v.name.clone());
            names.push(format!("{}.{ours}", inst.name));
        }
    }
    for r in replays {
        for c in &r.columns {
            names.push(format!("{}.{c}", r.name));
        }
    }
    names
}

/// "unknown instance" with every unit name, closest first.
fn unknown_instance(
    instances: &[InstanceDef],
    replays: &[ReplaySource],
    ctx: &str,
    name: &str,
) -> SystemError {
    let mut v: Vec<(usize, &str)> = instances
        .iter()
        .map(|i| i.name.as_str())
        .chain(replays.iter().map(|r| r.name.as_str()))
        .map(|n| (tb_fmi::description::edit_distance(name, n), n))
        .collect();
    v.sort();
    invalid(
        ctx,
        format!(
            "unknown instance '{name}'; instances: {}",
            v.iter().map(|x| x.1).collect::<Vec<_>>().join(", ")
        ),
    )
}

/// An FMU the system file names that is not there: the system file, the entry and, as
/// twinbench's own FMUs are written by `pack`, the command that writes them there.
fn missing_fmu(ctx_file: &str, key: &str, path: &Path) -> SystemError {
    let folder = path.parent().unwrap_or(Path::new("."));
    invalid(
        ctx_file,
        format!(
            "[fmus] {key}: {} does not exist (paths in a system file are relative to its folder); twinbench's own FMUs are written there by `twinbench pack -o {}`",
            path.display(),
            folder.display()
        ),
    )
}

/// A signal the system can read, `instance.variable`: an FMU variable (through the port
/// map) or a replayed column. Instances come first in the unit numbering, then replays.
pub(crate) fn resolve_endpoint(
    instances: &[InstanceDef],
    replays: &[ReplaySource],
    ctx: &str,
    full: &str,
) -> Result<Endpoint, SystemError> {
    let (u, var) = split_name(full).ok_or_else(|| {
        invalid(
            ctx,
            format!("'{full}' is not of the form instance.variable"),
        )
    })?;
    if let Some(k) = instances.iter().position(|i| i.name == u) {
        let sv = instances[k].variable(var, ctx)?;
        return Ok(Endpoint::Fmu {
            unit: k,
            vr: sv.value_reference,
            ty: sv.ty,
            unit_name: instances[k].description().unit_of(sv).map(str::to_string),
        });
    }
    let Some(k) = replays.iter().position(|r| r.name == u) else {
        return Err(unknown_instance(instances, replays, ctx, u));
    };
    let r = &replays[k];
    let c = r.column_index(var).ok_or_else(|| {
        invalid(
            ctx,
            format!(
                "replay '{}' has no column '{var}' (columns: {})",
                r.name,
                r.columns.join(", ")
            ),
        )
    })?;
    Ok(Endpoint::Replay {
        unit: instances.len() + k,
        column: c,
        unit_name: r.units[c].clone(),
    })
}

/// A settable variable (parameter or input) by its system name: the instance, the value
/// reference, the type and the declared range.
fn parameter_slot(
    instances: &[InstanceDef],
    name: &str,
    ctx: &str,
) -> Result<ParamSlot, SystemError> {
    let (u, var) =
        split_name(name).ok_or_else(|| invalid(ctx, "expected \"instance.variable\""))?;
    let k = instances.iter().position(|i| i.name == u).ok_or_else(|| {
        invalid(
            ctx,
            format!(
                "unknown instance '{u}'; instances: {}",
                instances
                    .iter()
                    .map(|i| i.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    let sv: &ScalarVariable = instances[k].variable(var, ctx)?;
    if !(sv.causality == Causality::Parameter || sv.causality == Causality::Input)
        || sv.variability == Variability::Constant
    {
        return Err(invalid(
            ctx,
            format!(
                "'{name}' is {} {}; only parameters and inputs can be set",
                sv.variability, sv.causality
            ),
        ));
    }
    Ok(ParamSlot {
        name: name.to_string(),
        unit: k,
        vr: sv.value_reference,
        ty: sv.ty,
        min: sv.min,
        max: sv.max,
        start: sv.start_f64(),
        is_path: sv.ty == ScalarType::String && sv.name.ends_with("_file"),
        items: instances[k]
            .description()
            .enumeration_items(sv)
            .map(<[_]>::to_vec),
    })
}

/// A connection's conversion: the file's gain, or the units (declared, or as the file
/// overrides them).
fn connection_conversion(
    conn: &crate::config::ConnectionConfig,
    from: (&ModelDescription, Option<&str>),
    to: (&ModelDescription, Option<&str>),
    to_ty: ScalarType,
) -> Result<Conversion, String> {
    let gain = conn.scale.is_some() || conn.offset.is_some();
    let units = conn.from_unit.is_some() || conn.to_unit.is_some();
    if gain && units {
        return Err("give either scale/offset or from_unit/to_unit, not both".into());
    }
    if (gain || units) && to_ty != ScalarType::Real {
        return Err(format!(
            "a scale, an offset or a unit applies to Real inputs only, this one is {}",
            to_ty.name()
        ));
    }
    if gain {
        let scale = conn.scale.unwrap_or(1.0);
        let offset = conn.offset.unwrap_or(0.0);
        if !(scale.is_finite() && scale != 0.0 && offset.is_finite()) {
            return Err(format!(
                "scale must be a finite non-zero number and offset a finite number, got scale = {scale}, offset = {offset}"
            ));
        }
        let declared = |u: Option<&str>| u.map_or("none".to_string(), |u| format!("'{u}'"));
        return Ok(Conversion {
            scale,
            offset,
            note: Some(format!(
                "scale {scale} and offset {offset} from the system file (declared units {} and {} not used)",
                declared(from.1),
                declared(to.1)
            )),
        });
    }
    let known = |md: &ModelDescription, u: &Option<String>, end: &str| -> Result<(), String> {
        match u {
            Some(u) if units::definition(md, u).is_none() => Err(format!(
                "{end} = '{u}' is defined neither by the FMU nor in twinbench's unit table ({})",
                tb_fmi::units::UNITS
                    .iter()
                    .map(|d| d.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
            _ => Ok(()),
        }
    };
    known(from.0, &conn.from_unit, "from_unit")?;
    known(to.0, &conn.to_unit, "to_unit")?;
    let from_unit = conn.from_unit.as_deref().or(from.1);
    let to_unit = conn.to_unit.as_deref().or(to.1);
    let mut c = unit_conversion((from.0, from_unit), (to.0, to_unit))?;
    if units {
        let said = format!(
            "units overridden in the system file: '{}' -> '{}', scale {}, offset {}",
            from_unit.unwrap_or("1"),
            to_unit.unwrap_or("1"),
            c.scale,
            c.offset
        );
        c.note = Some(match c.note {
            Some(n) => format!("{said}; {n}"),
            None => said,
        });
    }
    Ok(c)
}
