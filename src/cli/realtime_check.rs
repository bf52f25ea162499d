//! `twinbench realtime-check MODEL.fmu`: is the FMU fit for a real-time target? Exits 0
//! when every item is clean, 1 when one is not (a bench's CI can gate on it), 2 on an error.

use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RealtimeCheckArgs {
    /// The FMU (FMI 2.0 or 3.0 Co-Simulation), or a bench's system file (`.toml`): then
    /// every FMU of the bench, each with the inputs and parameters its first instance has
    /// on the bench's run.
    pub fmu: PathBuf,
    /// Communication step [s] (default: the FMU's default experiment's, else 1e-3).
    #[arg(long, value_name = "SECONDS")]
    pub step: Option<f64>,
    /// Simulated time of one pass [s] (default: to the input file's end, else the default
    /// experiment's stop, else 10).
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// The inputs over time: CSV or MDF 4, `time` (else the first column) and columns named
    /// as the FMU's Real inputs (default: every input held at its start value).
    #[arg(long, value_name = "FILE")]
    pub input: Option<PathBuf>,
    /// Passes over the duration, the instance reset between them.
    #[arg(long, default_value_t = 10)]
    pub passes: u32,
    /// Judge the slowest step against this [s] (without it the step's time is measured,
    /// not judged: a desktop's clock is not the target's).
    #[arg(long, value_name = "SECONDS")]
    pub budget: Option<f64>,
    /// Also count doStep's instructions per step under valgrind's callgrind (slow; the most
    /// expensive step must stay within 3 times the mean).
    #[arg(long)]
    pub instructions: bool,
    /// How the worker runs: confined (default) or crash isolation only.
    #[arg(long, value_enum, default_value = "confined")]
    pub isolate: super::IsolateMode,
    /// The longest the whole check may take [s].
    #[arg(long, default_value_t = 600.0, value_name = "SECONDS")]
    pub timeout: f64,
    /// A library the worker loads (RTLD_GLOBAL) before the FMU's, e.g. libpython for an
    /// FMU built with pythonfmu (repeatable).
    #[arg(long, value_name = "LIB")]
    pub preload: Vec<PathBuf>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The exit code of a check that ran and found an item not clean.
pub const EXIT_NOT_CLEAN: u8 = 1;
/// The exit code of a check that could not run.
pub const EXIT_ERROR: u8 = 2;

pub fn run(args: RealtimeCheckArgs) -> anyhow::Result<bool> {
    let bench = args.fmu.extension().is_some_and(|e| e == "toml");
    if bench && args.input.is_some() {
        anyhow::bail!("--input: a bench's FMUs take their inputs from the bench's run");
    }
    let options = crate::realtime_check::Options {
        fmu: args.fmu.clone(),
        step: args.step,
        duration: args.duration,
        input: args.input,
        passes: args.passes,
        budget: args.budget,
        instructions: args.instructions,
        mode: args.isolate.mode(),
        timeout: args.timeout,
        preload: args.preload,
        worker_exe: None,
    };
    if bench {
        let reports = crate::realtime_check::check_bench(&args.fmu, &options)?;
        if args.json {
            super::json::print(&serde_json::to_string_pretty(&reports)?)?;
        } else {
            for r in &reports {
                println!("instance {}:", r.instance);
                for l in r.report.lines() {
                    println!("{l}");
                }
            }
        }
        return Ok(reports.iter().all(|r| r.report.clean));
    }
    let report = crate::realtime_check::check(&options)?;
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&report)?)?;
    } else {
        for l in report.lines() {
            println!("{l}");
        }
    }
    Ok(report.clean)
}
