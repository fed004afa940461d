//! `filtrace bench render`.

#[derive(clap::Args)]
pub struct Args {}

pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("`filtrace bench render` is not implemented yet")
}
