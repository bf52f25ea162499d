//! `twinbench export-ssp`: write a system as an SSP 1.0 package (SystemStructure.ssd plus
//! the FMUs under resources/), for FMPy's simulate_ssp, libcosim and other SSP tools.

use std::path::PathBuf;
use std::sync::Arc;
use tb_cosim::Plan;
use tb_fmi::FmuCache;

#[derive(clap::Args, Debug)]
pub struct ExportSspArgs {
    /// The system description (TOML).
    pub system: PathBuf,
    /// The SSP file to write.
    #[arg(long, short)]
    pub out: PathBuf,
    /// DefaultExperiment stop time [s] (default: the system's fixed stop time, or its
    /// max_time when it stops on a lap; the lap condition is kept in an annotation).
    #[arg(long)]
    pub stop_time: Option<f64>,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ExportSspArgs) -> anyhow::Result<()> {
    let cache = Arc::new(FmuCache::temporary(false)?);
    let system = Plan::load(&args.system, cache)?;
    let mut inputs: Vec<&std::path::Path> = vec![args.system.as_path()];
    inputs.extend(system.file.fmus.values().map(|p| p.as_path()));
    tb_table::check_output(&args.out, &inputs)?;
    let options = tb_cosim::ssp::ExportOptions {
        stop_time: args.stop_time,
    };
    let s = tb_cosim::ssp::export(&system, &args.out, &options)?;
    if args.json {
        let mut j = serde_json::to_value(&s)?;
        j["out"] = serde_json::json!(args.out);
        super::json::print(&serde_json::to_string_pretty(&j)?)?;
    } else {
        println!("wrote           {}", args.out.display());
        println!(
            "components      {} ({} connectors, {} connections, {} parameter values)",
            s.components, s.connectors, s.connections, s.parameters
        );
        println!("FMUs            {}", s.fmus.join(", "));
        println!(
            "experiment      {} .. {} s, step {} s",
            s.start_time, s.stop_time, s.step
        );
        for n in &s.notes {
            println!("note            {n}");
        }
    }
    Ok(())
}
