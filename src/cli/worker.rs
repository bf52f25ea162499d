//! `twinbench worker` (hidden): serves one isolated FMU instance to the host process over
//! the socket on its stdin; see `system::isolated`.

#[derive(clap::Args, Debug)]
pub struct WorkerArgs {}

pub fn run(_args: WorkerArgs) -> anyhow::Result<()> {
    let code = tb_cosim::isolated::serve_stdio();
    super::command_finished();
    std::process::exit(code)
}
