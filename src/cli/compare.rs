//! `twinbench compare` (to be written).

#[derive(clap::Args, Debug)]
pub struct CompareArgs {}

pub fn run(_args: CompareArgs) -> anyhow::Result<()> {
    anyhow::bail!("twinbench compare is not implemented yet")
}
