//! `twinbench realtime-check`: whether an FMU is fit for a real-time target, for any FMU
//! (a supplier's is run isolated, as for a run). The measurement is
//! [`tb_cosim::realtime`]'s; this module chooses the steps and the inputs, adds the
//! instruction count (callgrind) and judges.

use anyhow::{bail, Context};
use serde::Serialize;
use std::path::{Path, PathBuf};
use tb_cosim::backend::RunAs;
use tb_cosim::isolated::confine::Mode;
use tb_cosim::isolated::IsolationOptions;
use tb_cosim::realtime::report::{self, Instructions, Item};
use tb_cosim::realtime::{CheckSpec, Inputs, Measurement};
use tb_fmi::import::description::Interface;
use tb_fmi::{FmuCache, LoadedFmu};

/// What to check.
#[derive(Clone, Debug)]
pub struct Options {
    pub fmu: PathBuf,
    /// The communication step [s]; default: the FMU's default experiment's, else 1 ms.
    pub step: Option<f64>,
    /// How long one pass runs [s]; default: to the input file's end, else the default
    /// experiment's stop, else 10 s.
    pub duration: Option<f64>,
    /// A CSV or MDF 4 file: `time` (else the first column) and the FMU's Real inputs by name.
    pub input: Option<PathBuf>,
    /// Passes over the duration (the step's time distribution is taken over all).
    pub passes: u32,
    /// The longest step allowed [s]; without it the step's time is measured, not judged.
    pub budget: Option<f64>,
    /// Also count `doStep`'s instructions per step under valgrind's callgrind.
    pub instructions: bool,
    /// Confined (the default) or crash isolation only.
    pub mode: Mode,
    /// The longest the worker may take for the whole check [s].
    pub timeout: f64,
    /// Libraries the worker loads before the FMU's (libpython for a pythonfmu FMU).
    pub preload: Vec<PathBuf>,
    /// The `twinbench` executable the worker runs (default: this one, or
    /// `TWINBENCH_WORKER_EXE`): only it counts allocations.
    pub worker_exe: Option<PathBuf>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            fmu: PathBuf::new(),
            step: None,
            duration: None,
            input: None,
            passes: 10,
            budget: None,
            instructions: false,
            mode: Mode::Confined,
            timeout: 600.0,
            preload: Vec::new(),
            worker_exe: None,
        }
    }
}

impl Options {
    /// The numbers given, checked before anything is loaded or run.
    fn check_numbers(&self) -> anyhow::Result<()> {
        let bad = |x: Option<f64>| x.filter(|x| !(x.is_finite() && *x > 0.0));
        if let Some(s) = bad(self.step) {
            bail!("--step {s}: expected a step of more than 0 s");
        }
        for (name, v) in [("--budget", self.budget), ("--duration", self.duration)] {
            if let Some(x) = bad(v) {
                bail!("{name} {x}: expected a positive number of seconds");
            }
        }
        Ok(())
    }
}

/// What the check found.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub fmu: PathBuf,
    pub model: String,
    pub fmi_version: String,
    pub step: f64,
    pub duration: f64,
    pub steps_per_pass: u64,
    pub inputs: Vec<String>,
    /// Where the inputs come from: a file, a bench's run; none: held at their starts.
    pub input_file: Option<String>,
    pub isolation: String,
    pub measurement: Measurement,
    pub instructions: Option<Instructions>,
    pub items: Vec<Item>,
    pub clean: bool,
}

/// One FMU of a bench and its report (a bench's check, as JSON: a list of these).
#[derive(Clone, Debug, Serialize)]
pub struct InstanceReport {
    /// The first instance of the FMU, whose inputs it was checked with.
    pub instance: String,
    pub report: Report,
}

