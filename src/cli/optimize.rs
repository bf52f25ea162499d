//! `twinbench optimize STUDY.toml [--resume] [--json] [--threads N]`: runs an optimisation
//! study (docs/optimize.md), checkpointing after every generation.

use anyhow::Context;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use tb_optimize::{
    run_study, Evaluator, OptimizerKind, Progress, RunOptions, Study, StudyOutcome, StudyResult,
};

#[derive(clap::Args, Debug)]
pub struct OptimizeArgs {
    /// The study file (TOML).
    pub study: PathBuf,
    /// Continue from the checkpoint (to the same result as an uninterrupted run).
    #[arg(long)]
    pub resume: bool,
    /// Print the result as JSON (per step: parameters and e before/after).
    #[arg(long)]
    pub json: bool,
    /// Evaluation threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// Output folder: checkpoint, result JSON, Tab. 1 and plots.
    #[arg(long, short, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Override the study's optimiser (ga or cmaes).
    #[arg(long, value_parser = parse_kind)]
    pub optimizer: Option<OptimizerKind>,
    /// Override the generations of every step.
    #[arg(long)]
    pub generations: Option<usize>,
    /// Skip the report (Tab. 1 and plots).
    #[arg(long)]
    pub no_report: bool,
    /// Optimise even when the first run says the measurement and the twin do not belong
    /// together (lap length, lap time, speed over distance; the study's [plausibility]).
    #[arg(long)]
    pub force: bool,
}

impl OptimizeArgs {
    /// The command line that continues this study from its checkpoint.
    pub fn resume_command(&self) -> String {
        let quote = super::interrupt::shell_word;
        let mut c = format!("twinbench optimize {} --resume", quote(&self.study));
        if self.out != std::path::Path::new(DEFAULT_OUT) {
            c.push_str(&format!(" --out {}", quote(&self.out)));
        }
        if let Some(k) = self.optimizer {
            c.push_str(&format!(" --optimizer {}", k.name()));
        }
        if let Some(g) = self.generations {
            c.push_str(&format!(" --generations {g}"));
        }
        c
    }
}

/// Where `optimize` writes without `--out`.
pub const DEFAULT_OUT: &str = "target/optimize";

fn parse_kind(s: &str) -> Result<OptimizerKind, String> {
    match s {
        "ga" => Ok(OptimizerKind::Ga),
        "cmaes" | "cma-es" => Ok(OptimizerKind::Cmaes),
        _ => Err(format!("unknown optimiser '{s}' (ga, cmaes)")),
    }
}

/// What an optimisation made: the result, its report (unless `--no-report`), its checkpoint.
pub struct Optimized {
    pub result: Box<StudyResult>,
    pub report: Option<crate::report::ReportFiles>,
    pub checkpoint: PathBuf,
}

/// `twinbench optimize` without its printing: the Python package runs the same (with its
/// own evaluator and progress), so both write the same files and fail with the same messages.
///
/// `interrupt`: set (by Ctrl-C) to stop after the generation under way; the error is then
/// [`super::interrupt::Interrupted`], saying how to resume.
pub fn optimize(
    args: &OptimizeArgs,
    evaluator: Option<Arc<dyn Evaluator>>,
    progress: Option<Arc<dyn Progress>>,
    interrupt: Option<Arc<AtomicBool>>,
) -> anyhow::Result<Optimized> {
    let study = Study::load(&args.study)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    // One optimisation per output folder at a time; no output replaces an input.
    let _lock = tb_table::FolderLock::acquire(&args.out)?;
    let checkpoint = args.out.join(format!("{}.checkpoint.json", study.name()));
    let inputs = [
        study.path.as_path(),
        study.system_path.as_path(),
        study.measurement_path.as_path(),
    ];
    for name in [
        checkpoint.clone(),
        args.out.join("result.json"),
        args.out.join("table1.json"),
        args.out.join("table1.md"),
    ] {
        tb_table::check_output(&name, &inputs)?;
    }
    if args.resume && !checkpoint.exists() {
        eprintln!(
            "no checkpoint at {}: starting from the beginning",
            checkpoint.display()
        );
    }
    let options = RunOptions {
        threads: args.threads,
        progress,
        checkpoint: Some(checkpoint.clone()),
        resume: args.resume,
        stop_after: None,
        interrupt,
        optimizer: args.optimizer,
        generations: args.generations,
        verbose: !args.json,
        force: args.force,
        evaluator,
    };
    let result = match run_study(&study, &options)? {
        StudyOutcome::Finished(r) => r,
        StudyOutcome::Interrupted { .. } => {
            return Err(
                super::interrupt::Interrupted::new(&checkpoint, args.resume_command()).into(),
            )
        }
    };
    let report = if args.no_report {
        None
    } else {
        Some(crate::report::write_report(&study, &result, &args.out)?)
    };
    Ok(Optimized {
        result,
        report,
        checkpoint,
    })
}

pub fn run(args: OptimizeArgs) -> anyhow::Result<()> {
    let progress = (!args.json).then(super::progress::Bars::shared);
    let Optimized {
        result,
        report,
        checkpoint,
    } = optimize(&args, None, progress, Some(super::interrupt::flag()?))?;
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&result)?)?;
    } else {
        if let Some(r) = &report {
            println!("{}", r.table_markdown);
        }
        println!(
            "{} full-lap simulations in {:.1} s ({:.2} per second, {} threads, {} simulations created)",
            result.simulations,
            result.wall_seconds,
            result.simulations as f64 / result.wall_seconds,
            result.threads,
            result.workers_created
        );
        println!("checkpoint  {}", checkpoint.display());
        if let Some(r) = &report {
            println!("report      {}", r.folder.display());
        }
    }
    Ok(())
}
