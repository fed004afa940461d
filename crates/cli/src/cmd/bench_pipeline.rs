//! `filtrace bench pipeline`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`filtrace bench pipeline` is not implemented yet")
}
