//! `filtrace bench render [SCENE]`: path tracer throughput (samples per second) at each
//! thread count, with the mean colour as a check that the same image was timed.

use super::render_args::BenchScene;
use filtrace_render::{render_bench, Renderer};
use serde::Serialize;
use std::io::Write;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub target: BenchScene,
    /// Samples per pixel of each timed render.
    #[arg(long, default_value_t = 8)]
    pub spp: u32,
    /// Mitsuba's convention: 1 = emitters only, 2 = direct light, -1 = unbounded.
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Comma-separated thread counts (default: 1 and all cores).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Print one JSON object instead of a markdown table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Row {
    threads: usize,
    samples: u64,
    seconds: f64,
    samples_per_s: f64,
    mean_rgb: [f64; 3],
}

#[derive(Serialize)]
struct Report {
    scene: String,
    res: String,
    spp: u32,
    max_depth: i32,
    triangles: usize,
    build_s: f64,
    rows: Vec<Row>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let scene = filtrace_scene::load_scene(&args.target.scene).map_err(|e| anyhow::anyhow!("{e}"))?;
    let settings = args.target.res.settings(args.spp, args.max_depth, 0)?;
    let renderer = Renderer::new(scene, settings).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut threads = args.threads.clone();
    if threads.is_empty() {
        threads = vec![1, rayon::current_num_threads()];
        threads.dedup();
    }
    anyhow::ensure!(threads.iter().all(|&t| t > 0), "--threads: every count must be at least 1");
    let rows = threads
        .iter()
        .map(|&t| {
            let r = render_bench(&renderer, t);
            Row {
                threads: r.threads,
                samples: r.samples,
                seconds: r.seconds,
                samples_per_s: r.samples_per_second,
                mean_rgb: r.mean_color,
            }
        })
        .collect();
    let report = Report {
        scene: args.target.scene.clone(),
        res: args.target.res.to_string(),
        spp: args.spp,
        max_depth: args.max_depth,
        triangles: renderer.triangle_count(),
        build_s: renderer.build_seconds(),
        rows,
    };
    super::output::print_report(args.json, &report, print_table)
}

fn print_table(out: &mut impl Write, r: &Report) -> std::io::Result<()> {
    writeln!(
        out,
        "path tracer: {} {} at {} spp, max depth {}, {} triangles, build {:.4} s\n",
        r.scene, r.res, r.spp, r.max_depth, r.triangles, r.build_s
    )?;
    writeln!(out, "| threads | samples | seconds | M samples/s | speed-up | mean RGB |")?;
    writeln!(out, "|---:|---:|---:|---:|---:|---|")?;
    let base = r.rows.first().map(|row| row.samples_per_s).unwrap_or(1.0);
    for row in &r.rows {
        writeln!(
            out,
            "| {} | {} | {:.3} | {:.3} | {:.2} | {:.5} {:.5} {:.5} |",
            row.threads,
            row.samples,
            row.seconds,
            row.samples_per_s / 1e6,
            row.samples_per_s / base,
            row.mean_rgb[0],
            row.mean_rgb[1],
            row.mean_rgb[2]
        )?;
    }
    Ok(())
}
