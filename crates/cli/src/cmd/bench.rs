//! `filtrace bench ...`: each benchmark prints a markdown table, or one JSON object with `--json`.

use clap::Subcommand;

#[derive(Subcommand)]
pub enum Which {
    /// Ray casting throughput of the BVH on a mesh.
    Rays(RaysArgs),
}

#[derive(clap::Args)]
pub struct RaysArgs {}

pub fn run(which: Which) -> anyhow::Result<()> {
    match which {
        Which::Rays(_) => anyhow::bail!("`filtrace bench rays` is not implemented yet"),
    }
}
