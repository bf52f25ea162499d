//! `twinbench demo`: the main job on the bundled data. Writes the bundled study, system,
//! measurement and the packed FMUs into `<out>/bundle` (they are embedded in the binary: no
//! sources needed), runs the paper's two-step optimisation with the whole virtual bench
//! (RLS/v) in the loop against the Spielberg measurement, prints Tab. 1 and writes the
//! report (Tab. 1 as Markdown and JSON, plots as SVG and PNG, all of it in report.html) to
//! `<out>`.

use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;
use tb_optimize::{run_study, RunOptions, Study, StudyOutcome};

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Output folder (Tab. 1, plots, report.html).
    #[arg(long, short, default_value = "target/demo")]
    pub out: PathBuf,
    /// Repack the FMUs even if they exist.
    #[arg(long)]
    pub repack: bool,
    /// Evaluation threads (default: all cores).
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
    /// The study to run (default: studies/spielberg.toml).
    #[arg(long)]
    pub study: Option<PathBuf>,
    /// Continue an interrupted demo from its checkpoint (to the same Tab. 1).
    #[arg(long)]
    pub resume: bool,
}

impl DemoArgs {
    /// The command line that continues this demo from its checkpoint.
    fn resume_command(&self) -> String {
        let quote = super::interrupt::shell_word;
        let mut c = String::from("twinbench demo --resume");
        if self.out != std::path::Path::new("target/demo") {
            c.push_str(&format!(" --out {}", quote(&self.out)));
        }
        if let Some(study) = &self.study {
            c.push_str(&format!(" --study {}", quote(study)));
        }
        c
    }
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let wall = Instant::now();
    let _lock = tb_table::FolderLock::acquire(&args.out)?;
    let bundle = args.out.join("bundle");
    prepare_bundle(&bundle, args.repack)?;
    let study_path = args
        .study
        .clone()
        .unwrap_or_else(|| bundle.join("studies/spielberg.toml"));
    let study = Study::load(&study_path)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    println!(
        "twinbench demo: the paper's two-step optimisation (Tab. 1) with the virtual bench \
         (RLS/v) in the loop"
    );
    println!("  study        {}", study_path.display());
    println!("  system       {}", study.system_path.display());
    println!("  measurement  {}", study.measurement_path.display());
    let optimise_start = Instant::now();
    let checkpoint = args.out.join(format!("{}.checkpoint.json", study.name()));
    crate::study::say_when_no_checkpoint(args.resume, &checkpoint);
    // Observers: the bars, Ctrl-C's stop after the generation, the report.
    let report = crate::report::ReportWriter::new(&study, &args.out);
    let options = RunOptions {
        threads: args.threads,
        observers: vec![
            super::progress::Bars::for_cli(false),
            std::sync::Arc::new(tb_optimize::StopOnFlag(super::interrupt::flag()?)),
            report.clone(),
        ],
        checkpoint: Some(checkpoint.clone()),
        resume: args.resume,
        verbose: true,
        ..RunOptions::default()
    };
    let result = match run_study(&study, &options)? {
        StudyOutcome::Finished(r) => r,
        // As `optimize`: the checkpoint of every finished generation, and how to go on.
        StudyOutcome::Interrupted { .. } => {
            return Err(
                super::interrupt::Interrupted::new(&checkpoint, args.resume_command()).into(),
            )
        }
    };
    let optimise_seconds = optimise_start.elapsed().as_secs_f64();
    let report = report.files().expect("written when the study finished");
    println!();
    // The identifiability of each step was printed when the step began (stderr).
    println!("{}", report.table_markdown);
    println!();
    println!(
        "optimisation  {} full-lap simulations in {:.1} s: {:.2} laps per second on {} threads \
         ({} Simulations created, reused between candidates)",
        result.simulations,
        optimise_seconds,
        result.simulations as f64 / optimise_seconds,
        result.threads,
        result.workers_created
    );
    println!(
        "demo          {:.1} s wall in all (packing check, optimisation, report)",
        wall.elapsed().as_secs_f64()
    );
    println!("report        {}", report.folder.display());
    println!(
        "page          {} (all of it on one page)",
        report.folder.join("report.html").display()
    );
    for f in &report.files {
        println!("  {}", f.display());
    }
    Ok(())
}

/// The bundled lap, embedded in the binary: the study, the system, the measurement with its
/// provenance, at their paths relative to each other.
const BUNDLE: &[(&str, &[u8])] = &[
    (
        "studies/spielberg.toml",
        include_bytes!("../../studies/spielberg.toml"),
    ),
    (
        "systems/rls_v.toml",
        include_bytes!("../../systems/rls_v.toml"),
    ),
    (
        "data/spielberg_lap.csv",
        include_bytes!("../../data/spielberg_lap.csv"),
    ),
    ("data/README.md", include_bytes!("../../data/README.md")),
    // The lap's truth: report.html marks it beside each parameter's answer.
    (
        "data/spielberg_lap_truth.json",
        include_bytes!("../../data/spielberg_lap_truth.json"),
    ),
];

/// The bundled lap and the shipped FMUs in `dir`, at the paths the bundled files name
/// (`systems/rls_v.toml` finds its FMUs in `target/fmu`): what the demo and the benchmark
/// run, with no sources needed. The FMUs are packed when missing, when they are not this
/// binary's (a bundle packed by an earlier build would run the old models), or when
/// `repack`.
pub(crate) fn prepare_bundle(dir: &std::path::Path, repack: bool) -> anyhow::Result<()> {
    write_bundle(dir)?;
    let fmu_dir = dir.join("target").join("fmu");
    let stale = crate::pack::models()
        .iter()
        .filter(|s| !s.test_only)
        .any(|s| !crate::pack::is_current(s, &crate::pack::fmu_path(&fmu_dir, s)));
    if stale || repack {
        eprintln!("packing the FMUs into {} ...", fmu_dir.display());
        crate::pack::pack(&[], &fmu_dir)?;
    }
    Ok(())
}

/// Writes the bundle into `dir` (files already there with the same content stay untouched).
fn write_bundle(dir: &std::path::Path) -> anyhow::Result<()> {
    for (name, bytes) in BUNDLE {
        let p = dir.join(name);
        if std::fs::read(&p).ok().as_deref() == Some(*bytes) {
            continue;
        }
        tb_table::write_atomic(&p, bytes)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    /// A bundle whose FMU is not this binary's (an earlier build's, here another model's
    /// bytes) is repacked; a current one is left as it is.
    #[test]
    fn a_bundle_packed_by_another_build_is_repacked() {
        let dir = tempfile::tempdir().unwrap();
        super::prepare_bundle(dir.path(), false).unwrap();
        let fmu_dir = dir.path().join("target/fmu");
        let spec = crate::pack::models()
            .into_iter()
            .find(|s| s.package == "driver")
            .unwrap();
        let spec = &spec;
        let driver = crate::pack::fmu_path(&fmu_dir, spec);
        assert!(crate::pack::is_current(spec, &driver));
        // Left alone when current (the file is not rewritten).
        let before = std::fs::metadata(&driver).unwrap().modified().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(20));
        super::prepare_bundle(dir.path(), false).unwrap();
        assert_eq!(
            std::fs::metadata(&driver).unwrap().modified().unwrap(),
            before
        );
        // Another build's FMU in its place: repacked.
        let other = std::fs::read(fmu_dir.join("dyno.fmu")).unwrap();
        std::fs::write(&driver, other).unwrap();
        assert!(!crate::pack::is_current(spec, &driver));
        super::prepare_bundle(dir.path(), false).unwrap();
        assert!(crate::pack::is_current(spec, &driver));
    }
}