impl Report {
    /// The report as text lines.
    pub fn lines(&self) -> Vec<String> {
        let mut out = vec![
            format!(
                "realtime-check {} (model {}, FMI {} Co-Simulation, {} worker)",
                self.fmu.display(),
                self.model,
                self.fmi_version,
                self.isolation
            ),
            format!(
                "  {} steps of {} s ({} s) × {} passes after initialisation; inputs: {}",
                self.steps_per_pass,
                tb_files::number(self.step),
                tb_files::number(self.duration),
                self.measurement.passes,
                match (&self.input_file, self.inputs.len()) {
                    (Some(f), n) => format!("{n} from {f}"),
                    (None, 0) => "none".into(),
                    (None, n) => format!("{n} held at their start values"),
                }
            ),
        ];
        out.extend(report::lines(&self.items));
        for n in &self.measurement.notes {
            out.push(format!("  note: {n}"));
        }
        let failed: Vec<&str> = self
            .items
            .iter()
            .filter(|i| !i.verdict.passes())
            .map(|i| i.name.as_str())
            .collect();
        out.push(match failed.is_empty() {
            true => "verdict: clean".into(),
            false => format!("verdict: not clean ({})", failed.join(", ")),
        });
        out
    }
}

/// Checks `o.fmu`.
pub fn check(o: &Options) -> anyhow::Result<Report> {
    o.check_numbers()?;
    let cache = FmuCache::temporary(false)?;
    let fmu = cache.load(&o.fmu)?;
    co_simulation(&fmu)?;
    let de = fmu.description.default_experiment.unwrap_or_default();
    let start = de.start_time.unwrap_or(0.0);
    let (inputs, names) = inputs(&fmu, o.input.as_deref())?;
    let until = match &o.input {
        Some(_) => inputs.time.last().copied(),
        None => de.stop_time,
    };
    let run = Run {
        start,
        step: o.step.or(de.step_size).unwrap_or(1e-3),
        duration: o
            .duration
            .or(until.map(|s| s - start).filter(|d| *d > 0.0))
            .unwrap_or(10.0),
        inputs,
        names,
        from: o.input.as_ref().map(|f| f.display().to_string()),
        parameters: Vec::new(),
    };
    measure_and_judge(&fmu, &o.fmu, run, o)
}

/// Every FMU of a bench (`SYSTEM.toml`), each with the inputs and parameters its first
/// instance has on the bench: the bench is run once (in this process, as `run` runs it),
/// every output recorded at every step, and each FMU then checked in a worker of its own
/// over the same time with the inputs the bench gave it.
pub fn check_bench(system: &Path, o: &Options) -> anyhow::Result<Vec<InstanceReport>> {
    o.check_numbers()?;
    let cache = std::sync::Arc::new(FmuCache::temporary(false)?);
    let mut file = tb_cosim::SystemFile::load(system)?;
    file.record = tb_cosim::config::RecordConfig {
        signals: Vec::new(),
        decimation: 1,
    };
    let plan = std::sync::Arc::new(tb_cosim::Plan::compile(
        file,
        system,
        cache,
        &tb_cosim::LoadOptions::default(),
    )?);
    let mut sim = tb_cosim::Simulation::new(plan.clone())?;
    sim.run()
        .with_context(|| format!("the bench's run ({})", system.display()))?;
    let table = sim.recording();
    let time = table
        .column("time")?
        .context("the bench's recording has no time")?
        .to_vec();
    let (start, end) = (time[0], *time.last().expect("a run records its start"));
    let mut seen = std::collections::BTreeSet::new();
    let mut reports = Vec::new();
    for (k, instance) in plan.instances.iter().enumerate() {
        if !seen.insert(instance.fmu.source.clone()) {
            continue; // one check per FMU: its first instance's inputs
        }
        co_simulation(&instance.fmu)?;
        let mut inputs = Inputs {
            time: time.clone(),
            ..Default::default()
        };
        let mut names = Vec::new();
        for c in plan
            .connections
            .iter()
            .filter(|c| c.to_unit == k && c.to_ty == tb_fmi::ScalarType::Real)
        {
            let from = table
                .column(&c.from_name)?
                .with_context(|| format!("the bench's recording has no {}", c.from_name))?;
            inputs.vrs.push(c.to_vr);
            inputs
                .columns
                .push(from.iter().map(|x| c.scale * x + c.offset).collect());
            names.push(c.to_name.clone());
        }
        let parameters = plan
            .parameters
            .iter()
            .filter(|(slot, _)| slot.unit == k)
            .filter_map(|(slot, v)| match v {
                tb_cosim::plan::ParamValue::Real(x) => Some((slot.vr, *x)),
                _ => None,
            })
            .collect();
        let run = Run {
            start,
            step: o.step.unwrap_or(plan.file.experiment.step),
            duration: o.duration.unwrap_or(end - start),
            inputs,
            names,
            from: Some(format!("the bench's run of {}", system.display())),
            parameters,
        };
        let report = measure_and_judge(&instance.fmu, &instance.fmu.source, run, o)
            .with_context(|| format!("instance {}", instance.name))?;
        reports.push(InstanceReport {
            instance: instance.name.clone(),
            report,
        });
    }
    Ok(reports)
}

