//! `twinbench run`: run a system file.

pub use crate::bench::set_parameter;
use anyhow::Context;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::{LoadOptions, Plan, Simulation};
use tb_fmi::FmuCache;

pub use super::run_args::RunArgs;

/// A run that failed: what it recorded up to the failure is kept, in a file named as
/// incomplete beside `--out` (a complete result there from an earlier run stays), and said
/// so in the message and, with `--json`, in a document with `"complete": false`.
/// `what`: "failed", or "ended early" (Ctrl-C).
fn failed_run(
    args: &RunArgs,
    sim: &Simulation,
    error: tb_cosim::SystemError,
    what: &str,
) -> anyhow::Error {
    let error = anyhow::Error::new(error);
    let rows = sim.recording().len();
    let reached = sim.recording().column_at(0).last().copied();
    let mut kept = None;
    if let (Some(out), Some(t)) = (&args.out, reached) {
        let partial = incomplete_path(out);
        match sim.recording().write_any(&partial) {
            Ok(()) => kept = Some((partial, t)),
            Err(e) => eprintln!(
                "warning: the rows recorded before the failure could not be written to {}: {e}",
                partial.display()
            ),
        }
    }
    if args.json {
        let j = serde_json::json!({
            "system": args.system,
            "complete": false,
            "error": format!("{error:#}"),
            "recorded_rows": rows,
            "recorded_until": reached,
            "out": kept.as_ref().map(|k| &k.0),
        });
        if let Ok(text) = serde_json::to_string_pretty(&j) {
            let _ = super::json::print(&text);
        }
    }
    match kept {
        Some((path, t)) => error.context(format!(
            "the run {what}; the {rows} rows recorded up to t = {} s are in {} (incomplete)",
            tb_files::number(t),
            path.display()
        )),
        None => error,
    }
}

/// `out.csv` -> `out.incomplete.csv` (the format kept by the extension).
pub fn incomplete_path(out: &Path) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match out.extension() {
        Some(ext) => format!("{stem}.incomplete.{}", ext.to_string_lossy()),
        None => format!("{stem}.incomplete"),
    };
    out.with_file_name(name)
}

/// Parse `name=value` into a TOML value: an integer, a number, a boolean, else a string
/// (surrounding double quotes removed); the variable's type decides whether it fits.
pub fn parse_assignment(s: &str) -> anyhow::Result<(String, toml::Value)> {
    let (name, value) = s
        .split_once('=')
        .with_context(|| format!("--set '{s}': expected instance.variable=value"))?;
    let value = value.trim();
    let v = if let Ok(i) = value.parse::<i64>() {
        toml::Value::Integer(i)
    } else if let Ok(x) = value.parse::<f64>() {
        toml::Value::Float(x)
    } else if let Ok(b) = value.parse::<bool>() {
        toml::Value::Boolean(b)
    } else {
        let text = value
            .strip_prefix('"')
            .and_then(|v| v.strip_suffix('"'))
            .unwrap_or(value);
        toml::Value::String(text.to_string())
    };
    Ok((name.trim().to_string(), v))
}

pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let cache = Arc::new(FmuCache::temporary(args.keep_extracted)?);
    if args.keep_extracted {
        eprintln!("unpacked FMUs kept in {}", cache.root().display());
    }
    let options = load_options(&args)?;
    let (system, instance) = load_plan(&args, cache, &options)?;
    check_outputs(&args, &system)?;
    for w in &system.warnings {
        eprintln!("warning: {w}");
    }
    for n in &system.notes {
        eprintln!("note: {n}");
    }
    let order: Vec<String> = system
        .order
        .iter()
        .map(|&k| system.unit_name(k).to_string())
        .collect();
    let mut sim = Simulation::new(system.clone())?;
    if let Some(instance) = &instance {
        crate::run_fmu::own_names(sim.recording_mut(), instance)?;
    }
    sim.record_events(args.record_events)?;
    apply_parameters(&args, &system, &mut sim, instance.as_deref())?;
    let (interrupt, paced) = observe(&args, &system, &mut sim)?;
    // A run that completed keeps its results even when an instance then fails to end.
    let trace = options.trace.as_ref().map(|t| t.sink.clone());
    let result = sim.run();
    // Dropping the pacer publishes its report.
    drop(sim.take_observers());
    // The results are written at normal priority, on any CPU.
    let paced = paced.map(|(report, prepared)| {
        let attempts = prepared.attempts.clone();
        prepared.restore();
        let report = report.lock().unwrap_or_else(|p| p.into_inner()).take();
        (report, attempts)
    });
    // While the results are written a signal ends the process at once, their temporary
    // files removed (nothing half-written stays).
    super::interrupt::install_default();
    if let (Some(sink), Some(path)) = (&trace, &args.trace_fmi) {
        // The instances are freed first so that their last calls are in the trace; a
        // failed run keeps its trace (it is what the trace is for).
        sim.free_instances();
        sink.finish()
            .with_context(|| format!("--trace-fmi: cannot write {}", path.display()))?;
        eprintln!("FMI call trace written to {}", path.display());
    }
    let (summary, after_run) = match result {
        Ok(s) => (s, None),
        Err(tb_cosim::SystemError::AfterRun { summary, error }) => (*summary, Some(error)),
        Err(e) if interrupt.load(std::sync::atomic::Ordering::SeqCst) => {
            let e = failed_run(&args, &sim, e, "ended early");
            return Err(super::interrupt::RunInterrupted(super::message(&e)).into());
        }
        Err(e) => return Err(failed_run(&args, &sim, e, "failed")),
    };
    if let Some(out) = &args.out {
        sim.recording()
            .write_any(out)
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    if let Some(e) = after_run {
        if let Some(out) = &args.out {
            eprintln!(
                "results written to {} (the run was complete)",
                out.display()
            );
        }
        return Err(anyhow::Error::new(*e).context(format!(
            "the run completed ({}), then ending an instance failed",
            summary.stopped_by
        )));
    }
    print_summary(&args, &system, &sim, &summary, &order, &paced)
}

/// How the system's instances are run (`--native`, `--isolate`, `--trace-fmi`, ...).
fn load_options(args: &RunArgs) -> anyhow::Result<LoadOptions> {
    let timeout = tb_cosim::isolated::watchdog(args.worker_timeout)
        .map_err(|m| anyhow::anyhow!("--worker-timeout: {m}"))?;
    let options = LoadOptions {
        native: args.native,
        native_models: crate::registry::native_models(),
        isolate: args.isolate.is_some(),
        isolation: tb_cosim::isolated::IsolationOptions {
            timeout,
            mode: args.isolate.map(|m| m.mode()).unwrap_or_default(),
            limits: args.worker_limits,
            ..Default::default()
        },
        trace: args
            .trace_fmi
            .as_ref()
            .map(|path| tb_cosim::trace::TraceOptions {
                sink: tb_cosim::trace::TraceSink::new(Box::new(tb_cosim::trace::TraceFile::new(
                    path,
                ))),
                instances: args.trace_instances.clone(),
            }),
        tolerance: args.tolerance,
        step_convention: args.step_convention,
    };
    if let Some(t) = args.tolerance {
        if !(t > 0.0 && t < 1.0) {
            anyhow::bail!(
                "--tolerance {}: a relative tolerance is a number between 0 and 1 (e.g. 1e-6)",
                tb_files::number(t)
            );
        }
    }
    Ok(options)
}

/// The plan of the system file, SSP package or single FMU (with its instance's name).
fn load_plan(
    args: &RunArgs,
    cache: Arc<FmuCache>,
    options: &LoadOptions,
) -> anyhow::Result<(Arc<Plan>, Option<String>)> {
    // One FMU on its own: a system of one instance, its recorded columns under the FMU's
    // own names and `--set` naming the FMU's variables.
    let alone = crate::run_fmu::is_fmu(&args.system);
    Ok(match alone {
        true => {
            let (file, instance) = crate::run_fmu::system(&args.fmu_run(), &cache)?;
            let plan = Plan::compile(file, &args.system, cache, options)?;
            (Arc::new(plan), Some(instance))
        }
        false => {
            crate::run_fmu::refuse_fmu_options(&args.fmu_run())?;
            (
                Arc::new(Plan::load_with(&args.system, cache, options)?),
                None,
            )
        }
    })
}

