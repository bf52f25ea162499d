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
    /// FMI versions to pack, comma-separated: `2` (the default, `<model>.fmu`), `3`
    /// (`<model>-fmi3.fmu`), or `2,3` (both; one library serves both descriptions).
    #[arg(long, value_name = "VERSIONS", default_value = "2")]
    pub fmi: String,
}

pub fn run(args: PackArgs) -> anyhow::Result<()> {
    let out = args.out.unwrap_or_else(crate::pack::default_fmu_dir);
    let mut versions = Vec::new();
    for v in args.fmi.split(',') {
        match crate::pack::FmiVersion::parse(v) {
            Some(v) if !versions.contains(&v) => versions.push(v),
            Some(_) => {}
            None => anyhow::bail!(
                "--fmi {}: '{}' is no FMI version twinbench packs (2, 3, or 2,3)",
                args.fmi,
                v.trim()
            ),
        }
    }
    versions.sort();
    for p in crate::pack::pack_versions(&args.models, &out, &versions)? {
        println!("{}", p.display());
    }
    Ok(())
}
