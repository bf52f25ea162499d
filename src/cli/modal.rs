//! `twinbench modal` (to be written).

#[derive(clap::Args, Debug)]
pub struct ModalArgs {}

pub fn run(_args: ModalArgs) -> anyhow::Result<()> {
    anyhow::bail!("twinbench modal is not implemented yet")
}
