//! `twinbench pack`: write the FMUs of the models built into this binary.

use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct PackArgs {
    /// Models to pack (default: all).
    pub models: Vec<String>,
    /// Output folder (default: target/fmu of the source tree, if it is there; else
    /// ~/.local/share/twinbench/fmu).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
}

pub fn run(args: PackArgs) -> anyhow::Result<()> {
    let out = args.out.unwrap_or_else(crate::pack::default_fmu_dir);
    for p in crate::pack::pack(&args.models, &out)? {
        println!("{}", p.display());
    }
    Ok(())
}
