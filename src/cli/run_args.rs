//! The options of `twinbench run`, shared by a system's run ([`super::run`]) and a lone
//! FMU's ([`crate::run_fmu`], which takes them as its own options, [`FmuRun`]).

use crate::run_fmu::FmuRun;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// The system description (TOML), an SSP 1.0 package (`.ssp`), or one FMU (`.fmu`,
    /// run on its own as `fmpy simulate` runs it: its default experiment, every output).
    pub system: PathBuf,
    /// Write the recorded signals here, written atomically: MDF 4 for `.mf4`/`.mdf` (with
    /// units, `time` the master channel), CSV otherwise.
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Override a parameter: instance.variable=value (repeatable).
    #[arg(long = "set", value_name = "INSTANCE.VARIABLE=VALUE")]
    pub set: Vec<String>,
    /// Apply a study's answer: every value of `parameters_final` in RESULT.json (the
    /// result `twinbench optimize` writes), before any `--set` (which wins).
    #[arg(long, value_name = "RESULT.json")]
    pub params: Option<PathBuf>,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
    /// Keep the unpacked FMUs (in a temporary folder whose path is printed).
    #[arg(long)]
    pub keep_extracted: bool,
    /// Call the linked models directly (no FMI boundary; same results, the overhead floor).
    #[arg(long)]
    pub native: bool,
    /// Run every FMU instance in a worker process: a crash or hang of an FMU ends the run
    /// with an error naming the instance, time and cause (`isolate = true` does it per
    /// instance). Confined by default (the FMU writes only a scratch folder, has no network,
    /// leaves no process behind); `--isolate=crash-only` isolates for crashes and hangs only.
    #[arg(long, num_args = 0..=1, require_equals = true, default_missing_value = "confined", value_name = "MODE")]
    pub isolate: Option<super::IsolateMode>,
    /// Watchdog of isolated instances: the longest wait for one call [s].
    #[arg(long, value_name = "SECONDS", default_value_t = 10.0)]
    pub worker_timeout: f64,
    /// Limits of confined workers: memory (address space), scratch (the size of its
    /// scratch folder), files (open), threads, e.g. `memory=2G,scratch=64M` (default
    /// memory=4G,scratch=256M,files=1024,threads=256; TWINBENCH_WORKER_LIMITS sets them too).
    #[arg(long, value_name = "KEY=VALUE,...", value_parser = |s: &str| tb_cosim::isolated::confine::Limits::parse(s))]
    pub worker_limits: Option<tb_cosim::isolated::confine::Limits>,
    /// Write every FMI call of the traced instances to FILE: the function, its arguments
    /// with variable names and values, and the status (for debugging a supplier's FMU).
    #[arg(long, value_name = "FILE")]
    pub trace_fmi: Option<PathBuf>,
    /// The instances `--trace-fmi` traces, comma-separated (default: all).
    #[arg(
        long,
        value_name = "NAMES",
        value_delimiter = ',',
        requires = "trace_fmi"
    )]
    pub trace_instances: Vec<String>,
    /// The relative tolerance of every FMU with an internal solver (over the system file's
    /// and the FMUs' DefaultExperiment tolerance).
    #[arg(long, value_name = "TOLERANCE")]
    pub tolerance: Option<f64>,
    /// The step size each doStep is given: `h` (the step itself, default) or `grid`
    /// (t[n+1] - t[n], as FMPy passes it).
    #[arg(long, value_name = "h|grid", value_parser = |s: &str| tb_cosim::StepConvention::from_name(s))]
    pub step_convention: Option<tb_cosim::StepConvention>,
    /// One FMU: the start time [s] (default: its DefaultExperiment's, else 0).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true)]
    pub start: Option<f64>,
    /// One FMU: the stop time [s] (default: its DefaultExperiment's, else start + 1).
    #[arg(long, value_name = "SECONDS")]
    pub stop: Option<f64>,
    /// One FMU: the communication step [s] (default: FMPy's, from the DefaultExperiment's
    /// step, at most 1000 steps; else 500 to 1000 steps of a round size).
    #[arg(long, value_name = "SECONDS")]
    pub step: Option<f64>,
    /// One FMU: record every OUTPUT_INTERVAL seconds (a whole number of steps; alone, it is
    /// the step too, as in FMPy).
    #[arg(long, value_name = "SECONDS")]
    pub output_interval: Option<f64>,
    /// One FMU: an input file (CSV or MDF 4, FMPy's format: `time`, then one column per
    /// input, by the input's name; a column without a unit takes its input's).
    #[arg(long, value_name = "FILE")]
    pub input: Option<PathBuf>,
    /// One FMU: the interface to run it through, model-exchange or co-simulation (FMPy's
    /// `--fmi-type`; default: Co-Simulation when the FMU has it).
    #[arg(long, value_name = "model-exchange|co-simulation", value_parser = |s: &str| tb_fmi::Interface::from_name(s))]
    pub interface: Option<tb_fmi::Interface>,
    /// One Model Exchange FMU: a row just before and just after each event too, both at the
    /// event's time (FMPy's `record_events`), besides the output points.
    #[arg(long)]
    pub record_events: bool,
    /// Pace the run: each macro step waits for its wall-clock deadline, start + t / FACTOR
    /// (1, the default: the wall clock keeps simulated time; 2: twice as fast), with
    /// SCHED_FIFO, mlockall and a CPU of its own where the system allows (a line on stderr
    /// says what was refused). The summary reports the steps' lateness. docs/realtime.md.
    #[arg(long, num_args = 0..=1, default_missing_value = "1", value_name = "FACTOR",
          allow_negative_numbers = true, value_parser = parse_factor)]
    pub realtime: Option<tb_cosim::pacing::RealTimeFactor>,
    /// With --realtime: the SCHED_FIFO priority, 1 to 99 (0: the normal scheduler, not asked).
    #[arg(long, value_name = "N", default_value_t = 80, requires = "realtime",
          value_parser = clap::value_parser!(i32).range(0..=99))]
    pub realtime_priority: i32,
    /// With --realtime: the CPU the run has to itself (default: the last this process may
    /// use; `none`: not asked).
    #[arg(long, value_name = "N|none", requires = "realtime", value_parser = parse_cpu)]
    pub realtime_cpu: Option<tb_cosim::pacing::CpuRequest>,
    /// With --realtime: what a step that finishes after its deadline does. continue: the
    /// later deadlines keep the schedule (the run catches up); skip: the schedule restarts
    /// one step after now (the frames lost are counted); stop: the run ends there, its rows
    /// kept, `stopped by` saying so.
    #[arg(long, value_name = "continue|skip|stop", default_value = "continue",
          requires = "realtime", value_parser = |s: &str| tb_cosim::pacing::OverrunPolicy::from_name(s))]
    pub overrun: tb_cosim::pacing::OverrunPolicy,
}