fn co_simulation(fmu: &LoadedFmu) -> anyhow::Result<()> {
    if !fmu.description.supports(Interface::CoSimulation) {
        bail!(
            "{}: realtime-check steps Co-Simulation FMUs; this one has Model Exchange only (a solver of the host's would be measured with it)",
            fmu.source.display()
        );
    }
    Ok(())
}

/// One FMU's run: when, with what.
struct Run {
    start: f64,
    step: f64,
    duration: f64,
    inputs: Inputs,
    names: Vec<String>,
    /// Where the inputs come from (None: held at their starts).
    from: Option<String>,
    parameters: Vec<(u32, f64)>,
}

fn measure_and_judge(
    fmu: &LoadedFmu,
    shown: &Path,
    run: Run,
    o: &Options,
) -> anyhow::Result<Report> {
    let Run {
        start,
        step,
        duration,
        ..
    } = run;
    if !(step.is_finite() && step > 0.0) {
        bail!("--step {step}: expected a step of more than 0 s");
    }
    if !(duration.is_finite() && duration >= step) {
        bail!("--duration {duration}: expected at least one step of {step} s");
    }
    let steps = (duration / step).round() as u64;
    if steps.saturating_mul(o.passes.max(1) as u64) > 100_000_000 {
        bail!(
            "{steps} steps × {} passes: more than 10⁸ steps; shorten --duration or make --step longer",
            o.passes
        );
    }
    let md = &fmu.description;
    let outputs: Vec<u32> = md
        .variables_of(tb_fmi::Causality::Output)
        .filter(|v| v.ty == tb_fmi::ScalarType::Real)
        .map(|v| v.value_reference)
        .collect();
    let spec = CheckSpec {
        start,
        step,
        steps,
        passes: o.passes.max(1),
        inputs: run.inputs,
        outputs,
        parameters: run.parameters,
        count_syscalls: true,
    };
    let options = IsolationOptions {
        mode: o.mode,
        timeout: tb_cosim::isolated::watchdog(o.timeout)
            .map_err(|m| anyhow::anyhow!("--timeout: {m}"))?,
        preload: o.preload.iter().map(|p| tb_files::absolute(p)).collect(),
        worker_exe: o.worker_exe.clone(),
        ..Default::default()
    };
    // Co-Simulation: the FMU's default interface once `co_simulation` passed.
    let interface = RunAs::default_for(fmu);
    let measurement =
        tb_cosim::isolated::realtime_check(fmu, &options, interface, &spec).map_err(|e| {
            anyhow::anyhow!("{}: {}", shown.display(), crate::bench::message(&e.into()))
        })?;
    let instructions = match o.instructions {
        true => Some(count_instructions(fmu, &spec, &options, interface)?),
        false => None,
    };
    let items = report::judge(&measurement, step, o.budget, instructions.as_ref());
    Ok(Report {
        fmu: shown.to_path_buf(),
        model: md.model_name.clone(),
        fmi_version: md.fmi_version.clone(),
        step,
        duration,
        steps_per_pass: steps,
        inputs: run.names,
        input_file: run.from,
        isolation: match o.mode {
            Mode::Confined => "confined".into(),
            Mode::CrashOnly => "crash-only".into(),
        },
        clean: report::clean(&items),
        measurement,
        instructions,
        items,
    })
}

