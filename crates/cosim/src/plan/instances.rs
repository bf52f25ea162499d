//! Stages "instances" and "replays": the FMUs loaded, each instance with the backend that
//! will run it, the replayed files; and [`Units`], the one place a name in the system file
//! (`instance.variable`, `replay.column`) becomes a unit, a variable or a signal.

use super::{Endpoint, InstanceDef, LoadOptions, ParamSlot};
use crate::backend::{BackendFactory, FmuFactory, RunAs};
use crate::config::{InstanceConfig, SystemFile};
use crate::isolated::IsolatedFactory;
use crate::native::NativeFactory;
use crate::replay::ReplaySource;
use crate::{invalid, split_name, SystemError};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use tb_fmi::import::description::ScalarVariable;
use tb_fmi::{Causality, FmuCache, Interface, LoadedFmu, MeSettings, ScalarType, Variability};

/// The FMUs of `[fmus]`, loaded once each (an FMU shared by instances is unpacked once).
pub(super) fn load_fmus(
    file: &SystemFile,
    ctx_file: &str,
    cache: &FmuCache,
) -> Result<HashMap<String, Arc<LoadedFmu>>, SystemError> {
    let mut loaded = HashMap::new();
    for (key, p) in &file.fmus {
        if std::fs::symlink_metadata(p).is_err() {
            return Err(missing_fmu(ctx_file, key, p));
        }
        loaded.insert(key.clone(), cache.load(p)?);
    }
    Ok(loaded)
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

/// A relative tolerance: a number in (0, 1).
pub(super) fn check_tolerance(t: f64, ctx: &str) -> Result<(), SystemError> {
    if t > 0.0 && t < 1.0 {
        return Ok(());
    }
    Err(invalid(
        ctx,
        format!(
            "{} is not a relative tolerance: expected a number between 0 and 1 (e.g. 1e-6)",
            tb_files::number(t)
        ),
    ))
}

/// The instances, each with the factory of its backend (in-process FMU, native model,
/// isolated worker, traced); and a warning for every instance `--native` could not link.
pub(super) fn instances(
    file: &SystemFile,
    loaded: &HashMap<String, Arc<LoadedFmu>>,
    ctx_file: &str,
    options: &LoadOptions,
) -> Result<(Vec<InstanceDef>, Vec<String>), SystemError> {
    let mut instances: Vec<InstanceDef> = Vec::new();
    let mut native_fallback = Vec::new();
    for inst in &file.instances {
        let fmu = instance_fmu(file, loaded, inst, ctx_file)?;
        check_instance_name(&instances, inst, ctx_file)?;
        let run = run_as(file, inst, fmu, ctx_file)?;
        check_only_once(file, inst, fmu, run.interface, ctx_file)?;
        let factory = backend(
            file,
            inst,
            fmu,
            run,
            ctx_file,
            options,
            &mut native_fallback,
        )?;
        let ctx = format!("{ctx_file}: instance '{}'", inst.name);
        let tolerance = instance_tolerance(file, inst, fmu, &ctx)?;
        let def = InstanceDef {
            name: inst.name.clone(),
            fmu: fmu.clone(),
            ports: inst.ports.clone(),
            logging: inst.logging,
            interface: run.interface,
            tolerance,
            factory,
        };
        check_port_map(&def, inst, ctx_file)?;
        instances.push(def);
    }
    check_traced_instances(options, &instances, ctx_file)?;
    Ok((instances, native_fallback))
}

/// The loaded FMU an instance names (its key in `[fmus]`).
fn instance_fmu<'l>(
    file: &SystemFile,
    loaded: &'l HashMap<String, Arc<LoadedFmu>>,
    inst: &InstanceConfig,
    ctx_file: &str,
) -> Result<&'l Arc<LoadedFmu>, SystemError> {
    loaded.get(inst.fmu.as_str()).ok_or_else(|| {
        invalid(
            format!("{ctx_file}: instance '{}'", inst.name),
            format!(
                "fmu '{}' is not in [fmus] (known: {})",
                inst.fmu,
                file.fmus.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        )
    })
}

