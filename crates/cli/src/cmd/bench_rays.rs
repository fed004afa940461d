//! `filtrace bench rays`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`filtrace bench rays` is not implemented yet")
}
