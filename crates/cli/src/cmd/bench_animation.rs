//! `filtrace bench animation`: the per-frame renderer on a meadow of a million triangles in
//! which one ball of 960 triangles rolls (`filtrace_render::frame_bench`): the cost of a
//! frame update against building everything anew, and samples per second of an animated
//! frame against the same frame built still.

use super::render::{parse_resolution, Resolution};
use filtrace_render::frame_bench::{self, UpdateTimings};
use filtrace_render::Renderer;
use serde::Serialize;
use std::io::Write;

#[derive(clap::Args)]
pub struct Args {
    /// Grass blades (5 triangles each; 200000 make a million triangles).
    #[arg(long, default_value_t = 200_000)]
    pub blades: usize,
    /// Rounds over the animation's frames whose updates are timed.
    #[arg(long, default_value_t = 3)]
    pub rounds: usize,
    /// Resolution of the sampling comparison, as WIDTHxHEIGHT.
    #[arg(long, default_value = "320x180", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Samples per pixel of each timed render.
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    /// Threads of the timed renders (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print one JSON object instead of a markdown table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Report {
    triangles: usize,
    moving_triangles: usize,
    frames: i64,
    update: UpdateTimings,
    /// Building the renderer from scratch (what a frame costs without updates).
    full_build_s: f64,
    res: String,
    spp: u32,
    threads: usize,
    animated_samples_per_s: f64,
    still_samples_per_s: f64,
    /// Mean colours of both renders (the same frame: they should agree).
    animated_mean_rgb: [f64; 3],
    still_mean_rgb: [f64; 3],
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.rounds > 0, "--rounds must be at least 1");
    anyhow::ensure!(args.threads != Some(0), "--threads must be at least 1");
    let scene = frame_bench::moving_object_scene(args.blades).map_err(|e| anyhow::anyhow!("{e}"))?;
    let settings = args.res.settings(args.spp, 8, 0)?;
    let mut renderer = Renderer::new(scene.clone(), settings.clone()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let update = frame_bench::time_updates(&mut renderer, frame_bench::FRAMES, args.rounds)?;
    let middle = frame_bench::FRAMES / 2;
    let still = frame_bench::still_at(&scene, middle)?;
    let full_build_s = frame_bench::time_full_build(&still, &settings).map_err(|e| anyhow::anyhow!("{e}"))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let (animated, still) = frame_bench::animated_vs_still(&scene, &settings, middle, threads)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let report = Report {
        triangles: scene.triangle_count(),
        moving_triangles: scene.meshes.last().map_or(0, |m| m.triangle_count()),
        frames: frame_bench::FRAMES,
        update,
        full_build_s,
        res: args.res.to_string(),
        spp: args.spp,
        threads,
        animated_samples_per_s: animated.samples_per_second,
        still_samples_per_s: still.samples_per_second,
        animated_mean_rgb: animated.mean_color,
        still_mean_rgb: still.mean_color,
    };
    super::output::print_report(args.json, &report, print_table)
}

fn print_table(out: &mut impl Write, r: &Report) -> std::io::Result<()> {
    let u = &r.update;
    writeln!(
        out,
        "animation: {} triangles, {} of them moving, {} frame updates ({} refits, {} top-level rebuilds, {} full rebuilds)\n",
        r.triangles, r.moving_triangles, u.frames, u.refits, u.rebuilds, u.full_rebuilds
    )?;
    writeln!(out, "| step | ms | vs full build |")?;
    writeln!(out, "|---|---:|---:|")?;
    for (what, s) in [("update, mean", u.mean_s), ("update, min", u.min_s), ("update, max", u.max_s)] {
        writeln!(out, "| {what} | {:.4} | {:.5} |", s * 1e3, s / r.full_build_s.max(1e-12))?;
    }
    writeln!(out, "| full build | {:.2} | 1 |", r.full_build_s * 1e3)?;
    writeln!(out, "\n{} at {} spp on {} threads:\n", r.res, r.spp, r.threads)?;
    writeln!(out, "| frame | M samples/s | mean RGB |")?;
    writeln!(out, "|---|---:|---|")?;
    let rows = [
        ("animated", r.animated_samples_per_s, r.animated_mean_rgb),
        ("still", r.still_samples_per_s, r.still_mean_rgb),
    ];
    for (what, sps, rgb) in rows {
        writeln!(out, "| {what} | {:.3} | {:.5} {:.5} {:.5} |", sps / 1e6, rgb[0], rgb[1], rgb[2])?;
    }
    let ratio = r.animated_samples_per_s / r.still_samples_per_s.max(1e-12);
    writeln!(out, "\nanimated / still: {ratio:.3}")
}