/// The Real inputs: from the file (columns by the inputs' names), else every Real input
/// held at its start value. Returns them and their names.
fn inputs(fmu: &LoadedFmu, file: Option<&Path>) -> anyhow::Result<(Inputs, Vec<String>)> {
    let md = &fmu.description;
    let real_inputs: Vec<&tb_fmi::import::description::ScalarVariable> = md
        .variables_of(tb_fmi::Causality::Input)
        .filter(|v| v.ty == tb_fmi::ScalarType::Real)
        .collect();
    let Some(file) = file else {
        let starts: Vec<Vec<f64>> = real_inputs
            .iter()
            .map(|v| vec![v.start_f64().unwrap_or(0.0)])
            .collect();
        return Ok((
            Inputs {
                vrs: real_inputs.iter().map(|v| v.value_reference).collect(),
                time: Vec::new(),
                columns: starts,
            },
            real_inputs.iter().map(|v| v.name.clone()).collect(),
        ));
    };
    let table =
        tb_table::Table::read_any(file).with_context(|| format!("--input {}", file.display()))?;
    let names = table.names().to_vec();
    let time_col = names.iter().position(|n| n == "time").unwrap_or(0);
    let time = table.column_at(time_col).to_vec();
    if time.windows(2).any(|w| w[1] < w[0]) || time.iter().any(|t| !t.is_finite()) {
        bail!(
            "--input {}: column '{}' is not a non-decreasing time",
            file.display(),
            names[time_col]
        );
    }
    let mut inputs = Inputs {
        time,
        ..Default::default()
    };
    let mut used = Vec::new();
    for (k, name) in names.iter().enumerate().filter(|(k, _)| *k != time_col) {
        let Some(v) = real_inputs.iter().find(|v| &v.name == name) else {
            let all: Vec<&str> = real_inputs.iter().map(|v| v.name.as_str()).collect();
            bail!(
                "--input {}: column '{name}' is not a Real input of {} (its Real inputs: {})",
                file.display(),
                fmu.source.display(),
                if all.is_empty() {
                    "none".to_string()
                } else {
                    all.join(", ")
                }
            );
        };
        let values = table.column_at(k).to_vec();
        if let Some(bad) = values.iter().position(|x| !x.is_finite()) {
            bail!(
                "--input {}: column '{name}' row {} is {} (expected a finite number)",
                file.display(),
                bad + 1,
                values[bad]
            );
        }
        inputs.vrs.push(v.value_reference);
        inputs.columns.push(values);
        used.push(name.clone());
    }
    Ok((inputs, used))
}

