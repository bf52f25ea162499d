//! `twinbench export-twin`: the fitted twin of a study, handed on as FMUs, SSP, SSV, a
//! system file and a parameter table ([`crate::export_twin`]).

use crate::pack::FmiVersion;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct ExportTwinArgs {
    /// The study's result (the result.json `twinbench optimize` writes).
    pub result: PathBuf,
    /// The folder to write (new, or an earlier export-twin output).
    #[arg(long, short)]
    pub out: PathBuf,
    /// The FMI versions of the fitted FMUs, comma-separated.
    #[arg(long, value_name = "2,3", value_delimiter = ',', default_value = "2,3",
          value_parser = |s: &str| FmiVersion::parse(s).ok_or_else(|| format!("'{s}': expected 2 or 3")))]
    pub fmi: Vec<FmiVersion>,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ExportTwinArgs) -> anyhow::Result<()> {
    let mut versions = args.fmi.clone();
    versions.sort();
    versions.dedup();
    let ex = crate::export_twin::export_twin(
        &args.result,
        &args.out,
        &crate::export_twin::ExportOptions { versions },
    )?;
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&ex)?)?;
        return Ok(());
    }
    println!("wrote           {}", ex.folder.display());
    println!(
        "fitted FMUs     {} (start values: the system's and the study's answer)",
        ex.fitted_instances.join(", ")
    );
    if !ex.copied_instances.is_empty() {
        println!("copied FMUs     {}", ex.copied_instances.join(", "));
    }
    println!("values          {}", ex.parameters);
    for f in &ex.files {
        println!("  {}", f.display());
    }
    for n in &ex.notes {
        println!("note            {n}");
    }
    println!(
        "run it         twinbench run {}",
        ex.folder.join("fitted_system.toml").display()
    );
    Ok(())
}
