//! `twinbench run model.fmu`: one FMU on its own, as `fmpy simulate` runs it. The run is a
//! system of one instance (named after the model identifier) that twinbench writes for
//! itself: the FMU's default experiment (or `--start`, `--stop`, `--step`,
//! `--output-interval`, `--tolerance`), every output recorded under its own name in FMPy's
//! column order, and an input file (`--input`) whose columns drive the inputs of the same
//! names (a column without a unit takes its input's). Everything else (checks, messages,
//! the summary, `--out`, `--set`, `--isolate`, `--trace-fmi`) is `run`'s.

use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use tb_cosim::SystemFile;
use tb_fmi::import::description::{ModelDescription, ScalarVariable};
use tb_fmi::import::description3::Fmi3Type;
use tb_fmi::{Causality, FmuCache, Interface, LoadedFmu, ScalarType};

/// The name of the input file's replay in the system (never an instance's: those are C
/// identifiers, this is not one).
const INPUT: &str = "input-file";

/// The options of one FMU's run: `twinbench run model.fmu`'s (the command line's options
/// convert into this) and the Python package's `run` (every option at its default).
#[derive(Clone, Debug, Default)]
pub struct FmuRun {
    /// The FMU.
    pub system: PathBuf,
    /// The start time [s] (default: its DefaultExperiment's, else 0).
    pub start: Option<f64>,
    /// The stop time [s] (default: its DefaultExperiment's, else start + 1).
    pub stop: Option<f64>,
    /// The communication step [s] (default: FMPy's, [`default_step`]).
    pub step: Option<f64>,
    /// Record every this many seconds (a whole number of steps; alone, the step too).
    pub output_interval: Option<f64>,
    /// An input file (CSV or MDF 4, FMPy's format) whose columns drive the inputs.
    pub input: Option<PathBuf>,
    /// The interface to run it through (default: Co-Simulation when the FMU has it).
    pub interface: Option<Interface>,
    /// Model Exchange: a row just before and just after each event too.
    pub record_events: bool,
    /// The instance runs in a worker process (`--isolate`).
    pub isolated: bool,
}

impl FmuRun {
    /// The FMU at `system` with every option at its default.
    pub fn new(system: impl Into<PathBuf>) -> Self {
        FmuRun {
            system: system.into(),
            ..FmuRun::default()
        }
    }
}

/// Whether `path` names an FMU (by its extension, as FMPy decides).
pub fn is_fmu(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("fmu"))
}

/// The options that only a run of one FMU takes, refused with a system file.
pub fn refuse_fmu_options(args: &FmuRun) -> anyhow::Result<()> {
    let given = [
        ("--start", args.start.is_some()),
        ("--stop", args.stop.is_some()),
        ("--step", args.step.is_some()),
        ("--output-interval", args.output_interval.is_some()),
        ("--input", args.input.is_some()),
        ("--interface", args.interface.is_some()),
        ("--record-events", args.record_events),
    ];
    if let Some((name, _)) = given.iter().find(|(_, on)| *on) {
        bail!(
            "{name} is for running one FMU (`twinbench run model.fmu {name} ...`); {} is a system: its [experiment] and [[replay]] say this",
            args.system.display()
        );
    }
    Ok(())
}

/// The system of one FMU run alone, and its instance's name.
pub fn system(args: &FmuRun, cache: &FmuCache) -> anyhow::Result<(SystemFile, String)> {
    let fmu_path = tb_files::absolute(&args.system);
    let fmu = cache.load(&fmu_path)?;
    let md = &fmu.description;
    let interface = args.interface.unwrap_or_else(|| fmu.default_interface());
    fmu.check_interface(interface)
        .map_err(|why| anyhow::anyhow!("--interface {interface}: {}: {why}", fmu_path.display()))?;
    if args.record_events && args.isolated && interface == Interface::ModelExchange {
        bail!(
            "--record-events with --isolate: an isolated Model Exchange instance integrates in its worker and records no event rows yet; run without --isolate for event rows"
        );
    }
    let instance = md
        .model_identifier(interface)
        .unwrap_or(fmu.model_identifier())
        .to_string();
    let mut connections = Vec::new();
    let mut replay = String::new();
    if let Some(input) = &args.input {
        let file = tb_files::absolute(input);
        for column in input_columns(&file)? {
            let sv = input_variable(md, &column, &file)?;
            connections.push(quoted(&format!(
                "{INPUT}.{column} -> {instance}.{}",
                sv.name
            )));
        }
        replay = format!(
            "[[replay]]\nname = {}\nfile = {}\nbasis = \"time\"\n\n",
            quoted(INPUT),
            quoted(&file.to_string_lossy())
        );
    }
    let recorded: Vec<String> = outputs(md)
        .iter()
        .map(|v| quoted(&format!("{instance}.{}", v.name)))
        .collect();
    let text = format!(
        "connections = [{}]\n\n[fmus]\n{} = {}\n\n[[instance]]\nname = {}\nfmu = {}\ninterface = {}\n\n{replay}{}[record]\nsignals = [{}]\ndecimation = {}\n",
        connections.join(", "),
        quoted(&instance),
        quoted(&fmu_path.to_string_lossy()),
        quoted(&instance),
        quoted(&instance),
        quoted(interface.name()),
        experiment(args, &fmu, interface)?,
        recorded.join(", "),
        decimation(args)?,
    );
    let file = SystemFile::parse(&text, &fmu_path)?;
    Ok((file, instance))
}

