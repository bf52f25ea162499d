//! `twinbench pack`: write the FMUs of the models built into this binary.

use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct PackArgs {
    /// Models to pack (default: every shipped model of the registry, e.g. vehicle, driver,
    /// dyno, edu; a test FMU such as `faulty` only when named).
    pub models: Vec<String>,
    /// Output folder (default: $XDG_DATA_HOME/twinbench/fmu, that is
    /// ~/.local/share/twinbench/fmu; the repository's system files name target/fmu:
    /// `twinbench pack -o target/fmu` there).
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
