//! Command-line interface: one module per subcommand, each with its clap `Args` and `run`.

use clap::{Parser, Subcommand};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

pub mod benchmark;
pub mod cache;
pub mod compare;
pub mod demo;
pub mod export_ssp;
pub mod export_twin;
pub mod identify;
pub mod info;
pub mod interrupt;
pub mod json;
pub mod lap;
pub mod modal;
pub mod optimize;
pub mod pack;
pub mod progress;
pub mod realtime_check;
pub mod run;
pub mod run_args;
pub mod validate;
pub mod worker;

#[derive(Parser, Debug)]
#[command(
    name = "twinbench",
    version,
    about = "Digital twin of a powertrain test bench: FMI Co-Simulation models (exports FMI 2.0 and 3.0 FMUs and SSP 1.0 packages; imports FMI 2.0 and 3.0 FMUs, Co-Simulation and Model Exchange, and SSP 1.0 packages), orchestrator, optimiser, bench analysis"
)]
pub struct Cli {
    /// More log output (repeat for more).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Write the FMUs (their libraries are built into this binary) to ~/.local/share/twinbench/fmu, or -o DIR.
    Pack(pack::PackArgs),
    /// The main job on the bundled data (packs the FMUs if needed).
    Demo(demo::DemoArgs),
    /// Time one lap of the bench (wall time, real-time factor, ns per macro step).
    Benchmark(benchmark::BenchmarkArgs),
    /// Run a system file, an SSP 1.0 package, or one FMU on its own (as fmpy simulate).
    Run(run::RunArgs),
    /// Show an FMU's capabilities and variables.
    Info(info::InfoArgs),
    /// Prepare a lap of any circuit from its measurement: target speed, track, system, study.
    Lap(lap::LapArgs),
    /// Write a system as an SSP 1.0 package (SystemStructure.ssd, FMUs under resources/).
    ExportSsp(export_ssp::ExportSspArgs),
    /// Hand on a study's fitted twin: FMUs with the answer as start values, SSP, SSV, a system file, a parameter table.
    ExportTwin(export_twin::ExportTwinArgs),
    /// Compare a simulation result with a vehicle measurement on a distance basis.
    Compare(compare::CompareArgs),
    /// Optimise the twin's parameters against a vehicle measurement (a study file).
    Optimize(optimize::OptimizeArgs),
    /// Run the fitted twin on a lap it was not fitted on: e, m, R², bias per signal.
    Validate(validate::ValidateArgs),
    /// Is an FMU fit for a real-time target? Counts allocations, locks, log messages and system calls of its steps, times them; exit 0 when clean.
    RealtimeCheck(realtime_check::RealtimeCheckArgs),
    /// Modal analysis of a torsional drivetrain chain.
    Modal(modal::ModalArgs),
    /// Identify the dyno loop from a step response or a frequency sweep.
    Identify(identify::IdentifyArgs),
    /// The store of unpacked FMUs: `cache info`, `cache prune [--older-than DAYS] [--max-size SIZE]`.
    Cache(cache::CacheArgs),
    /// Serve one isolated FMU instance over stdin (started by `run --isolate`).
    #[command(hide = true)]
    Worker(worker::WorkerArgs),
}

impl Command {
    /// Whether the command prints a JSON document (stdout is then the document alone).
    pub fn json(&self) -> bool {
        match self {
            Command::Benchmark(a) => a.json,
            Command::Run(a) => a.json,
            Command::Info(a) => a.json,
            Command::Lap(a) => a.json,
            Command::ExportSsp(a) => a.json,
            Command::ExportTwin(a) => a.json,
            Command::Compare(a) => a.json,
            Command::Optimize(a) => a.json,
            Command::Validate(a) => a.json,
            Command::Modal(a) => a.json,
            Command::RealtimeCheck(a) => a.json,
            Command::Identify(a) => a.json(),
            Command::Pack(_) | Command::Demo(_) | Command::Cache(_) | Command::Worker(_) => false,
        }
    }
}

/// Set while a command runs. An FMU loaded in this process that calls `exit()` (some
/// exporters do on a fatal error) would end twinbench with the FMU's exit code, often 0, and
/// no word: the handler below turns that into a message and a failure.
static COMMAND_RUNNING: AtomicBool = AtomicBool::new(false);

/// Set in a `twinbench worker` process (an isolated FMU's).
static IN_WORKER: AtomicBool = AtomicBool::new(false);

/// The exit code when something called `exit()` in the middle of a command.
pub const EXIT_BY_FMU: i32 = 3;

/// Set by the panic hook: a panic of twinbench's own is reported as such (with its location,
/// printed by the default hook), never as an FMU's `exit()`.
static PANICKED: AtomicBool = AtomicBool::new(false);