/// Before the run: `--out`, where a failed run keeps its rows, and `--trace-fmi` replace
/// no input, device, link or folder.
fn check_outputs(args: &RunArgs, system: &Plan) -> anyhow::Result<()> {
    if let Some(out) = &args.out {
        // Before the run: a result must not replace a device, a link, a folder or an input.
        let files = system.input_files();
        let mut inputs: Vec<&std::path::Path> = vec![args.system.as_path()];
        inputs.extend(files.iter().map(|p| p.as_path()));
        tb_table::check_output(out, &inputs)?;
        // Where a failed run keeps its rows (M9): never an input of the run (the system,
        // an --input file, an FMU), a folder or a link either.
        let partial = incomplete_path(out);
        inputs.push(out);
        tb_table::check_output(&partial, &inputs).with_context(|| {
            format!(
                "{}: where a failed run would keep its rows (choose another --out)",
                partial.display()
            )
        })?;
    }
    // The trace file is created on its first line, after this check.
    if let Some(trace) = &args.trace_fmi {
        let files = system.input_files();
        let mut inputs: Vec<&std::path::Path> = vec![args.system.as_path()];
        inputs.extend(files.iter().map(|p| p.as_path()));
        inputs.extend(args.out.as_deref());
        tb_table::check_output(trace, &inputs).context("--trace-fmi")?;
    }
    Ok(())
}

/// A study's answer (`--params`), then `--set`, on the instances before the run.
fn apply_parameters(
    args: &RunArgs,
    system: &Plan,
    sim: &mut Simulation,
    instance: Option<&str>,
) -> anyhow::Result<()> {
    // A study's answer first, so that a `--set` of the same parameter wins.
    let answer = match &args.params {
        Some(path) => {
            let result = crate::validate::read_result(path)?;
            result
                .parameters_final
                .iter()
                .map(|(name, value)| {
                    (
                        format!("--params {}: {name}", path.display()),
                        name.clone(),
                        toml::Value::Float(*value),
                    )
                })
                .collect()
        }
        None => Vec::new(),
    };
    let assignments = args
        .set
        .iter()
        .map(|s| parse_assignment(s).map(|(n, v)| (format!("--set {s}"), n, v)))
        .collect::<anyhow::Result<Vec<_>>>()?;
    for (what, name, value) in answer.into_iter().chain(assignments) {
        let name = match instance {
            // The FMU's own variable name; `instance.variable` as in a system is taken too
            // when the FMU has no variable of that whole name (red team M17).
            Some(i) => {
                let own = format!("{i}.{name}");
                match name.strip_prefix(&format!("{i}.")) {
                    Some(_)
                        if system.parameter(&own).is_err() && system.parameter(&name).is_ok() =>
                    {
                        name
                    }
                    _ => own,
                }
            }
            None => name,
        };
        set_parameter(system, sim, &name, &value).with_context(|| what.clone())?;
    }
    Ok(())
}

/// What a paced run leaves: the pacer's report and what the system gave.
type Paced = Option<(
    Option<tb_cosim::pacing::PacingReport>,
    Vec<tb_cosim::pacing::Attempt>,
)>;
/// The pacer's report slot and what was asked of the system, before the run.
type Pacing = Option<(
    Arc<std::sync::Mutex<Option<tb_cosim::pacing::PacingReport>>>,
    tb_cosim::pacing::Prepared,
)>;

