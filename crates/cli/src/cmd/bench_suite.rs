//! `filtrace bench suite`: the scenes a user would render, each measured the same way
//! (issue 13), as a markdown table or one JSON object.
//!
//! Per scene:
//! - **path tracing**: samples per second of a full render (`--res`, `--spp`, `--max-depth`,
//!   512x512, 64 spp, depth 8 by default) at each `--threads` count, best and median of
//!   `--repeats` renders, and samples per CPU-second (steady on a shared machine); the mean
//!   colour checks that the same image was timed (and that a peer rendered the same scene);
//! - **ray throughput**: `filtrace_accel::bench::ray_bench` (as `bench rays`) on a pool of
//!   `--ray-threads` threads (1 by default: per-thread speed, as Embree is measured by
//!   `scripts/embree_bench.py`), incoherent closest-hit and any-hit in the table, every query
//!   in the JSON.
//!
//! The peers run on the same scenes through the hidden `--dump-scene-json DIR`, which writes
//! each scene as it is rendered here (world placement, materials, lights, the camera used)
//! for `scripts/mitsuba_bench.py --scene-dir` and `scripts/embree_bench.py --scene-dir`;
//! `scripts/bench_suite.sh` runs all of them interleaved (docs/performance.md, "The suite").

mod scene_dump;

use super::render::{parse_resolution, Resolution};
use anyhow::Context;
use filtrace_accel::bench::{ray_bench, RayBenchOptions, RayBenchReport};
use filtrace_render::{render_bench, RenderSettings, Renderer};
use filtrace_scene::builtin::{grass_with, shared_candidates, GrassParams};
use filtrace_scene::Scene;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

/// The suite: name and what it exercises. Any other name is read as `bench rays` reads one
/// (a built-in scene, a scene file or `sphere:N`).
pub const SUITE: [(&str, &str); 7] = [
    ("cornell", "built-in, 36 triangles: the flat-mesh special kernels"),
    ("bunny-room", "built-in, the 56k-triangle bunny in the Cornell room"),
    ("grass", "built-in, 82k thin blades, area light and sky"),
    ("grass-1m", "GrassParams::dense() with 220,000 blades: 1.1 M triangles"),
    ("engine", "2CylinderEngine.glb: 34 meshes, instanced, 121k triangles, default sky and sun"),
    ("bunny", "bunny.obj alone, 56k triangles, default sky and sun (earlier Embree comparisons)"),
    ("teapot", "teapot.obj, 1,024 triangles, default sky and sun"),
];

/// Blades of `grass-1m`: 5 triangles each, so 1.1 M triangles of grass.
const GRASS_1M_BLADES: usize = 220_000;

#[derive(clap::Args)]
pub struct Args {
    /// Scenes, comma-separated: suite names (cornell, bunny-room, grass, grass-1m, engine,
    /// bunny, teapot), other built-in names, scene files or sphere:N. Default: the whole suite.
    #[arg(long, value_delimiter = ',')]
    pub scenes: Vec<String>,
    /// Resolution as WIDTHxHEIGHT (also the primary-ray image of the ray benchmark).
    #[arg(long, default_value = "512x512", value_parser = parse_resolution)]
    pub res: Resolution,
    /// Samples per pixel of each timed render.
    #[arg(long, default_value_t = 64)]
    pub spp: u32,
    /// Mitsuba's convention: 1 = emitters only, 2 = direct light, -1 = unbounded.
    #[arg(long, default_value_t = 8, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Path-tracer thread counts, comma-separated (default: all cores).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Timed renders per scene and thread count, and repetitions of each ray query.
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Incoherent rays per scene.
    #[arg(long, default_value_t = 1 << 20)]
    pub rays: usize,
    /// Threads of the ray benchmark (1: the per-thread speed compared with Embree).
    #[arg(long, default_value_t = 1)]
    pub ray_threads: usize,
    /// Skip path tracing.
    #[arg(long)]
    pub no_render: bool,
    /// Skip the ray benchmark.
    #[arg(long)]
    pub no_rays: bool,
    /// Print one JSON object instead of markdown tables.
    #[arg(long)]
    pub json: bool,
    /// Debug: write each scene to DIR/NAME/ (scene.json + binary PLY meshes) for the peer
    /// scripts, then exit without timing anything.
    #[arg(long, hide = true, value_name = "DIR")]
    pub dump_scene_json: Option<PathBuf>,
}

#[derive(Serialize)]
struct RenderRow {
    threads: usize,
    samples: u64,
    seconds: Vec<f64>,
    samples_per_s_best: f64,
    samples_per_s_median: f64,
    /// Samples per CPU-second of all threads, best run; `None` off Linux.
    samples_per_cpu_s: Option<f64>,
    mean_rgb: [f64; 3],
}

#[derive(Serialize)]
struct SceneReport {
    scene: String,
    what: String,
    triangles: usize,
    meshes: usize,
    instances: usize,
    build_s: f64,
    render: Vec<RenderRow>,
    rays: Option<RayBenchReport>,
}

