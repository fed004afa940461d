//! `filtrace bench pipeline`: frames per second of the filtered pipeline (Bauszat et al.
//! 2011) and milliseconds per stage, as a markdown table or one JSON object.
//!
//! Default: the Cornell box at 512x512, 1 spp (the guide ray), max depth 3 (direct light
//! and one indirect bounce), guided filter (paper preset), all cores; 3 warm-up frames,
//! then 20 timed frames of the same renderer (buffers kept between frames, as a viewer
//! would drive it). Per stage: median and mean. The machine may be shared, so the process
//! CPU time per frame (Linux `/proc/self/stat`) is reported too: `cpu_ms / threads` is the
//! frame time the threads would take with the cores to themselves.
//!
//! `--trace lockstep` (the default) traces the guide rays and further samples on the SIMD
//! lockstep tracer, `--trace scalar` one key at a time (the reference; same frame bit for
//! bit). With the lockstep tracer, the lane utilisation of the timed frames is reported: a
//! deterministic measure (a function of the scene, resolution and seed) beside the timings.

use filtrace_pipeline::{FilterChoice, FrameTimings, PipelineSettings};
use serde::Serialize;
use std::io::Write;

use super::render_args::{BenchScene, TraceArg};
use super::render_filtered::Pipeline;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub target: BenchScene,
    /// Eye samples per pixel (the guide ray included).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Mitsuba convention: 3 = direct light + one indirect bounce.
    #[arg(long, default_value_t = 3, allow_negative_numbers = true)]
    pub max_depth: i32,
    /// Filters to time, comma-separated (none, atrous, guided, bilateral).
    #[arg(long, default_value = "guided", value_delimiter = ',')]
    pub filter: Vec<String>,
    /// Preset of the filter (applies to every filter listed; default: the paper's).
    #[arg(long)]
    pub filter_preset: Option<String>,
    /// Paths estimating the indirect light at each guide ray (at least 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub indirect_paths: u32,
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=10000))]
    pub frames: u32,
    #[arg(long, default_value_t = 3)]
    pub warmup: u32,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    pub threads: Option<u32>,
    /// How the guide rays and further samples are traced: `lockstep` (SIMD lanes, the
    /// default) or `scalar` (one key at a time, the reference). Same frame either way.
    #[arg(long, value_enum, default_value = "lockstep")]
    pub trace: TraceArg,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct StageStats {
    stage: String,
    median_ms: f64,
    mean_ms: f64,
}

#[derive(Serialize)]
struct Row {
    filter: String,
    frames: u32,
    fps_median: f64,
    /// Process CPU milliseconds per frame (user + system), mean; `None` off Linux.
    cpu_ms_mean: Option<f64>,
    /// `1000 / (cpu_ms / threads)`: frames per second with every thread on its own core.
    fps_if_cores_free: Option<f64>,
    stages: Vec<StageStats>,
    /// Lane slots used over lane slots paid for by the lockstep tracer in the timed frames
    /// (`LaneStats::mean_utilisation`); `None` with `--trace scalar`.
    lane_utilisation: Option<f64>,
    /// Groups of eight lanes run through a bounce per timed frame (lockstep only).
    lane_groups_per_frame: Option<f64>,
}

#[derive(Serialize)]
struct Report {
    scene: String,
    width: u32,
    height: u32,
    spp: u32,
    indirect_paths: u32,
    max_depth: i32,
    /// `lockstep` or `scalar`.
    trace: String,
    threads: usize,
    triangles: usize,
    rows: Vec<Row>,
}

/// CPU time (user + system) of this process in milliseconds, from `/proc/self/stat`
/// (fields 14 and 15, in clock ticks; 100 ticks per second on Linux).
fn process_cpu_ms() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) may contain spaces; fields after the last ')' are plain.
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let (utime, stime): (f64, f64) = (f.get(11)?.parse().ok()?, f.get(12)?.parse().ok()?);
    Some((utime + stime) * 10.0)
}

fn stats(name: &str, mut v: Vec<f64>) -> StageStats {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len().max(1) as f64;
    StageStats { stage: name.into(), median_ms: v[v.len() / 2], mean_ms: v.iter().sum::<f64>() / n }
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let threads = a
        .threads
        .map(|t| t as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let scene = filtrace_scene::load_scene(&a.target.scene)
        .map_err(|e| anyhow::anyhow!("cannot load scene '{}': {e}", a.target.scene))?;
    let triangles = scene.triangle_count();
    let settings = PipelineSettings {
        spp: a.spp,
        indirect_paths: a.indirect_paths,
        ..PipelineSettings::interactive(a.target.res.width, a.target.res.height)
    };
    let rows = a
        .filter
        .iter()
        .map(|f| time_filter(&a, &pool, &scene, &settings, f, threads))
        .collect::<anyhow::Result<Vec<Row>>>()?;
    let report = Report {
        scene: a.target.scene.clone(),
        width: a.target.res.width,
        height: a.target.res.height,
        spp: a.spp,
        indirect_paths: a.indirect_paths,
        max_depth: a.max_depth,
        trace: format!("{:?}", a.trace).to_lowercase(),
        threads,
        triangles,
        rows,
    };
    let mut out = super::output::stdout();
    if a.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)?;
    } else {
        write_table(&mut out, &report, a.frames)?;
    }
    Ok(out.flush()?)
}