impl RunArgs {
    /// The options of one FMU's run (the library's, which has no clap).
    pub fn fmu_run(&self) -> FmuRun {
        FmuRun {
            system: self.system.clone(),
            start: self.start,
            stop: self.stop,
            step: self.step,
            output_interval: self.output_interval,
            input: self.input.clone(),
            interface: self.interface,
            record_events: self.record_events,
            isolated: self.isolate.is_some(),
        }
    }
}

/// `--realtime FACTOR`: a finite number above 0.
fn parse_factor(s: &str) -> Result<tb_cosim::pacing::RealTimeFactor, String> {
    let x: f64 = s.trim().parse().map_err(|_| {
        format!(
            "'{s}' is not a number (a real-time factor: 1 keeps real time, 2 runs twice as fast)"
        )
    })?;
    tb_cosim::pacing::RealTimeFactor::new(x).map_err(|e| e.to_string())
}

/// `--realtime-cpu N|none`.
fn parse_cpu(s: &str) -> Result<tb_cosim::pacing::CpuRequest, String> {
    match s.trim() {
        "none" => Ok(tb_cosim::pacing::CpuRequest::Any),
        n => n
            .parse()
            .map(tb_cosim::pacing::CpuRequest::Cpu)
            .map_err(|_| format!("'{s}' is not a CPU number (0, 1, ...) or `none`")),
    }
}