/// `doStep`'s instructions per step: the same check in a worker run under callgrind
/// (crash isolation only: valgrind runs neither Landlock nor the worker's seccomp filters),
/// one profile dump per `doStep`, read and removed as they come.
fn count_instructions(
    fmu: &LoadedFmu,
    spec: &CheckSpec,
    options: &IsolationOptions,
    run: RunAs,
) -> anyhow::Result<Instructions> {
    let valgrind =
        which("valgrind").context("--instructions needs valgrind (apt-get install valgrind)")?;
    let dir = tempfile::tempdir()?;

    let exe = options.resolve_exe().map_err(|m| anyhow::anyhow!(m))?;
    let do_step = if fmu.is_fmi3() {
        "fmi3DoStep"
    } else {
        "fmi2DoStep"
    };
    let script = dir.path().join("worker-under-callgrind");
    let dumps = dir.path().join("dumps");
    std::fs::create_dir(&dumps)?;
    std::fs::write(
        &script,
        format!(
            "#!/bin/sh\nexec '{}' -q --tool=callgrind --callgrind-out-file='{}/cg.%p' --dump-instr=no --collect-atstart=no --toggle-collect={do_step} --zero-before={do_step} --dump-after={do_step} '{}' \"$@\"\n",
            valgrind.display(),
            dumps.display(),
            exe.display()
        ),
    )?;
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755))?;
    let spec = CheckSpec {
        passes: 1,
        count_syscalls: false,
        ..spec.clone()
    };
    let options = IsolationOptions {
        worker_exe: Some(script),
        mode: Mode::CrashOnly,
        timeout: options.timeout.max(std::time::Duration::from_secs(60)) * 20,
        ..options.clone()
    };
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let harvest = {
        let (dumps, stop) = (dumps.clone(), stop.clone());
        std::thread::spawn(move || harvest_dumps(&dumps, &stop))
    };
    let result = tb_cosim::isolated::realtime_check(fmu, &options, run, &spec);
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    let counts = harvest.join().expect("the harvest thread does not panic")?;
    result.map_err(|e| {
        anyhow::anyhow!(
            "the check under callgrind: {}",
            crate::bench::message(&e.into())
        )
    })?;
    if counts.is_empty() {
        bail!("callgrind wrote no profile of {do_step}: is the symbol exported?");
    }
    let steps = counts.len() as u64;
    let mean = counts.iter().sum::<u64>() as f64 / steps as f64;
    let (kmax, max) = counts
        .iter()
        .copied()
        .enumerate()
        .max_by_key(|(_, c)| *c)
        .expect("not empty");
    let (kafter, after) = counts
        .iter()
        .copied()
        .enumerate()
        .skip(1)
        .max_by_key(|(_, c)| *c)
        .unwrap_or((0, counts[0]));
    let mut sorted = counts.clone();
    sorted.sort_unstable();
    Ok(Instructions {
        steps,
        mean,
        median: sorted[sorted.len() / 2],
        max,
        max_at: spec.start + kmax as f64 * spec.step,
        first: counts[0],
        max_after_first: after,
        max_after_first_at: spec.start + kafter as f64 * spec.step,
    })
}

/// Reads callgrind's dumps (`cg.<pid>.<n>`) as they come, removing each; the costs by `n`.
fn harvest_dumps(dir: &Path, stop: &std::sync::atomic::AtomicBool) -> anyhow::Result<Vec<u64>> {
    let mut by_n: std::collections::BTreeMap<u64, u64> = Default::default();
    loop {
        let last = stop.load(std::sync::atomic::Ordering::SeqCst);
        for e in std::fs::read_dir(dir)? {
            let path = e?.path();
            let name = path
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or("")
                .to_string();
            let parts: Vec<&str> = name.split('.').collect();
            let [_, _, n] = parts[..] else { continue };
            let Ok(n) = n.parse::<u64>() else { continue };
            let text = match std::fs::read_to_string(&path) {
                Ok(t) if t.contains("\ntotals:") || t.contains("\nsummary:") => t,
                // Still being written.
                _ => continue,
            };
            let total = text
                .lines()
                .find_map(|l| {
                    l.strip_prefix("totals:")
                        .or_else(|| l.strip_prefix("summary:"))
                })
                .and_then(|v| v.split_whitespace().next())
                .and_then(|v| v.parse::<u64>().ok())
                .with_context(|| format!("callgrind dump {name} has no total"))?;
            by_n.insert(n, total);
            if let Some(keep) = std::env::var_os("TWINBENCH_KEEP_CALLGRIND") {
                std::fs::copy(&path, Path::new(&keep).join(&name))?;
            }
            std::fs::remove_file(&path)?;
        }
        if last {
            return Ok(by_n.into_values().collect());
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

fn which(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")?
        .to_str()?
        .split(':')
        .map(|d| Path::new(d).join(program))
        .find(|p| p.is_file())
}
