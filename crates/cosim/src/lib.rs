//! System description, validation and the co-simulation master.
//!
//! [`System::load`] reads a system file, loads the FMUs and checks everything before the
//! first step: names (with suggestions), causality, types, units (converted when
//! compatible, refused when not), unconnected inputs, direct-feed-through cycles.
//! [`Simulation`] owns the instances and runs the system, repeatedly if asked (instances
//! are reset and reused between runs).

pub mod backend;
pub mod config;
pub mod isolated;
pub mod master;
pub mod native;
pub mod replay;
pub mod results;
pub mod ssp;

pub use config::{Algorithm, StopConfig, SystemFile};
pub use master::{RunSummary, Simulation};
pub use results::Recording;

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::Arc;
use tb_fmi::description::{ModelDescription, ScalarVariable};
use tb_fmi::{Causality, FmuCache, FmuError, LoadedFmu, ScalarType, Variability};

#[derive(Debug, thiserror::Error)]
pub enum SystemError {
    #[error("{path}: {message}")]
    File { path: PathBuf, message: String },
    // Transparent: with "{0}" and #[from], `{:#}` printed the FMU error twice.
    #[error(transparent)]
    Fmu(#[from] FmuError),
    #[error("{context}: {message}")]
    Invalid { context: String, message: String },
    #[error("replay '{name}' ({path}): {message}")]
    Replay {
        name: String,
        path: PathBuf,
        message: String,
    },
    #[error(
        "{signal} is not finite ({value}) at t = {time} s after the step of instance '{instance}'"
    )]
    NotFinite {
        instance: String,
        signal: String,
        value: f64,
        time: f64,
    },
    #[error("{0}")]
    Stop(String),
}

pub(crate) fn invalid(context: impl Into<String>, message: impl Into<String>) -> SystemError {
    SystemError::Invalid {
        context: context.into(),
        message: message.into(),
    }
}

/// One FMU instance of the system, resolved.
pub struct InstanceDef {
    pub name: String,
    pub fmu: Arc<LoadedFmu>,
    /// Name in the system file -> the FMU's variable name.
    pub ports: BTreeMap<String, String>,
    pub logging: bool,
    /// Creates the running unit (in-process FMU by default).
    pub factory: Arc<dyn backend::BackendFactory>,
}

/// How instances are run, chosen when a system is loaded.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Run linked models natively (no FMI boundary); other FMUs stay FMUs (with a warning).
    pub native: bool,
    /// The models linked into the host that `native` may use (the host's model registry).
    pub native_models: Vec<native::NativeModel>,
    /// Run every FMU instance in a worker process (as `isolate = true` does for one).
    pub isolate: bool,
    /// Watchdog and worker executable of isolated instances.
    pub isolation: isolated::IsolationOptions,
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
    pub from_name: String,
    pub to_unit: usize,
    pub to_vr: u32,
    pub to_ty: ScalarType,
    pub to_name: String,
    pub scale: f64,
    pub offset: f64,
}

/// The loaded, validated system.
pub struct System {
    pub file: SystemFile,
    pub path: PathBuf,
    /// FMU instances first (indices 0..n), then replays (n..).
    pub instances: Vec<InstanceDef>,
    pub replays: Vec<replay::ReplaySource>,
    pub connections: Vec<ConnectionDef>,
    /// Stepping order over units (FMU instances and replays).
    pub order: Vec<usize>,
    pub warnings: Vec<String>,
    /// Keeps the unpacked FMUs alive (and removes them at the end).
    pub cache: Arc<FmuCache>,
}

/// Split `instance.variable`.
pub fn split_name(s: &str) -> Option<(&str, &str)> {
    let (a, b) = s.trim().split_once('.')?;
    (!a.is_empty() && !b.is_empty()).then_some((a, b))
}

fn unit_conversion(
    from: (&ModelDescription, Option<&str>),
    to: (&ModelDescription, Option<&str>),
) -> Result<(f64, f64), String> {
    let (Some(fu), Some(tu)) = (from.1, to.1) else {
        return Ok((1.0, 0.0));
    };
    if fu == tu {
        return Ok((1.0, 0.0));
    }
    let def = |md: &ModelDescription, u: &str| {
        md.unit_def(u)
            .copied()
            .or_else(|| tb_fmi::units::lookup(u).copied())
    };
    let (Some(a), Some(b)) = (def(from.0, fu), def(to.0, tu)) else {
        return Err(format!(
            "units '{fu}' and '{tu}' differ and at least one has no definition to convert by"
        ));
    };
    if !a.compatible(&b) {
        return Err(format!(
            "incompatible units '{fu}' and '{tu}' (different base units)"
        ));
    }
    // SI = factor·value + offset on both sides.
    Ok((a.factor / b.factor, (a.offset - b.offset) / b.factor))
}