/// A TOML basic string.
fn quoted(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The columns FMPy's `simulate` writes: the outputs (but a variable named `time`), Strings
/// and Binaries left out, grouped by type as FMPy's recorder groups them (FMI 2.0: Real,
/// Integer and Enumeration, Boolean; FMI 3.0: Float32 … UInt64 with Enumerations among the
/// Int64s, Boolean), each group in model order. An FMI 3.0 array is one column per element.
pub fn outputs(md: &ModelDescription) -> Vec<&ScalarVariable> {
    // An FMI 3.0 `<Alias>` shares its value (type, value reference, element) with a
    // variable declared before it; FMPy lists aliases after every declared variable.
    let mut declared = std::collections::HashSet::new();
    let mut outputs: Vec<(usize, bool, &ScalarVariable)> = Vec::new();
    for v in &md.variables {
        let alias = v
            .fmi3
            .as_ref()
            .is_some_and(|s| !declared.insert((s.ty, s.vr, s.index)));
        if v.causality != Causality::Output || v.name == "time" {
            continue;
        }
        if let Some(g) = fmpy_group(v) {
            outputs.push((g, alias, v));
        }
    }
    // Stable: model order within a group, aliases last.
    outputs.sort_by_key(|(g, alias, _)| (*g, *alias));
    outputs.into_iter().map(|(_, _, v)| v).collect()
}

/// FMPy's recorder group of a variable's type (None: not recorded).
fn fmpy_group(v: &ScalarVariable) -> Option<usize> {
    if let Some(slot) = &v.fmi3 {
        use Fmi3Type::*;
        return match slot.ty {
            Float32 => Some(0),
            Float64 => Some(1),
            Int8 => Some(2),
            UInt8 => Some(3),
            Int16 => Some(4),
            UInt16 => Some(5),
            Int32 => Some(6),
            UInt32 => Some(7),
            Int64 | Enumeration => Some(8),
            UInt64 => Some(9),
            Boolean => Some(10),
            String | Binary => None,
        };
    }
    match v.ty {
        ScalarType::Real => Some(0),
        ScalarType::Integer | ScalarType::Enumeration => Some(1),
        ScalarType::Boolean => Some(2),
        ScalarType::String => None,
    }
}

/// `[experiment]` from the options, else the FMU's default experiment, else FMPy's
/// defaults (start 0, stop start + 1 s; the step: see [`default_step`]).
fn experiment(args: &FmuRun, fmu: &LoadedFmu, interface: Interface) -> anyhow::Result<String> {
    let de = fmu.description.default_experiment.unwrap_or_default();
    let start = args.start.or(de.start_time).unwrap_or(0.0);
    let stop = args.stop.or(de.stop_time).unwrap_or(start + 1.0);
    for (name, v) in [("--start", start), ("--stop", stop)] {
        if !v.is_finite() {
            bail!("{name} {v}: a time is a finite number of seconds");
        }
    }
    if stop <= start {
        bail!(
            "the run would end at {} s, not after its start at {} s (--start, --stop, or the FMU's DefaultExperiment)",
            tb_files::number(stop),
            tb_files::number(start)
        );
    }
    let step = match args.step.or(args.output_interval) {
        Some(h) => h,
        None => default_step(fmu, interface, start, stop),
    };
    if !(step.is_finite() && step > 0.0) {
        bail!(
            "--step {}: a step is a positive number of seconds",
            tb_files::number(step)
        );
    }
    Ok(format!(
        "[experiment]\nstart = {start:?}\nstop = {stop:?}\nstep = {step:?}\n\n"
    ))
}

/// The step FMPy's `simulate` takes when none is given: Co-Simulation, the FMU's
/// `fixedInternalStepSize` (FMI 3.0), else its DefaultExperiment step, doubled until the run has
/// at most 1000 of them, else FMPy's automatic interval (500 to 1000 steps of a round
/// number); Model Exchange, 10^(round(log10 T) - 3) doubled likewise.
pub fn default_step(fmu: &LoadedFmu, interface: Interface, start: f64, stop: f64) -> f64 {
    let t = stop - start;
    let at_most_1000 = |mut h: f64| {
        while t / h > 1000.0 {
            h *= 2.0;
        }
        h
    };
    let md = &fmu.description;
    if interface == Interface::ModelExchange {
        return at_most_1000(10f64.powf(t.log10().round_ties_even() - 3.0));
    }
    let declared = md
        .co_simulation
        .as_ref()
        .and_then(|c| c.fixed_internal_step_size)
        .or(md.default_experiment.and_then(|d| d.step_size));
    match declared {
        Some(h) if h > 0.0 => at_most_1000(h),
        _ => auto_interval(t),
    }
}

/// FMPy's `auto_interval`: a round step that divides `t` into 500 to 1000 steps.
fn auto_interval(t: f64) -> f64 {
    let mut h = 10f64.powf(t.log10().round_ties_even() - 3.0);
    let n = t / h;
    if n >= 2500.0 {
        h *= 5.0;
    } else if n >= 2000.0 {
        h *= 4.0;
    } else if n >= 1000.0 {
        h *= 2.0;
    } else if n <= 200.0 {
        h /= 5.0;
    } else if n <= 250.0 {
        h /= 4.0;
    } else if n <= 500.0 {
        h /= 2.0;
    }
    h
}

/// Rows recorded every `--output-interval / --step` steps (a whole number).
fn decimation(args: &FmuRun) -> anyhow::Result<usize> {
    let (Some(interval), Some(step)) = (args.output_interval, args.step) else {
        return Ok(1);
    };
    let k = interval / step;
    if !(k.is_finite() && k >= 1.0 && (k - k.round()).abs() < 1e-9 * k) {
        bail!(
            "--output-interval {} is not a whole number of steps of {} s",
            tb_files::number(interval),
            tb_files::number(step)
        );
    }
    Ok(k.round() as usize)
}

/// The input file's columns other than its time (named `time`, else the first), as FMPy
/// reads an input file.
fn input_columns(file: &Path) -> anyhow::Result<Vec<String>> {
    // Only the time is parsed here; the replay reads the columns.
    let table = match tb_table::is_mdf(file) {
        true => tb_table::Table::read_any(file),
        false => tb_table::Table::read_path_keeping(file, &|k, _| k == 0),
    }
    .with_context(|| format!("--input {}", file.display()))?;
    let header = table.names();
    let time = header.iter().position(|n| n == "time").unwrap_or(0);
    Ok(header
        .iter()
        .cloned()
        .enumerate()
        .filter(|(k, _)| *k != time)
        .map(|(_, n)| n)
        .collect())
}

/// The input a column of the input file drives: the FMU's input of that name.
fn input_variable<'a>(
    md: &'a ModelDescription,
    column: &str,
    file: &Path,
) -> anyhow::Result<&'a ScalarVariable> {
    let inputs: Vec<&str> = md
        .variables_of(Causality::Input)
        .map(|v| v.name.as_str())
        .collect();
    match md.variable(column) {
        Some(v) if v.causality == Causality::Input => Ok(v),
        Some(v) => bail!(
            "--input {}: column '{column}' is {} {}, not an input of the FMU (inputs: {})",
            file.display(),
            v.variability,
            v.causality,
            list(&inputs)
        ),
        None => bail!(
            "--input {}: column '{column}' is no variable of the FMU; its inputs: {}",
            file.display(),
            list(&tb_fmi::import::description::closest(
                column,
                inputs.iter().copied(),
                inputs.len()
            ))
        ),
    }
}

fn list(names: &[&str]) -> String {
    match names.is_empty() {
        true => "none".into(),
        false => names.join(", "),
    }
}

/// The recorded columns under the FMU's own names (`h`, not `BouncingBall.h`), as FMPy
/// writes them.
pub fn own_names(recording: &mut tb_table::Table, instance: &str) -> anyhow::Result<()> {
    let prefix = format!("{instance}.");
    let renames: Vec<(usize, String)> = recording
        .names()
        .iter()
        .enumerate()
        .filter_map(|(k, n)| n.strip_prefix(&prefix).map(|own| (k, own.to_string())))
        .collect();
    recording.rename_many(&renames)?;
    Ok(())
}