#[derive(Serialize)]
struct Report {
    res: String,
    spp: u32,
    max_depth: i32,
    repeats: usize,
    ray_threads: usize,
    scenes: Vec<SceneReport>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    anyhow::ensure!(args.repeats > 0, "--repeats must be at least 1");
    anyhow::ensure!(args.rays > 0, "--rays must be at least 1");
    anyhow::ensure!(args.ray_threads > 0, "--ray-threads must be at least 1");
    anyhow::ensure!(args.threads.iter().all(|&t| t > 0), "--threads: every count must be at least 1");
    let names: Vec<String> = if args.scenes.is_empty() {
        SUITE.iter().map(|(n, _)| n.to_string()).collect()
    } else {
        args.scenes.clone()
    };
    let settings = args.res.settings(args.spp, args.max_depth, 0)?;
    if let Some(dir) = &args.dump_scene_json {
        return dump_all(&names, dir);
    }
    let mut scenes = Vec::with_capacity(names.len());
    for name in &names {
        let scene = suite_scene(name)?;
        scenes.push(measure_scene(name, scene, &settings, &args)?);
    }
    let report = Report {
        res: args.res.to_string(),
        spp: args.spp,
        max_depth: args.max_depth,
        repeats: args.repeats,
        ray_threads: args.ray_threads,
        scenes,
    };
    super::output::print_report(args.json, &report, print_tables)
}

/// The scene `name` of [`SUITE`], or any scene `bench rays` accepts.
pub fn suite_scene(name: &str) -> anyhow::Result<Scene> {
    let shared = |rel: &str| -> anyhow::Result<Scene> {
        let candidates = shared_candidates(rel);
        let path = candidates.iter().find(|p| p.is_file()).with_context(|| {
            let tried: Vec<String> = candidates.iter().map(|p| p.display().to_string()).collect();
            format!("suite scene '{name}' needs {rel}; not found at: {}", tried.join(", "))
        })?;
        filtrace_scene::load(path).map_err(|e| anyhow::anyhow!("{e}"))
    };
    let mut scene = match name {
        "grass-1m" => {
            let p = GrassParams { blades: GRASS_1M_BLADES, ..GrassParams::dense() };
            grass_with(&p).map_err(|e| anyhow::anyhow!("{e}"))?
        }
        "engine" => shared("scenes/gltf/2CylinderEngine.glb")?,
        "bunny" => shared("scenes/bunny/bunny.obj")?,
        "teapot" => shared("scenes/teapot/teapot.obj")?,
        other => filtrace_accel::bench::bench_scene(other).map_err(|e| anyhow::anyhow!("{other}: {e}"))?,
    };
    anyhow::ensure!(scene.triangle_count() > 0, "{name}: the scene has no triangles");
    scene.name = name.to_string();
    Ok(scene)
}

fn dump_all(names: &[String], dir: &std::path::Path) -> anyhow::Result<()> {
    let mut out = super::output::stdout();
    for name in names {
        let scene = suite_scene(name)?;
        let path = scene_dump::dump_scene(&scene, &dir.join(dir_name(name)))?;
        writeln!(out, "{name}: {} triangles -> {}", scene.triangle_count(), path.display())?;
    }
    Ok(out.flush()?)
}

/// A folder name for a scene name that may be a path (`a/b.obj` -> `a_b.obj`).
pub fn dir_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect()
}

fn measure_scene(
    name: &str,
    scene: Scene,
    settings: &RenderSettings,
    args: &Args,
) -> anyhow::Result<SceneReport> {
    let what = SUITE.iter().find(|(n, _)| *n == name).map_or("scene file or built-in", |(_, w)| w);
    let (meshes, instances) = (scene.meshes.len(), scene.instances.len());
    let rays = if args.no_rays { None } else { Some(measure_rays(&scene, args)?) };
    let triangles = scene.triangle_count();
    let (render, build_s) = if args.no_render {
        (Vec::new(), rays.as_ref().map_or(0.0, |r| r.build_s))
    } else {
        let renderer = Renderer::new(scene, settings.clone()).map_err(|e| anyhow::anyhow!("{e}"))?;
        let threads = thread_counts(&args.threads);
        let rows = threads.iter().map(|&t| measure_render(&renderer, t, args.repeats)).collect();
        (rows, renderer.build_seconds())
    };
    Ok(SceneReport {
        scene: name.to_string(),
        what: what.to_string(),
        triangles,
        meshes,
        instances,
        build_s,
        render,
        rays,
    })
}

fn thread_counts(requested: &[usize]) -> Vec<usize> {
    if requested.is_empty() {
        vec![rayon::current_num_threads()]
    } else {
        requested.to_vec()
    }
}