/// An instance's name is new (none of the `instances` before it has it), has no `.` (a name
/// `instance.variable` splits at it) and can head a result column as it is.
fn check_instance_name(
    instances: &[InstanceDef],
    inst: &InstanceConfig,
    ctx_file: &str,
) -> Result<(), SystemError> {
    if instances.iter().any(|i| i.name == inst.name)
        || inst.name.contains('.')
        || !valid_unit_name(&inst.name)
    {
        return Err(invalid(
            ctx_file,
            format!(
                "instance name '{}' is repeated, empty, or contains a '.', a quote, a separator or a control character",
                inst.name
            ),
        ));
    }
    Ok(())
}

/// An FMU that can be instantiated only once per process (through the interface this
/// instance uses) is the FMU of no other instance.
fn check_only_once(
    file: &SystemFile,
    inst: &InstanceConfig,
    fmu: &LoadedFmu,
    interface: Interface,
    ctx_file: &str,
) -> Result<(), SystemError> {
    let md = &fmu.description;
    let only_once = match interface {
        Interface::CoSimulation => md
            .co_simulation
            .as_ref()
            .is_some_and(|c| c.can_be_instantiated_only_once_per_process),
        Interface::ModelExchange => md
            .model_exchange
            .as_ref()
            .is_some_and(|m| m.can_be_instantiated_only_once_per_process),
    };
    if only_once && file.instances.iter().filter(|i| i.fmu == inst.fmu).count() > 1 {
        return Err(invalid(
            ctx_file,
            format!(
                "FMU '{}' can be instantiated only once per process",
                inst.fmu
            ),
        ));
    }
    Ok(())
}

/// An instance's relative tolerance: its own, else the experiment's, else the FMU's
/// DefaultExperiment one; checked where it is given (the instance's, or the FMU's when it
/// is the one used; the experiment's is checked with the experiment).
fn instance_tolerance(
    file: &SystemFile,
    inst: &InstanceConfig,
    fmu: &LoadedFmu,
    ctx: &str,
) -> Result<Option<f64>, SystemError> {
    let tolerance = inst
        .tolerance
        .or(file.experiment.tolerance)
        .or_else(|| fmu.description.default_experiment.as_ref()?.tolerance);
    if let Some(t) = inst.tolerance {
        check_tolerance(t, &format!("{ctx}: tolerance"))?;
    }
    if let Some(t) =
        tolerance.filter(|_| inst.tolerance.is_none() && file.experiment.tolerance.is_none())
    {
        check_tolerance(
            t,
            &format!(
                "{ctx}: the DefaultExperiment tolerance of {}",
                fmu.source.display()
            ),
        )?;
    }
    Ok(tolerance)
}

/// Every variable an instance's port map names is one of its FMU's.
fn check_port_map(
    def: &InstanceDef,
    inst: &InstanceConfig,
    ctx_file: &str,
) -> Result<(), SystemError> {
    for theirs in inst.ports.values() {
        if def.description().variable(theirs).is_none() {
            def.variable(theirs, &format!("{ctx_file}: port map of '{}'", inst.name))?;
        }
    }
    Ok(())
}

/// Every instance `--trace-instances` names is one of the system's.
fn check_traced_instances(
    options: &LoadOptions,
    instances: &[InstanceDef],
    ctx_file: &str,
) -> Result<(), SystemError> {
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
    Ok(())
}

/// The interface an instance runs through (its `interface`, else the FMU's default),
/// checked against the FMU, with the Model Exchange solver's settings.
fn run_as(
    file: &SystemFile,
    inst: &InstanceConfig,
    fmu: &LoadedFmu,
    ctx_file: &str,
) -> Result<RunAs, SystemError> {
    let interface = inst.interface.unwrap_or_else(|| fmu.default_interface());
    fmu.check_interface(interface).map_err(|why| {
        invalid(
            format!("{ctx_file}: instance '{}'", inst.name),
            format!(
                "interface = \"{interface}\": {}: {why}",
                fmu.source.display()
            ),
        )
    })?;
    Ok(RunAs {
        interface,
        me: MeSettings {
            // The instance's, else the experiment's; else the FMU's DefaultExperiment
            // tolerance, else FMPy's 1e-5 (`MeSettings::relative_tolerance_for`).
            relative_tolerance: inst.tolerance.or(file.experiment.tolerance),
        },
    })
}

