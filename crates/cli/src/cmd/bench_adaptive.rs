//! `filtrace bench adaptive`: overhead of the adaptive sampling scheme (Bauszat et al.
//! 2011, Tables 1 and 2): importance map + apportionment per window size, and batch
//! generation/storage at several sample rates. Prints markdown tables, or JSON.

use filtrace_adaptive::bench::{run as run_bench, BenchConfig};
use std::io::Write;

#[derive(clap::Args)]
pub struct Args {
    /// Frame width (the paper: 1024).
    #[arg(long, default_value_t = 1024)]
    pub width: usize,
    /// Frame height (the paper: 768).
    #[arg(long, default_value_t = 768)]
    pub height: usize,
    /// Importance window radii; the paper's "NxN" window is radius N/2.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize, 2, 3, 4, 5])]
    pub radii: Vec<usize>,
    /// Average samples per pixel for the batch table.
    #[arg(long, value_delimiter = ',', default_values_t = vec![4u32, 16, 64])]
    pub spp: Vec<u32>,
    /// Minimum samples per pixel.
    #[arg(long, default_value_t = 1)]
    pub min_spp: u32,
    /// Runs per measurement (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub repeats: usize,
    /// Print one JSON object instead of tables.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.width > 0 && args.height > 0, "width and height must be positive");
    anyhow::ensure!(args.repeats > 0, "--repeats must be at least 1");
    let config = BenchConfig {
        width: args.width,
        height: args.height,
        radii: args.radii,
        spp: args.spp,
        min_spp: args.min_spp,
        repeats: args.repeats,
        ..BenchConfig::paper()
    };
    let report = run_bench(&config)?;
    let mut out = super::output::stdout();
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        write!(out, "{}", report.to_markdown())?;
    }
    Ok(out.flush()?)
}