/// The CLI's observers of the run: Ctrl-C (or SIGTERM) ends it keeping its rows, a
/// progress bar on a terminal, the pacer of `--realtime`. Returns the Ctrl-C flag.
fn observe(
    args: &RunArgs,
    system: &Plan,
    sim: &mut Simulation,
) -> anyhow::Result<(Arc<std::sync::atomic::AtomicBool>, Pacing)> {
    let interrupt = super::interrupt::run_flag()?;
    sim.observe(Box::new(super::progress::StopRunOnFlag(interrupt.clone())));
    let lines = super::progress::RunBar::lines_for_cli(args.json);
    if std::io::stderr().is_terminal() || lines.is_some() {
        let until = match &system.stop {
            tb_cosim::Stop::Time(t) => format!("of {} s", tb_files::number(*t)),
            tb_cosim::Stop::When {
                condition,
                max_time,
            } => format!(
                "until {condition} (at most {} s)",
                tb_files::number(*max_time)
            ),
        };
        sim.observe(Box::new(super::progress::RunBar::new(until, lines)));
    }
    // A paced run: the pacer last, so that each step's deadline covers the other observers'
    // work too; the system asked for priority, locked memory and a CPU just before the run.
    let paced = args.realtime.map(|factor| {
        use tb_cosim::pacing;
        let pacer = pacing::Pacer::new(pacing::Monotonic, factor, args.overrun)
            .with_interrupt(interrupt.clone());
        let (observer, report) = pacing::PacedRun::new(pacer);
        sim.observe(Box::new(observer));
        let prepared = pacing::prepare(&pacing::RealtimeRequest {
            fifo_priority: (args.realtime_priority > 0).then_some(args.realtime_priority),
            lock_memory: true,
            cpu: args.realtime_cpu.unwrap_or(pacing::CpuRequest::Last),
        });
        for a in &prepared.attempts {
            eprintln!("{}", a.line());
        }
        (report, prepared)
    });
    Ok((interrupt, paced))
}

/// The run's summary: JSON with `--json`, else lines.
fn print_summary(
    args: &RunArgs,
    system: &Plan,
    sim: &Simulation,
    summary: &tb_cosim::RunSummary,
    order: &[String],
    paced: &Paced,
) -> anyhow::Result<()> {
    let rtf = summary.simulated_time / summary.wall_time.max(1e-12);
    if args.json {
        let j = serde_json::json!({
            "system": args.system,
            "complete": true,
            "steps": summary.steps,
            "simulated_time": summary.simulated_time,
            "wall_time": summary.wall_time,
            "real_time_factor": rtf,
            "ns_per_step": summary.wall_time * 1e9 / summary.steps.max(1) as f64,
            "lap_time": super::lap_time(summary, system),
            "reported": summary.reported.iter().cloned().collect::<std::collections::BTreeMap<_, _>>(),
            "stopped_by": summary.stopped_by,
            "order": order,
            "backends": system.instances.iter().map(|i| (i.name.clone(), i.factory.kind())).collect::<std::collections::BTreeMap<_, _>>(),
            "recorded_rows": sim.recording().len(),
            "out": args.out,
        });
        let mut j = j;
        if let Some((report, attempts)) = &paced {
            let mut r = serde_json::to_value(report)?;
            r["system"] = serde_json::to_value(attempts)?;
            j["realtime"] = r;
        }
        super::json::print(&serde_json::to_string_pretty(&j)?)?;
    } else {
        println!("system          {}", args.system.display());
        println!("stopped by      {}", summary.stopped_by);
        println!("stepping order  {}", order.join(", "));
        println!("steps           {}", summary.steps);
        println!("simulated time  {:.3} s", summary.simulated_time);
        if let Some(l) = super::lap_time(summary, system) {
            println!("lap time        {l:.3} s");
        }
        println!(
            "wall time       {:.3} s ({rtf:.0}x real time, {:.0} ns per macro step)",
            summary.wall_time,
            summary.wall_time * 1e9 / summary.steps.max(1) as f64
        );
        if let Some((report, attempts)) = &paced {
            if let Some(r) = report {
                println!("{}", r.text());
            }
            let got: Vec<String> = attempts
                .iter()
                .map(|a| {
                    let how = if a.obtained { "obtained" } else { "refused" };
                    format!("{} {how}", a.asked)
                })
                .collect();
            println!("real-time setup {}", got.join("; "));
        }
        if let Some(out) = &args.out {
            println!(
                "results         {} ({} rows)",
                out.display(),
                sim.recording().len()
            );
        }
    }
    Ok(())
}