impl System {
    /// Load a system file and check it. `overrides` are `instance.variable=value` strings.
    pub fn load(path: &std::path::Path, cache: Arc<FmuCache>) -> Result<System, SystemError> {
        Self::load_with(path, cache, &LoadOptions::default())
    }

    /// [`System::load`] with a choice of backends.
    pub fn load_with(
        path: &std::path::Path,
        cache: Arc<FmuCache>,
        options: &LoadOptions,
    ) -> Result<System, SystemError> {
        let file = SystemFile::load(path)?;
        Self::from_file_with(file, path, cache, options)
    }

    pub fn from_file(
        file: SystemFile,
        path: &std::path::Path,
        cache: Arc<FmuCache>,
    ) -> Result<System, SystemError> {
        Self::from_file_with(file, path, cache, &LoadOptions::default())
    }

    pub fn from_file_with(
        file: SystemFile,
        path: &std::path::Path,
        cache: Arc<FmuCache>,
        options: &LoadOptions,
    ) -> Result<System, SystemError> {
        let ctx_file = path.display().to_string();
        for lib in &file.preload {
            tb_fmi::library::preload_global(lib)?;
        }
        if !(file.experiment.step > 0.0 && file.experiment.step.is_finite()) {
            return Err(invalid(
                &ctx_file,
                format!(
                    "experiment.step must be positive, got {}",
                    file.experiment.step
                ),
            ));
        }
        match &file.experiment.stop {
            StopConfig::Time(t) if *t <= file.experiment.start || t.is_nan() => {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "experiment.stop {t} is not after start {}",
                        file.experiment.start
                    ),
                ))
            }
            StopConfig::Word(w) if w != "lap" => {
                return Err(invalid(
                    &ctx_file,
                    format!("experiment.stop must be a time in s or \"lap\", got \"{w}\""),
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
            {
                return Err(invalid(
                    &ctx_file,
                    format!(
                        "instance name '{}' is repeated or contains a '.'",
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
            let factory: Arc<dyn backend::BackendFactory> = match options.native {
                true => match native::NativeFactory::for_fmu(fmu, &options.native_models) {
                    Ok(f) => Arc::new(f),
                    Err(why) => {
                        native_fallback
                            .push(format!("instance '{}' runs as an FMU: {why}", inst.name));
                        Arc::new(backend::FmuFactory(fmu.clone()))
                    }
                },
                false => Arc::new(backend::FmuFactory(fmu.clone())),
            };
            // Isolation (of this instance, or of all) wins over the in-process choices.
            let factory: Arc<dyn backend::BackendFactory> = if inst.isolate || options.isolate {
                let mut iso = options.isolation.clone();
                if let Some(w) = inst.watchdog {
                    if !w.is_finite() || w <= 0.0 {
                        return Err(invalid(
                            format!("{ctx_file}: instance '{}'", inst.name),
                            format!("watchdog must be a positive number of seconds, got {w}"),
                        ));
                    }
                    iso.timeout = std::time::Duration::from_secs_f64(w);
                }
                Arc::new(isolated::IsolatedFactory {
                    fmu: fmu.clone(),
                    options: iso,
                })
            } else {
                factory
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
        let n_fmu = instances.len();
        let mut replays = Vec::new();
        for r in &file.replay {
            if instances.iter().any(|i| i.name == r.name) {
                return Err(invalid(
                    &ctx_file,
                    format!("replay name '{}' is also an instance name", r.name),
                ));
            }
            replays.push(replay::ReplaySource::load(r)?);
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
        // Connections.
        let mut connections: Vec<ConnectionDef> = Vec::new();
        for text in &file.connections {
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
            let type_ok = from_ty == to_sv.ty
                || (to_sv.ty == ScalarType::Real
                    && matches!(
                        from_ty,
                        ScalarType::Integer | ScalarType::Boolean | ScalarType::Enumeration
                    ))
                || (matches!(to_sv.ty, ScalarType::Integer | ScalarType::Enumeration)
                    && matches!(from_ty, ScalarType::Integer | ScalarType::Enumeration));
            if !type_ok || to_sv.ty == ScalarType::String {
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
            let (scale, offset) = unit_conversion(
                (from_md.unwrap_or(&empty), from_unit_name.as_deref()),
                (to_def.description(), to_def.description().unit_of(to_sv)),
            )
            .map_err(|m| invalid(&ctx, m))?;
            if connections
                .iter()
                .any(|c| c.to_unit == to_unit && c.to_vr == to_sv.value_reference)
            {
                return Err(invalid(&ctx, format!("'{b}' is already connected")));
            }
            connections.push(ConnectionDef {
                text: text.clone(),
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
        // Parameters: names and types checked now, values when set.
        for (name, value) in &file.parameters {
            let ctx = format!("{ctx_file}: parameter \"{name}\"");
            check_parameter(&instances, name, value, &ctx)?;
        }
        // Replay bases.
        for r in &replays {
            if let Some(by) = &r.by {
                let ctx = format!("{ctx_file}: replay '{}'", r.name);
                match resolve_source(&ctx, by)? {
                    Endpoint::Fmu { .. } => {}
                    Endpoint::Replay { .. } => {
                        return Err(invalid(&ctx, "a replay cannot be driven by another replay"))
                    }
                }
            }
        }
        // Recorded signals and the stop signal must resolve.
        for s in &file.record.signals {
            resolve_source(&format!("{ctx_file}: record"), s)?;
        }
        if file.experiment.stop == StopConfig::Word("lap".into()) {
            resolve_source(
                &format!("{ctx_file}: experiment.lap_signal"),
                &file.experiment.lap_signal,
            )?;
        }
        let mut warnings = native_fallback;
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
        Ok(System {
            file,
            path: path.to_path_buf(),
            instances,
            replays,
            connections,
            order,
            warnings,
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
}

/// "unknown instance" with every unit name, closest first.
fn unknown_instance(
    instances: &[InstanceDef],
    replays: &[replay::ReplaySource],
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

/// A signal the system can read, `instance.variable`: an FMU variable (through the port
/// map) or a replayed column. Instances come first in the unit numbering, then replays.
pub(crate) fn resolve_endpoint(
    instances: &[InstanceDef],
    replays: &[replay::ReplaySource],
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

/// A parameter assignment: the instance, the variable and the typed value.
pub(crate) fn check_parameter<'a>(
    instances: &'a [InstanceDef],
    name: &str,
    value: &toml::Value,
    ctx: &str,
) -> Result<(usize, &'a ScalarVariable), SystemError> {
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
    let sv = instances[k].variable(var, ctx)?;
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
    let ok = match sv.ty {
        ScalarType::Real => value.as_float().is_some() || value.as_integer().is_some(),
        ScalarType::Integer | ScalarType::Enumeration => value.as_integer().is_some(),
        ScalarType::Boolean => value.as_bool().is_some(),
        ScalarType::String => value.as_str().is_some(),
    };
    if !ok {
        return Err(invalid(
            ctx,
            format!("'{name}' is {}, the value {value} is not", sv.ty.name()),
        ));
    }
    let x = value
        .as_float()
        .or_else(|| value.as_integer().map(|i| i as f64));
    if let Some(x) = x {
        if sv.min.is_some_and(|m| x < m) || sv.max.is_some_and(|m| x > m) {
            return Err(invalid(
                ctx,
                format!(
                    "{x} is outside the declared range [{}, {}] of '{name}'",
                    sv.min.map_or("-inf".into(), |m| m.to_string()),
                    sv.max.map_or("inf".into(), |m| m.to_string())
                ),
            ));
        }
    }
    Ok((k, sv))
}

/// Direct feed-through cycles: output -> input (connection) -> output of the same instance
/// (declared dependency). Cycles made only of declared dependencies are errors; cycles
/// that rely on outputs without a `dependencies` attribute (meaning "may depend on every
/// input") are warnings.
fn check_feedthrough_cycles(
    instances: &[InstanceDef],
    connections: &[ConnectionDef],
    warnings: &mut Vec<String>,
) -> Result<(), String> {
    // Nodes: (instance, vr) of connected inputs and outputs.
    type Node = (usize, u32);
    let mut edges: HashMap<Node, Vec<(Node, bool)>> = HashMap::new();
    for c in connections {
        if let Endpoint::Fmu { unit, vr, .. } = c.from {
            edges
                .entry((unit, vr))
                .or_default()
                .push(((c.to_unit, c.to_vr), true));
        }
    }
    for (k, inst) in instances.iter().enumerate() {
        let md = inst.description();
        for o in &md.outputs {
            let out = &md.variables[o.index - 1];
            let (deps, declared): (Vec<&ScalarVariable>, bool) = match &o.dependencies {
                Some(d) => (
                    d.iter()
                        .filter_map(|i| md.variables.get(i - 1))
                        .filter(|v| v.causality == Causality::Input)
                        .collect(),
                    true,
                ),
                None => (
                    md.variables
                        .iter()
                        .filter(|v| v.causality == Causality::Input)
                        .collect(),
                    false,
                ),
            };
            for inp in deps {
                edges
                    .entry((k, inp.value_reference))
                    .or_default()
                    .push(((k, out.value_reference), declared));
            }
        }
    }
    let name = |n: &Node| {
        let inst = &instances[n.0];
        let v = inst
            .description()
            .variables
            .iter()
            .find(|v| v.value_reference == n.1)
            .map(|v| v.name.as_str())
            .unwrap_or("?");
        format!("{}.{v}", inst.name)
    };
    // DFS for a cycle.
    let mut color: HashMap<Node, u8> = HashMap::new();
    let mut nodes: Vec<Node> = edges.keys().copied().collect();
    nodes.sort();
    type Edges = HashMap<(usize, u32), Vec<((usize, u32), bool)>>;
    fn dfs(
        n: (usize, u32),
        edges: &Edges,
        color: &mut HashMap<(usize, u32), u8>,
        path: &mut Vec<((usize, u32), bool)>,
    ) -> Option<Vec<((usize, u32), bool)>> {
        color.insert(n, 1);
        if let Some(next) = edges.get(&n) {
            for &(m, declared) in next {
                path.push((m, declared));
                match color.get(&m).copied().unwrap_or(0) {
                    1 => {
                        let start = path.iter().position(|p| p.0 == m).unwrap_or(0);
                        return Some(path[start..].to_vec());
                    }
                    0 => {
                        if let Some(c) = dfs(m, edges, color, path) {
                            return Some(c);
                        }
                    }
                    _ => {}
                }
                path.pop();
            }
        }
        color.insert(n, 2);
        None
    }
    for n in nodes {
        if color.get(&n).copied().unwrap_or(0) == 0 {
            let mut path = vec![(n, true)];
            if let Some(cycle) = dfs(n, &edges, &mut color, &mut path) {
                let text = cycle.iter().map(|(n, _)| name(n)).collect::<Vec<_>>();
                let text = format!("{} -> {}", text.join(" -> "), text[0]);
                if cycle.iter().all(|c| c.1) {
                    return Err(format!(
                        "direct feed-through cycle (an algebraic loop): {text}"
                    ));
                }
                warnings.push(format!("possible feed-through cycle through outputs that declare no dependencies: {text}"));
                return Ok(());
            }
        }
    }
    Ok(())
}

/// Stepping order: the explicit one, or a topological order of the connections
/// (sources before their consumers), ties and cycles broken by declaration order.
fn stepping_order(
    file: &SystemFile,
    unit_names: &[String],
    n_fmu: usize,
    connections: &[ConnectionDef],
    replays: &[replay::ReplaySource],
    instances: &[InstanceDef],
) -> Result<Vec<usize>, String> {
    let n = unit_names.len();
    if !file.experiment.order.is_empty() {
        let mut order = Vec::new();
        for name in &file.experiment.order {
            let k = unit_names
                .iter()
                .position(|u| u == name)
                .ok_or_else(|| format!("experiment.order: unknown instance '{name}'"))?;
            if order.contains(&k) {
                return Err(format!("experiment.order: '{name}' appears twice"));
            }
            order.push(k);
        }
        if let Some(missing) = unit_names
            .iter()
            .enumerate()
            .find(|(k, _)| !order.contains(k))
        {
            return Err(format!("experiment.order: '{}' is missing", missing.1));
        }
        return Ok(order);
    }
    let mut deps: Vec<Vec<usize>> = vec![Vec::new(); n];
    for c in connections {
        let from = match c.from {
            Endpoint::Fmu { unit, .. } | Endpoint::Replay { unit, .. } => unit,
        };
        if from != c.to_unit && !deps[c.to_unit].contains(&from) {
            deps[c.to_unit].push(from);
        }
    }
    for (k, r) in replays.iter().enumerate() {
        if let Some((u, _)) = r.by.as_deref().and_then(split_name) {
            if let Some(src) = instances.iter().position(|i| i.name == u) {
                deps[n_fmu + k].push(src);
            }
        }
    }
    let mut done = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        let next = (0..n)
            .find(|&k| !done[k] && deps[k].iter().all(|&d| done[d]))
            .or_else(|| (0..n).find(|&k| !done[k]))
            .unwrap();
        done[next] = true;
        order.push(next);
    }
    Ok(order)
}
