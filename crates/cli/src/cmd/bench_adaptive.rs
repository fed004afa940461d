//! `filtrace bench adaptive`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`filtrace bench adaptive` is not implemented yet")
}
