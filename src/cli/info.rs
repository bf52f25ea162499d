//! `twinbench info`: an FMU's capabilities and variables.

use std::path::PathBuf;
use tb_fmi::{FmuCache, LoadedFmu};

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// The FMU file.
    pub fmu: PathBuf,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
    /// Also load the FMU's library here and check it (fmi2GetVersion, the required
    /// functions). Without this or --isolate, none of the FMU's code runs.
    #[arg(long)]
    pub check: bool,
    /// Check the library in a worker process: a crash or hang there cannot harm this one
    /// (confined, or `--isolate=crash-only`).
    #[arg(long, conflicts_with = "check", num_args = 0..=1, require_equals = true, default_missing_value = "confined", value_name = "MODE")]
    pub isolate: Option<super::IsolateMode>,
    /// Watchdog of the --isolate check [s].
    #[arg(long, default_value_t = 10.0, value_name = "SECONDS")]
    pub worker_timeout: f64,
    /// Limits of the confined worker (as `twinbench run --worker-limits`).
    #[arg(long, value_name = "KEY=VALUE,...", value_parser = |s: &str| tb_cosim::isolated::confine::Limits::parse(s))]
    pub worker_limits: Option<tb_cosim::isolated::confine::Limits>,
    /// Load a shared library with RTLD_GLOBAL first (e.g. libpython for a pythonfmu FMU);
    /// with --isolate, in the worker.
    #[arg(long, value_name = "LIBRARY")]
    pub preload: Vec<PathBuf>,
}

/// The library check's outcome.
enum LibraryCheck {
    NotLoaded,
    Loaded(tb_cosim::isolated::LibraryReport),
}

pub fn run(args: InfoArgs) -> anyhow::Result<()> {
    let cache = FmuCache::temporary(false)?;
    // Reading the archive and its model description runs none of the FMU's code.
    let fmu = cache.load(&args.fmu)?;
    let check = check_library(&args, &fmu)?;
    let gaps = fmu.description.model_structure_gaps();
    if args.json {
        return print_json(&args, &fmu, &check, &gaps);
    }
    print_summary(&args, &fmu, &check);
    for g in &gaps {
        eprintln!("warning: {}: {g}", args.fmu.display());
    }
    println!();
    print_variables(&fmu.description);
    Ok(())
}

/// Loads the FMU's library when asked (here with --check, in a worker with --isolate) and
/// says what it found; without either, none of the FMU's code runs.
fn check_library(args: &InfoArgs, fmu: &LoadedFmu) -> anyhow::Result<LibraryCheck> {
    if let Some(mode) = args.isolate {
        let options = tb_cosim::isolated::IsolationOptions {
            mode: mode.mode(),
            timeout: tb_cosim::isolated::watchdog(args.worker_timeout)
                .map_err(|m| anyhow::anyhow!("--worker-timeout: {m}"))?,
            preload: args.preload.clone(),
            limits: args.worker_limits,
            ..Default::default()
        };
        return Ok(LibraryCheck::Loaded(tb_cosim::isolated::probe(
            fmu, &options,
        )?));
    }
    if !args.check {
        return Ok(LibraryCheck::NotLoaded);
    }
    for lib in &args.preload {
        tb_fmi::import::library::preload_global(lib)?;
    }
    let report = if fmu.is_fmi3() {
        let lib = fmu.library3()?;
        tb_cosim::isolated::LibraryReport {
            version: lib.version.clone(),
            missing_optional: Vec::new(),
        }
    } else {
        let lib = fmu.library()?;
        tb_cosim::isolated::LibraryReport {
            version: lib.version.clone(),
            missing_optional: lib.missing_optional.iter().map(|s| s.to_string()).collect(),
        }
    };
    Ok(LibraryCheck::Loaded(report))
}

/// `--json`: the whole description, the library check and the warnings.
fn print_json(
    args: &InfoArgs,
    fmu: &LoadedFmu,
    check: &LibraryCheck,
    gaps: &[String],
) -> anyhow::Result<()> {
    let md = &fmu.description;
    let cs = md.co_simulation.clone().unwrap_or_default();
    let vars: Vec<serde_json::Value> = md
        .variables
        .iter()
        .map(|v| {
            serde_json::json!({
                "name": v.name, "value_reference": v.declared_value_reference(), "array_element": v.array_element(), "type": v.ty.name(),
                "fmi3_type": v.fmi3.map(|s| s.ty.name()),
                "causality": v.causality.xml_name(), "variability": v.variability.xml_name(), "unit": md.unit_of(v),
                "start": v.start, "min": v.min, "max": v.max, "description": v.description,
            })
        })
        .collect();
    let j = serde_json::json!({
        "fmu": args.fmu, "model_name": md.model_name, "guid": md.guid, "fmi_version": md.fmi_version,
        "generation_tool": md.generation_tool, "model_identifier": cs.model_identifier,
        "can_get_and_set_fmu_state": cs.can_get_and_set_fmu_state,
        "can_serialize_fmu_state": cs.can_serialize_fmu_state,
        "can_be_instantiated_only_once_per_process": cs.can_be_instantiated_only_once_per_process,
        "can_handle_variable_communication_step_size": cs.can_handle_variable_communication_step_size,
        "default_experiment": md.default_experiment.map(|d| serde_json::json!({"start": d.start_time, "stop": d.stop_time, "step": d.step_size})),
        "library": {
            "entry": fmu.library_entry(),
            "checked": matches!(check, LibraryCheck::Loaded(_)),
            "fmi2GetVersion": match &check { LibraryCheck::Loaded(r) => Some(&r.version), LibraryCheck::NotLoaded => None },
            "missing_optional_functions": match &check { LibraryCheck::Loaded(r) => Some(&r.missing_optional), LibraryCheck::NotLoaded => None },
        },
        "warnings": gaps,
        "variables": vars,
    });
    super::json::print(&serde_json::to_string_pretty(&j)?)?;
    Ok(())
}

