//! `filtrace bench filters`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`filtrace bench filters` is not implemented yet")
}
