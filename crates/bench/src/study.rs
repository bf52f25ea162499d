//! An optimisation study run to its files: the checkpoint after every generation, the result,
//! Tab. 1 and the plots (`twinbench optimize`, the Python package's `Study.optimize`; the
//! same files and messages from both).

use anyhow::Context;
use std::path::{Path, PathBuf};
use std::sync::Arc;
#[cfg(doc)]
use tb_optimize::StopOnFlag;
use tb_optimize::{
    run_study, Evaluator, OptimizerKind, RunOptions, Study, StudyObserver, StudyOutcome,
    StudyResult,
};

/// What to run: the study file, where to write, and the overrides of the command line.
#[derive(Clone, Debug)]
pub struct StudyRun {
    /// The study file (TOML).
    pub study: PathBuf,
    /// Continue from the checkpoint (to the same result as an uninterrupted run).
    pub resume: bool,
    /// Evaluation threads (0: all cores).
    pub threads: usize,
    /// Output folder: checkpoint, result JSON, Tab. 1 and plots.
    pub out: PathBuf,
    /// Override the study's optimiser.
    pub optimizer: Option<OptimizerKind>,
    /// Override the generations of every step.
    pub generations: Option<usize>,
    /// Skip the report (Tab. 1, plots and report.html).
    pub no_report: bool,
    /// Optimise even when the first run says the measurement and the twin do not belong
    /// together.
    pub force: bool,
    /// Print each step's progress and identifiability on stderr.
    pub verbose: bool,
    /// Profile likelihood of every parameter after the refinement.
    pub profiles: bool,
    /// Refits of a moving-block bootstrap of the joint answer (0: none).
    pub bootstrap: usize,
}

impl StudyRun {
    /// The command line that continues this study from its checkpoint.
    pub fn resume_command(&self) -> String {
        let quote = shell_word;
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
        if self.profiles {
            c.push_str(" --profiles");
        }
        if self.bootstrap > 0 {
            c.push_str(&format!(" --bootstrap {}", self.bootstrap));
        }
        c
    }
}

/// Where `optimize` writes without `--out`.
pub const DEFAULT_OUT: &str = "target/optimize";

/// A study stopped on request; its checkpoint holds every finished generation.
#[derive(Debug, thiserror::Error)]
#[error("interrupted: checkpoint kept ({checkpoint}); resume with `{resume}`")]
pub struct Interrupted {
    pub checkpoint: String,
    pub resume: String,
}

/// A path as one word of a shell command line (quoted only when it needs to be).
pub fn shell_word(p: &Path) -> String {
    let s = p.display().to_string();
    match s
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "/._-+".contains(c))
    {
        true => s,
        false => format!("'{}'", s.replace('\'', "'\\''")),
    }
}

impl Interrupted {
    pub fn new(checkpoint: &Path, resume: String) -> Self {
        Interrupted {
            checkpoint: checkpoint.display().to_string(),
            resume,
        }
    }
}

/// A resume without a checkpoint starts from the beginning, and says so.
pub fn say_when_no_checkpoint(resume: bool, checkpoint: &Path) {
    if resume && !checkpoint.exists() {
        eprintln!(
            "no checkpoint at {}: starting from the beginning",
            checkpoint.display()
        );
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
/// `observers` watch the study (progress, a stop condition such as [`StopOnFlag`] for
/// Ctrl-C: the error is then [`Interrupted`], saying how to resume); the report is one more,
/// last (unless `--no-report`).
pub fn optimize(
    args: &StudyRun,
    evaluator: Option<Arc<dyn Evaluator>>,
    mut observers: Vec<Arc<dyn StudyObserver>>,
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
        args.out.join("report.html"),
    ] {
        tb_table::check_output(&name, &inputs)?;
    }
    say_when_no_checkpoint(args.resume, &checkpoint);
    let report = (!args.no_report).then(|| crate::report::ReportWriter::new(&study, &args.out));
    if let Some(r) = &report {
        observers.push(r.clone());
    }
    let options = RunOptions {
        threads: args.threads,
        observers,
        checkpoint: Some(checkpoint.clone()),
        resume: args.resume,
        optimizer: args.optimizer,
        generations: args.generations,
        verbose: args.verbose,
        force: args.force,
        evaluator,
        profiles: args.profiles,
        bootstrap: args.bootstrap,
    };
    let result = match run_study(&study, &options)? {
        StudyOutcome::Finished(r) => r,
        StudyOutcome::Interrupted { .. } => {
            return Err(Interrupted::new(&checkpoint, args.resume_command()).into())
        }
    };
    let report = report.and_then(|r| r.files());
    if report.is_none() {
        // Without the report the answer is still written: result.json is the study's
        // result, what validate, export and Python read (the report writes it otherwise).
        let path = args.out.join("result.json");
        tb_table::write_atomic(
            &path,
            &serde_json::to_vec_pretty(&result).expect("a result serialises"),
        )
        .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(Optimized {
        result,
        report,
        checkpoint,
    })
}