extern "C" fn exit_guard() {
    if PANICKED.load(Ordering::SeqCst) {
        let message = b"error: twinbench stopped on an internal error (the panic above, with its location): this is a bug in twinbench, please report it with the command that caused it\n";
        // SAFETY: only async-signal-safe calls; the process is already ending.
        unsafe {
            libc::write(2, message.as_ptr().cast(), message.len());
            libc::_exit(101);
        }
    }
    if COMMAND_RUNNING.load(Ordering::SeqCst) {
        // In an isolated worker the FMU is isolated already (M17: it was told to isolate it).
        let message: &[u8] = if IN_WORKER.load(Ordering::SeqCst) {
            b"error: the FMU called exit() in its isolated worker (twinbench never calls it); the worker ends, twinbench goes on.\n"
        } else {
            b"error: the process was ended by a call to exit() before the command finished, from inside an FMU's code (twinbench never calls it); nothing more was written. Run the FMU with --isolate (or isolate = true) to keep twinbench alive and see where.\n"
        };
        // Only async-signal-safe calls here: the process is already ending.
        unsafe {
            libc::write(2, message.as_ptr().cast(), message.len());
            libc::_exit(EXIT_BY_FMU);
        }
    }
}

/// The command is over: an exit from here on is twinbench's own (and a panic caught and
/// handled on the way is not the cause of the exit).
pub(crate) fn command_finished() {
    COMMAND_RUNNING.store(false, Ordering::SeqCst);
    PANICKED.store(false, Ordering::SeqCst);
}

pub fn main() -> ExitCode {
    // Die quietly on a closed pipe (`twinbench info X | head`) instead of panicking in println!.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        libc::atexit(exit_guard);
    }
    interrupt::install_default();
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        PANICKED.store(true, Ordering::SeqCst);
        default_hook(info);
    }));
    let cli = Cli::parse();
    let level = match cli.verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .init();
    if cli.command.json() {
        json::protect();
    }
    IN_WORKER.store(matches!(cli.command, Command::Worker(_)), Ordering::SeqCst);
    COMMAND_RUNNING.store(true, Ordering::SeqCst);
    // The test suite's way to a panic of twinbench's own (tests/robustness_faults.rs).
    if std::env::var_os("TWINBENCH_TEST_PANIC").is_some() {
        panic!("a panic on purpose (TWINBENCH_TEST_PANIC is set)");
    }
    let result = match cli.command {
        Command::Pack(a) => pack::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Benchmark(a) => benchmark::run(a),
        Command::Run(a) => run::run(a),
        Command::Info(a) => info::run(a),
        Command::Lap(a) => lap::run(a),
        Command::ExportSsp(a) => export_ssp::run(a),
        Command::ExportTwin(a) => export_twin::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Optimize(a) => optimize::run(a),
        Command::Validate(a) => validate::run(a),
        Command::Modal(a) => modal::run(a),
        Command::RealtimeCheck(a) => match realtime_check::run(a) {
            Ok(true) => Ok(()),
            Ok(false) => {
                command_finished();
                return ExitCode::from(realtime_check::EXIT_NOT_CLEAN);
            }
            Err(e) => {
                command_finished();
                eprintln!("error: {}", message(&e));
                return ExitCode::from(realtime_check::EXIT_ERROR);
            }
        },
        Command::Identify(a) => identify::run(a),
        Command::Cache(a) => cache::run(a),
        Command::Worker(a) => worker::run(a),
    };
    command_finished();
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<interrupt::Interrupted>().is_some() => {
            eprintln!("{e}");
            ExitCode::from(interrupt::EXIT_INTERRUPTED)
        }
        Err(e) if e.downcast_ref::<interrupt::RunInterrupted>().is_some() => {
            eprintln!("{e}");
            ExitCode::from(interrupt::EXIT_INTERRUPTED)
        }
        Err(e) => {
            eprintln!("error: {}", message(&e));
            ExitCode::FAILURE
        }
    }
}

pub use crate::bench::{lap_time, message};

/// `--isolate[=MODE]`: confined (the default) or crash isolation only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum IsolateMode {
    /// Confined: the FMU writes only its scratch folder, no network, nothing outlives the run.
    Confined,
    /// Crash and hang isolation only: the worker runs unconfined, as the user.
    CrashOnly,
}

impl IsolateMode {
    pub fn mode(self) -> tb_cosim::isolated::confine::Mode {
        match self {
            IsolateMode::Confined => tb_cosim::isolated::confine::Mode::Confined,
            IsolateMode::CrashOnly => tb_cosim::isolated::confine::Mode::CrashOnly,
        }
    }
}