/// What runs one instance: the native model (`--native`, when linked, Co-Simulation only),
/// else the FMU through its interface; in a worker process when isolated (of this
/// instance, or of all: isolation wins); wrapped by the call trace when traced.
fn backend(
    file: &SystemFile,
    inst: &InstanceConfig,
    fmu: &Arc<LoadedFmu>,
    run: RunAs,
    ctx_file: &str,
    options: &LoadOptions,
    native_fallback: &mut Vec<String>,
) -> Result<Arc<dyn BackendFactory>, SystemError> {
    let as_fmu = || -> Arc<dyn BackendFactory> {
        Arc::new(FmuFactory {
            fmu: fmu.clone(),
            run,
        })
    };
    let native = options.native && run.interface == Interface::CoSimulation;
    let in_process: Arc<dyn BackendFactory> = match native {
        true => match NativeFactory::for_fmu(fmu, &options.native_models) {
            Ok(f) => Arc::new(f),
            Err(why) => {
                native_fallback.push(format!("instance '{}' runs as an FMU: {why}", inst.name));
                as_fmu()
            }
        },
        false => as_fmu(),
    };
    let factory: Arc<dyn BackendFactory> = if inst.isolate || options.isolate {
        let mut iso = options.isolation.clone();
        iso.preload.extend(file.preload.iter().cloned());
        if let Some(w) = inst.watchdog {
            iso.timeout = crate::isolated::watchdog(w).map_err(|m| {
                invalid(
                    format!("{ctx_file}: instance '{}'", inst.name),
                    m.to_string(),
                )
            })?;
        }
        Arc::new(IsolatedFactory {
            fmu: fmu.clone(),
            options: iso,
            run,
        })
    } else {
        in_process
    };
    Ok(match &options.trace {
        Some(t) if t.instances.is_empty() || t.instances.contains(&inst.name) => {
            Arc::new(crate::trace::TracedFactory {
                inner: factory,
                sink: t.sink.clone(),
                fmu: fmu.clone(),
            })
        }
        _ => factory,
    })
}

/// The preloads serve in-process FMU libraries; isolated ones get them in their worker, so
/// a system of isolated instances loads nothing into this process.
pub(super) fn preload(file: &SystemFile, instances: &[InstanceDef]) -> Result<(), SystemError> {
    if instances.iter().any(|i| i.factory.kind() != "isolated") {
        for lib in &file.preload {
            tb_fmi::import::library::preload_global(lib)?;
        }
    }
    Ok(())
}

/// Stage "replays": the replayed files, loaded and named apart from the instances.
pub(super) fn replays(
    file: &SystemFile,
    instances: &[InstanceDef],
    ctx_file: &str,
) -> Result<Vec<ReplaySource>, SystemError> {
    let mut replays = Vec::new();
    for r in &file.replay {
        if !valid_unit_name(&r.name) || r.name.contains('.') {
            return Err(invalid(
                ctx_file,
                format!(
                    "replay name '{}' is empty, or contains a '.', a quote, a separator or a control character",
                    r.name
                ),
            ));
        }
        if instances.iter().any(|i| i.name == r.name) {
            return Err(invalid(
                ctx_file,
                format!("replay name '{}' is also an instance name", r.name),
            ));
        }
        replays.push(ReplaySource::load(r)?);
    }
    Ok(replays)
}

/// A name that can head a result column as it is: no quote, no separator, no control
/// character, not empty.
fn valid_unit_name(name: &str) -> bool {
    !name.is_empty()
        && !name
            .chars()
            .any(|c| c.is_control() || matches!(c, '"' | ',' | ';' | '\t'))
}

/// The units of a system, FMU instances first (numbered 0..n) then replays (n..): what
/// every later stage resolves names against.
#[derive(Clone, Copy)]
pub(crate) struct Units<'a> {
    pub instances: &'a [InstanceDef],
    pub replays: &'a [ReplaySource],
}