/// CPU time of the whole process, threads that have exited included, from the `utime` and
/// `stime` fields of `/proc/self/stat` (in the kernel's fixed 100 Hz `USER_HZ` ticks; Linux
/// only). `render_bench` runs on a pool of its own that is gone when it returns, which
/// `process_cpu_seconds` (live threads only) would not count. 10 ms ticks are fine for
/// renders of seconds.
fn cpu_seconds_with_exited_threads() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the parenthesised command name, which may contain spaces.
    let mut rest = stat.get(stat.rfind(')')? + 1..)?.split_whitespace();
    let utime: u64 = rest.nth(11)?.parse().ok()?;
    let stime: u64 = rest.next()?.parse().ok()?;
    Some((utime + stime) as f64 / 100.0)
}

/// `repeats` full renders on `threads` threads.
fn measure_render(renderer: &Renderer, threads: usize, repeats: usize) -> RenderRow {
    let (mut seconds, mut best_cpu, mut last) = (Vec::new(), None::<f64>, None);
    for _ in 0..repeats {
        let cpu0 = cpu_seconds_with_exited_threads();
        let r = render_bench(renderer, threads);
        if let (Some(a), Some(b)) = (cpu0, cpu_seconds_with_exited_threads()) {
            best_cpu = Some(best_cpu.map_or(b - a, |c| c.min(b - a)));
        }
        seconds.push(r.seconds);
        last = Some(r);
    }
    let last = last.expect("repeats >= 1");
    let mut sorted = seconds.clone();
    sorted.sort_by(f64::total_cmp);
    let samples = last.samples as f64;
    RenderRow {
        threads,
        samples: last.samples,
        samples_per_s_best: samples / sorted[0].max(1e-9),
        samples_per_s_median: samples / sorted[sorted.len() / 2].max(1e-9),
        samples_per_cpu_s: best_cpu.map(|c| samples / c.max(1e-9)),
        seconds,
        mean_rgb: last.mean_color,
    }
}

fn measure_rays(scene: &Scene, args: &Args) -> anyhow::Result<RayBenchReport> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.ray_threads)
        .build()
        .context("cannot start the worker threads")?;
    let opts = RayBenchOptions {
        rays: args.rays,
        width: args.res.width as usize,
        height: args.res.height as usize,
        repeats: args.repeats,
        ..RayBenchOptions::default()
    };
    let mut report = pool.install(|| ray_bench(scene, &opts));
    report.scene = scene.name.clone();
    Ok(report)
}

fn print_tables(out: &mut impl Write, r: &Report) -> std::io::Result<()> {
    if r.scenes.iter().any(|s| !s.render.is_empty()) {
        writeln!(out, "## Path tracing, {} at {} spp, max depth {}\n", r.res, r.spp, r.max_depth)?;
        writeln!(
            out,
            "| scene | triangles | threads | M samples/s best | median | M samples per CPU-s | mean RGB |"
        )?;
        writeln!(out, "|---|---:|---:|---:|---:|---:|---|")?;
        for s in &r.scenes {
            for row in &s.render {
                let cpu =
                    finite(row.samples_per_cpu_s).map_or("n/a".to_string(), |c| format!("{:.3}", c / 1e6));
                let [red, green, blue] = row.mean_rgb;
                writeln!(
                    out,
                    "| {} | {} | {} | {:.3} | {:.3} | {cpu} | {red:.4} {green:.4} {blue:.4} |",
                    s.scene,
                    s.triangles,
                    row.threads,
                    row.samples_per_s_best / 1e6,
                    row.samples_per_s_median / 1e6
                )?;
            }
        }
        writeln!(out)?;
    }
    if r.scenes.iter().any(|s| s.rays.is_some()) {
        writeln!(out, "## Incoherent rays, {} thread(s), Mrays/s per thread (per CPU-s)\n", r.ray_threads)?;
        writeln!(out, "| scene | triangles | instances | build s | closest hit | any hit | hit fraction |")?;
        writeln!(out, "|---|---:|---:|---:|---:|---:|---:|")?;
        for s in &r.scenes {
            let Some(rays) = &s.rays else { continue };
            let t = rays.threads.max(1) as f64;
            let cell = |m: f64, c: Option<f64>| {
                format!("{:.2} ({})", m / t, finite(c).map_or("n/a".into(), |c| format!("{c:.2}")))
            };
            writeln!(
                out,
                "| {} | {} | {} | {:.3} | {} | {} | {:.3} |",
                s.scene,
                s.triangles,
                s.instances,
                rays.build_s,
                cell(rays.incoherent_closest_mrays, rays.incoherent_closest_mrays_per_cpu_s),
                cell(rays.incoherent_any_mrays, rays.incoherent_any_mrays_per_cpu_s),
                rays.incoherent_hit_fraction
            )?;
        }
    }
    Ok(())
}

/// `None` for a CPU time too short to measure (an infinite rate on a tiny setting).
fn finite(x: Option<f64>) -> Option<f64> {
    x.filter(|v| v.is_finite())
}
