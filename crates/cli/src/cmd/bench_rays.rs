//! `filtrace bench rays MESH`: BVH build time and ray throughput (primary, incoherent
//! closest-hit, incoherent any-hit) on a mesh or scene, see `filtrace_accel::bench`.

use super::render::{parse_resolution, Resolution};
use anyhow::Context;
use filtrace_accel::bench::{ray_bench, RayBenchOptions};
use std::io::Write;

#[derive(clap::Args)]
pub struct Args {
    /// Mesh or scene: OBJ, glTF/GLB, PLY, TOML or a built-in name.
    pub mesh: String,
    /// Number of incoherent rays (origins uniform in the bounds, directions uniform on the sphere).
    #[arg(long, default_value_t = 1 << 20)]
    pub rays: usize,
    /// Primary-ray image size WIDTHxHEIGHT, each side 1..=32768 (one ray per pixel).
    #[arg(long, default_value = "1024x1024", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed repetitions; the fastest is reported.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Print one JSON object instead of a markdown table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.rays > 0, "--rays must be at least 1");
    anyhow::ensure!(args.repeats > 0, "--repeats must be at least 1");
    let scene = filtrace_scene::load_scene(&args.mesh).map_err(|e| anyhow::anyhow!("{e}"))?;
    anyhow::ensure!(scene.triangle_count() > 0, "{}: the mesh has no triangles", args.mesh);
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(t) = args.threads {
        anyhow::ensure!(t > 0, "--threads must be at least 1");
        builder = builder.num_threads(t);
    }
    let pool = builder.build().context("cannot start the worker threads")?;
    let opts = RayBenchOptions {
        rays: args.rays,
        width: args.res.width as usize,
        height: args.res.height as usize,
        repeats: args.repeats,
        ..RayBenchOptions::default()
    };
    let mut report = pool.install(|| ray_bench(&scene, &opts));
    report.scene = args.mesh.clone();
    let mut out = super::output::stdout();
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        writeln!(out, "{}", report.to_markdown())?;
    }
    Ok(out.flush()?)
}