/// The row of filter `filter`: its pipeline's warm-up and timed frames, per stage.
fn time_filter(
    a: &Args,
    pool: &rayon::ThreadPool,
    scene: &filtrace_scene::Scene,
    settings: &PipelineSettings,
    filter: &str,
    threads: usize,
) -> anyhow::Result<Row> {
    let choice = FilterChoice { preset: a.filter_preset.clone(), ..FilterChoice::named(filter) };
    let mut p = pool.install(|| {
        let trace = Some(a.trace.mode());
        super::render_filtered::build_pipeline_traced(
            scene.clone(),
            settings.clone(),
            a.max_depth,
            &choice,
            trace,
        )
    })?;
    let (times, cpu) = time_frames(a, pool, &mut p)?;
    // Clock ticks are 10 ms, too coarse for a per-frame median: take the mean.
    let cpu_ms_mean = (cpu.len() == times.len()).then(|| cpu.iter().sum::<f64>() / cpu.len().max(1) as f64);
    let fps_if_cores_free = cpu_ms_mean.map(|c| 1000.0 * threads as f64 / c.max(1e-9));
    let col = |g: fn(&FrameTimings) -> f64| times.iter().map(g).collect::<Vec<_>>();
    let stages = vec![
        stats("guide", col(|t| t.guide_ms)),
        stats("filter", col(|t| t.filter_ms)),
        stats("samples", col(|t| t.samples_ms)),
        stats("lookup", col(|t| t.lookup_ms)),
        stats("total", col(|t| t.total_ms)),
    ];
    let fps_median = 1000.0 / stages[4].median_ms.max(1e-9);
    let lanes = p.source().take_lane_stats();
    let lockstep = p.source().lane_code().is_some();
    Ok(Row {
        filter: p.filter_mut().label(),
        frames: a.frames,
        fps_median,
        cpu_ms_mean,
        fps_if_cores_free,
        stages,
        lane_utilisation: lockstep.then(|| lanes.mean_utilisation()),
        lane_groups_per_frame: lockstep.then(|| lanes.bounces as f64 / a.frames as f64),
    })
}

/// Renders `--warmup` frames, then `--frames` timed ones (lane statistics restarted at the
/// first); returns the timed frames' stage times and process CPU milliseconds.
fn time_frames(
    a: &Args,
    pool: &rayon::ThreadPool,
    p: &mut Pipeline,
) -> anyhow::Result<(Vec<FrameTimings>, Vec<f64>)> {
    let mut times = Vec::new();
    let mut cpu = Vec::new();
    for i in 0..a.warmup + a.frames {
        if i == a.warmup {
            p.source().take_lane_stats();
        }
        let c0 = process_cpu_ms();
        let t = pool.install(|| p.render_frame().map(|fr| fr.timings)).map_err(|e| anyhow::anyhow!("{e}"))?;
        if i >= a.warmup {
            times.push(t);
            if let (Some(c0), Some(c1)) = (c0, process_cpu_ms()) {
                cpu.push(c1 - c0);
            }
        }
    }
    Ok((times, cpu))
}

fn write_table(out: &mut impl Write, report: &Report, frames: u32) -> anyhow::Result<()> {
    writeln!(
        out,
        "filtered pipeline: {} {}x{}, {} spp, {} indirect path(s), max depth {}, {} tracer, {} threads, {} triangles, median of {} frames",
        report.scene, report.width, report.height, report.spp, report.indirect_paths, report.max_depth, report.trace, report.threads, report.triangles, frames
    )?;
    writeln!(out)?;
    writeln!(out, "| filter | guide ms | filter ms | samples ms | lookup ms | frame ms | fps | CPU ms/frame | fps, cores free | lanes used |")?;
    writeln!(out, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")?;
    for r in &report.rows {
        let m: Vec<f64> = r.stages.iter().map(|s| s.median_ms).collect();
        writeln!(
            out,
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} | {} |",
            r.filter,
            m[0],
            m[1],
            m[2],
            m[3],
            m[4],
            r.fps_median,
            r.cpu_ms_mean.map_or("-".into(), |c| format!("{c:.0}")),
            r.fps_if_cores_free.map_or("-".into(), |f| format!("{f:.1}")),
            r.lane_utilisation.map_or("-".into(), |u| format!("{:.1} %", 100.0 * u))
        )?;
    }
    Ok(())
}
