//! `twinbench benchmark`: one lap of the 5-instance bench at 1 ms, timed (issue 4's figure:
//! wall time, real-time factor, nanoseconds per macro step).

use std::path::PathBuf;
use std::sync::Arc;
use tb_cosim::{Plan, Simulation};
use tb_fmi::FmuCache;

#[derive(clap::Args, Debug)]
pub struct BenchmarkArgs {
    /// The system to time (default: the bundled RLS/v bench, written with the shipped FMUs
    /// into a temporary folder).
    #[arg(long)]
    pub system: Option<PathBuf>,
    /// Timed laps (after one warm-up lap); the best and the median are reported.
    #[arg(long, default_value_t = 5)]
    pub laps: usize,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: BenchmarkArgs) -> anyhow::Result<()> {
    let bundle = tempfile::Builder::new()
        .prefix("twinbench-benchmark-")
        .tempdir()?;
    let path = match args.system {
        Some(p) => p,
        None => {
            super::demo::prepare_bundle(bundle.path(), false)?;
            bundle.path().join("systems/rls_v.toml")
        }
    };
    let cache = Arc::new(FmuCache::temporary(false)?);
    let plan = Arc::new(Plan::load(&path, cache)?);
    let mut sim = Simulation::new(plan.clone())?;
    sim.echo_fmu_log = false;
    sim.run()?; // warm-up: pages in the libraries, resources, caches
    let mut runs = Vec::new();
    for _ in 0..args.laps.max(1) {
        runs.push(sim.run()?);
    }
    let mut walls: Vec<f64> = runs.iter().map(|r| r.wall_time).collect();
    walls.sort_by(f64::total_cmp);
    let best = walls[0];
    let median = walls[walls.len() / 2];
    let r = &runs[0];
    let ns = |w: f64| w * 1e9 / r.steps as f64;
    let instances = plan.instances.len();
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&serde_json::json!({
            "system": path, "instances": instances, "steps": r.steps, "simulated_time": r.simulated_time,
            "lap_time": super::lap_time(r, &plan), "laps_timed": walls.len(),
            "wall_time_best": best, "wall_time_median": median,
            "real_time_factor": r.simulated_time / median,
            "ns_per_macro_step_best": ns(best), "ns_per_macro_step_median": ns(median),
        }))?)?;
    } else {
        println!(
            "system            {} ({instances} instances)",
            path.display()
        );
        println!(
            "lap               {} steps, {:.3} s simulated",
            r.steps, r.simulated_time
        );
        println!(
            "wall time / lap   best {:.4} s, median {:.4} s ({} laps)",
            best,
            median,
            walls.len()
        );
        println!("real-time factor  {:.0}x", r.simulated_time / median);
        println!(
            "per macro step    best {:.0} ns, median {:.0} ns (all instances, models included)",
            ns(best),
            ns(median)
        );
    }
    Ok(())
}
