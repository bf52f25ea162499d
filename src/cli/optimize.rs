//! `twinbench optimize STUDY.toml [--resume] [--json] [--threads N]`: runs an optimisation
//! study (docs/optimize.md), checkpointing after every generation.

pub use crate::study::{optimize, Optimized, StudyRun, DEFAULT_OUT};
use std::path::PathBuf;
use std::sync::Arc;
use tb_optimize::{OptimizerKind, StopOnFlag, StudyObserver};

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
    /// Output folder: checkpoint, result JSON, Tab. 1, plots and report.html.
    #[arg(long, short, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Override the study's optimiser (ga or cmaes).
    #[arg(long, value_parser = parse_kind)]
    pub optimizer: Option<OptimizerKind>,
    /// Override the generations of every step.
    #[arg(long)]
    pub generations: Option<usize>,
    /// Skip the report (Tab. 1, plots and report.html).
    #[arg(long)]
    pub no_report: bool,
    /// Optimise even when the first run says the measurement and the twin do not belong
    /// together (lap length, lap time, speed over distance; the study's [plausibility]).
    #[arg(long)]
    pub force: bool,
    /// Profile likelihood of every fitted parameter after the joint refinement: each held
    /// on a grid, the others re-optimised; intervals and plots from it (docs/optimize.md)
    #[arg(long)]
    pub profiles: bool,
    /// A moving-block bootstrap of the joint answer with N refits from it (residuals
    /// resampled in blocks as long as their persistence): each parameter's bootstrap standard
    /// error against the sandwich's, a check of the intervals (docs/optimize.md)
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub bootstrap: usize,
}

impl OptimizeArgs {
    /// The run these arguments ask for.
    pub fn study_run(&self) -> StudyRun {
        StudyRun {
            study: self.study.clone(),
            resume: self.resume,
            threads: self.threads,
            out: self.out.clone(),
            optimizer: self.optimizer,
            generations: self.generations,
            no_report: self.no_report,
            force: self.force,
            verbose: !self.json,
            profiles: self.profiles,
            bootstrap: self.bootstrap,
        }
    }
}

fn parse_kind(s: &str) -> Result<OptimizerKind, String> {
    match s {
        "ga" => Ok(OptimizerKind::Ga),
        "cmaes" | "cma-es" => Ok(OptimizerKind::Cmaes),
        _ => Err(format!("unknown optimiser '{s}' (ga, cmaes)")),
    }
}

pub fn run(args: OptimizeArgs) -> anyhow::Result<()> {
    // Observers: the bars (not with --json), then Ctrl-C's stop after the generation.
    let observers: Vec<Arc<dyn StudyObserver>> = vec![
        super::progress::Bars::for_cli(args.json),
        Arc::new(StopOnFlag(super::interrupt::flag()?)),
    ];
    let Optimized {
        result,
        report,
        checkpoint,
    } = optimize(&args.study_run(), None, observers)?;
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
            // The page to open first, or to hand on: everything above on one page.
            println!("page        {}", r.folder.join("report.html").display());
        }
    }
    Ok(())
}
