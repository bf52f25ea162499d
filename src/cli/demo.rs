//! `twinbench demo`: the main job on the bundled data. Packs the FMUs when missing, runs the
//! virtual bench (RLS/v) over the bundled Spielberg lap, and writes the results.

use crate::fmu::FmuCache;
use crate::system::{Simulation, System};
use anyhow::Context;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(long, short, default_value = "target/demo")]
    pub out: PathBuf,
    /// Repack the FMUs even if they exist.
    #[arg(long)]
    pub repack: bool,
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let root = crate::pack::workspace_root();
    let fmu_dir = crate::pack::default_fmu_dir();
    let missing = crate::pack::models()
        .iter()
        .any(|s| !crate::pack::fmu_path(&fmu_dir, s).exists());
    if missing || args.repack {
        eprintln!("packing the FMUs into {} ...", fmu_dir.display());
        crate::pack::pack(&[], &fmu_dir)?;
    }
    let cache = Arc::new(FmuCache::temporary(false)?);
    let system_path = root.join("systems/rls_v.toml");
    let mut sim = Simulation::new(System::load(&system_path, cache)?)?;
    sim.echo_fmu_log = false;
    let summary = sim.run()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let csv = args.out.join("rls_v_lap.csv");
    sim.recording.write_csv(&csv)?;
    println!("twinbench demo: the virtual bench (RLS/v) drives the bundled Spielberg lap");
    println!("  system      {}", system_path.display());
    println!(
        "  lap time    {:.3} s (measured lap: 97.490 s)",
        summary.lap_time.unwrap_or(f64::NAN)
    );
    println!(
        "  steps       {} at 1 ms, wall time {:.3} s",
        summary.steps, summary.wall_time
    );
    println!("  results     {}", csv.display());
    Ok(())
}