impl<'a> Units<'a> {
    /// The unit named `name`.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.instances
            .iter()
            .position(|i| i.name == name)
            .or_else(|| {
                self.replays
                    .iter()
                    .position(|r| r.name == name)
                    .map(|k| self.instances.len() + k)
            })
    }

    pub fn is_replay(&self, unit: usize) -> bool {
        unit >= self.instances.len()
    }

    pub fn replay(&self, unit: usize) -> &'a ReplaySource {
        &self.replays[unit - self.instances.len()]
    }

    /// "unknown instance" with every unit name, closest first.
    pub fn unknown(&self, ctx: &str, name: &str) -> SystemError {
        let names = self
            .instances
            .iter()
            .map(|i| i.name.as_str())
            .chain(self.replays.iter().map(|r| r.name.as_str()));
        let all: Vec<&str> = names.clone().collect();
        invalid(
            ctx,
            format!(
                "unknown instance '{name}'; instances: {}",
                tb_fmi::import::description::closest(name, names, all.len()).join(", ")
            ),
        )
    }

    /// A signal the system can read, `instance.variable`: an FMU variable (through the
    /// port map) or a replayed column.
    pub fn endpoint(&self, ctx: &str, full: &str) -> Result<Endpoint, SystemError> {
        let (u, var) = split_name(full).ok_or_else(|| {
            invalid(
                ctx,
                format!("'{full}' is not of the form instance.variable"),
            )
        })?;
        if let Some(k) = self.instances.iter().position(|i| i.name == u) {
            let sv = self.instances[k].variable(var, ctx)?;
            return Ok(Endpoint::Fmu {
                unit: k,
                vr: sv.value_reference,
                ty: sv.ty,
                unit_name: self.instances[k]
                    .description()
                    .unit_of(sv)
                    .map(str::to_string),
            });
        }
        let Some(k) = self.replays.iter().position(|r| r.name == u) else {
            return Err(self.unknown(ctx, u));
        };
        let r = &self.replays[k];
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
            unit: self.instances.len() + k,
            column: c,
            unit_name: r.units[c].clone(),
        })
    }

    /// FMI 3.0: `instance.array` → `instance.array[1]`, … (the elements' full names);
    /// empty when `full` is not an instance's array.
    pub fn array_elements(&self, full: &str) -> Vec<String> {
        let Some((u, var)) = split_name(full) else {
            return Vec::new();
        };
        match self.instances.iter().find(|i| i.name == u) {
            Some(inst) => inst
                .elements(var)
                .into_iter()
                .map(|e| format!("{u}.{e}"))
                .collect(),
            None => Vec::new(),
        }
    }

    /// The FMU variable behind an FMU endpoint.
    pub fn variable(&self, e: &Endpoint) -> Option<&'a ScalarVariable> {
        match e {
            Endpoint::Fmu { unit, vr, ty, .. } => self.instances[*unit]
                .description()
                .variables
                .iter()
                .find(|v| v.has_key((ty.value_space(), *vr))),
            Endpoint::Replay { .. } => None,
        }
    }
}

/// A settable variable (parameter or input) by its system name: the instance, the value
/// reference, the type and the declared range.
pub(crate) fn parameter_slot(
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
        variable_unit: instances[k].description().unit_of(sv).map(str::to_string),
        items: instances[k]
            .description()
            .enumeration_items(sv)
            .map(<[_]>::to_vec),
    })
}

/// Every output of every instance (under the system's names) and every replayed column:
/// what a system without `[record]` records.
pub(super) fn default_record(units: Units<'_>) -> Vec<String> {
    let mut names = Vec::new();
    for inst in units.instances {
        for v in inst.description().variables_of(Causality::Output) {
            let ours = inst
                .ports
                .iter()
                .find(|(_, t)| *t == &v.name)
                .map(|(o, _)| o.clone())
                .unwrap_or(v.name.clone());
            names.push(format!("{}.{ours}", inst.name));
        }
    }
    for r in units.replays {
        for c in &r.columns {
            names.push(format!("{}.{c}", r.name));
        }
    }
    names
}
