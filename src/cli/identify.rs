//! `twinbench identify` (to be written).

#[derive(clap::Args, Debug)]
pub struct IdentifyArgs {}

pub fn run(_args: IdentifyArgs) -> anyhow::Result<()> {
    anyhow::bail!("twinbench identify is not implemented yet")
}