/// The model, its interfaces and identity, the tool, the capabilities, the default
/// experiment and the library.
fn print_summary(args: &InfoArgs, fmu: &LoadedFmu, check: &LibraryCheck) {
    let md = &fmu.description;
    let cs = md.co_simulation.clone().unwrap_or_default();
    println!("{}  ({})", md.model_name, args.fmu.display());
    if !md.description.is_empty() {
        println!("{}", md.description);
    }
    // The interfaces the FMU has (M17: an ME-only FMU was shown as "Co-Simulation,
    // identifier ,").
    let interfaces: Vec<String> = [
        md.co_simulation
            .as_ref()
            .map(|c| format!("Co-Simulation (identifier {})", c.model_identifier)),
        md.model_exchange
            .as_ref()
            .map(|m| format!("Model Exchange (identifier {})", m.model_identifier)),
    ]
    .into_iter()
    .flatten()
    .collect();
    // FMI 3.0 calls the model's identity its instantiation token.
    let identity = match md.fmi_version.starts_with('3') {
        true => "instantiation token",
        false => "GUID",
    };
    println!(
        "FMI {} {}, {identity} {}",
        md.fmi_version,
        interfaces.join(" and "),
        md.guid
    );
    println!(
        "generated by {}",
        if md.generation_tool.is_empty() {
            "?"
        } else {
            &md.generation_tool
        }
    );
    println!(
        "capabilities: get/set state {}, serialize state {}, once per process {}, variable step {}",
        cs.can_get_and_set_fmu_state,
        cs.can_serialize_fmu_state,
        cs.can_be_instantiated_only_once_per_process,
        cs.can_handle_variable_communication_step_size
    );
    if let Some(d) = md.default_experiment {
        println!("default experiment: {}", default_experiment(&d));
    }
    match &check {
        LibraryCheck::NotLoaded => println!(
            "library: {} (not loaded; --check loads it here, --isolate in a worker)",
            fmu.library_entry()
        ),
        LibraryCheck::Loaded(r) => println!(
            "library: {} loads; {}GetVersion \"{}\"; optional functions missing: {}",
            fmu.library_entry(),
            if fmu.is_fmi3() { "fmi3" } else { "fmi2" },
            r.version,
            if r.missing_optional.is_empty() {
                "none".to_string()
            } else {
                r.missing_optional.join(", ")
            }
        ),
    }
}

/// One line per variable: name, value reference, type, causality, variability, unit, start,
/// range and description.
fn print_variables(md: &tb_fmi::ModelDescription) {
    // An FMI 3.0 value reference may take ten digits.
    let vr_width = md
        .variables
        .iter()
        .map(|v| v.declared_value_reference().to_string().len())
        .max()
        .unwrap_or(0)
        .max(4);
    println!(
        "{:<28} {:>vr_width$} {:<8} {:<11} {:<10} {:<10} {:>12} {:>22}  description",
        "name", "vr", "type", "causality", "variab.", "unit", "start", "range"
    );
    for v in &md.variables {
        let range = match (v.min, v.max) {
            (None, None) => String::new(),
            (a, b) => format!(
                "[{}, {}]",
                a.map_or("-inf".into(), |x| x.to_string()),
                b.map_or("inf".into(), |x| x.to_string())
            ),
        };
        println!(
            "{:<28} {:>vr_width$} {:<8} {:<11} {:<10} {:<10} {:>12} {:>22}  {}",
            v.name,
            v.declared_value_reference(),
            v.fmi3.map_or(v.ty.name(), |s| s.ty.name()),
            v.causality.xml_name(),
            v.variability.xml_name(),
            md.unit_of(v).unwrap_or(""),
            v.start.as_deref().unwrap_or(""),
            range,
            v.description
        );
    }
}

/// `start 0 s, stop 100 s, step 0.001 s, tolerance 1e-6`: the attributes the FMU gives.
pub fn default_experiment(d: &tb_fmi::import::description::DefaultExperiment) -> String {
    let parts: Vec<String> = [
        ("start", d.start_time, " s"),
        ("stop", d.stop_time, " s"),
        ("step", d.step_size, " s"),
        ("tolerance", d.tolerance, ""),
    ]
    .iter()
    .filter_map(|(name, v, unit)| v.map(|v| format!("{name} {}{unit}", tb_files::number(v))))
    .collect();
    match parts.is_empty() {
        true => "none of start, stop, step and tolerance given".into(),
        false => parts.join(", "),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_default_experiment_is_said_in_seconds_without_option_wrappers() {
        let d = tb_fmi::import::description::DefaultExperiment {
            start_time: Some(0.0),
            stop_time: Some(100.0),
            step_size: Some(0.001),
            tolerance: None,
        };
        assert_eq!(
            super::default_experiment(&d),
            "start 0 s, stop 100 s, step 0.001 s"
        );
    }
}
